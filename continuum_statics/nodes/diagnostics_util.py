"""Small helpers for the nodes' diagnostics: statuses, rates and timing windows."""
import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

# The ROS-free part lives in control/health.py (levels, counters, the rejection record).
from continuum_statics.control.health import (  # noqa: F401  (re-exported for the nodes)
    ERROR,
    OK,
    STALE,
    STARTING,
    WARN,
    Problems,
    RateMeter,
    TimingWindow,
    ValueWindow,
    tendon_values,
)

assert (OK, WARN, ERROR, STALE) == (ord(DiagnosticStatus.OK), ord(DiagnosticStatus.WARN),
                                    ord(DiagnosticStatus.ERROR), ord(DiagnosticStatus.STALE))


def diagnostic_array(stamp, name, hardware_id, level, message, values):
    """Return a DiagnosticArray holding one status with string key/values.

    :param values: mapping of key -> value; floats are printed with 6 significant digits
    """
    status = DiagnosticStatus(level=bytes([int(level)]), name=name, hardware_id=hardware_id,
                              message=str(message))
    status.values = [KeyValue(key=str(key), value=_text(value)) for key, value in values.items()]
    array = DiagnosticArray(status=[status])
    array.header.stamp = stamp
    return array


def _text(value):
    if isinstance(value, float):
        # 'n/a' rather than 'nan'/'inf': no NaN leaves a node, not even as text
        return '%.6g' % value if math.isfinite(value) else 'n/a'
    return str(value)


def publish_starting(node, publisher, hardware_id, waiting_for):
    """Publish one ``starting`` status at once (before the node spins), saying what it waits for.

    Level OK: a node that starts is not faulty; the ``state`` value says it is not ready.
    """
    publisher.publish(diagnostic_array(
        node.get_clock().now().to_msg(), node.get_fully_qualified_name().lstrip('/'),
        hardware_id, OK, STARTING + waiting_for, {'state': 'starting'}))


def driver_refusal(msg, name):
    """Return why the cable_driver of status ``name`` refuses commands, from a DiagnosticArray.

    '' when it accepts them; None when the array holds no status of such a driver.
    """
    refusal = None
    for status in msg.status:
        if status.name == name:
            values = {kv.key: kv.value for kv in status.values}
            if 'accepts_commands' in values:  # a driver of this package
                refusal = ('' if values['accepts_commands'] == 'True'
                           else values.get('refusal') or status.message)
    return refusal
