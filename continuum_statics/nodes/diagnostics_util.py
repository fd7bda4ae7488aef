"""Small helpers for the nodes' diagnostics: statuses, rates and timing windows."""
from collections import deque
import math
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np

#: Levels as ints (the message constants are bytes in Python); ``max()`` picks the worst.
OK, WARN, ERROR, STALE = (ord(DiagnosticStatus.OK), ord(DiagnosticStatus.WARN),
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


class TimingWindow:
    """Durations (s) collected since the last report: median and max in ms."""

    def __init__(self, capacity=5000):
        self._samples = deque(maxlen=capacity)

    def add(self, seconds):
        """Record one duration in seconds."""
        self._samples.append(seconds)

    def report(self):
        """Return (count, median ms, max ms) and start a new window; NaN-free (0 when empty)."""
        samples = np.fromiter(self._samples, dtype=float)
        self._samples.clear()
        if samples.size == 0:
            return 0, 0.0, 0.0
        return samples.size, float(np.median(samples)) * 1e3, float(samples.max()) * 1e3


class RateMeter:
    """Events per second over the interval between two reports."""

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._count = 0
        self._since = clock()
        self.total = 0

    def tick(self, n=1):
        """Count ``n`` events."""
        self._count += n
        self.total += n

    def report(self):
        """Return the rate in Hz since the last report and start a new interval."""
        now = self._clock()
        elapsed = now - self._since
        rate = self._count / elapsed if elapsed > 0.0 else 0.0
        self._count, self._since = 0, now
        return rate


class Problems:
    """The latest reason for each kind of rejected input, with counts, for diagnostics."""

    def __init__(self):
        self.counts = {}
        self.last_reason = ''
        self.last_time = None

    def add(self, kind, reason):
        """Record one rejected input of ``kind`` (e.g. 'cable_states') with its reason."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        reason = '%s: %s' % (kind, reason)
        # one huge bad message must not bloat every later diagnostics message
        self.last_reason = reason if len(reason) <= 300 else reason[:297] + '...'
        self.last_time = time.monotonic()

    def recent(self, window):
        """Return True if something was rejected in the last ``window`` seconds."""
        return self.last_time is not None and time.monotonic() - self.last_time < window

    def values(self):
        """Return key/values: a rejected count per kind and the last reason."""
        values = {'rejected_%s' % kind: count for kind, count in sorted(self.counts.items())}
        values['last_rejection'] = self.last_reason or 'none'
        return values


class ValueWindow:
    """Values collected since the last report (e.g. residuals, m): count, median and max."""

    def __init__(self, capacity=5000):
        self._samples = deque(maxlen=capacity)

    def add(self, value):
        """Record one value."""
        self._samples.append(value)

    def report(self):
        """Return (count, median, max) and start a new window; (0, nan, nan) when empty."""
        samples = np.fromiter(self._samples, dtype=float)
        self._samples.clear()
        if samples.size == 0:
            return 0, math.nan, math.nan
        return samples.size, float(np.median(samples)), float(samples.max())


#: Message prefix of a node that cannot serve yet (compiling kernels, waiting for its inputs).
STARTING = 'starting: '


def publish_starting(node, publisher, hardware_id, waiting_for):
    """Publish one ``starting`` status at once (before the node spins), saying what it waits for.

    Level OK: a node that starts is not faulty; the ``state`` value says it is not ready.
    """
    publisher.publish(diagnostic_array(
        node.get_clock().now().to_msg(), node.get_fully_qualified_name().lstrip('/'),
        hardware_id, OK, STARTING + waiting_for, {'state': 'starting'}))


def tendon_values(names, tensions, slack):
    """Diagnostic values of the tendon model: which cables are slack, model tensions (N).

    ``tensions``/``slack`` are the estimate's (None when the shape came from ideal taut cables).
    """
    if tensions is None or slack is None:
        return {'slack_cables': 'none', 'tension_estimates_n': 'not estimated (taut ideal cables)'}
    return {'slack_cables': ', '.join(n for n, s in zip(names, slack) if s) or 'none',
            'tension_estimates_n': ', '.join('%s %.4g' % (n, t) for n, t in zip(names, tensions))}
