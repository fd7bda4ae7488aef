"""Serve one high-rate subscription from a thread of its own, outside the rclpy executor.

rclpy's Python executors rebuild their wait set and schedule a task for every message: ~0.4 ms of
CPU per message on this class of machine, which alone would cap a 1 kHz input. A subscription in
:class:`DedicatedIntake` is created normally (it is on the ROS graph, with its QoS) but in a
callback group no executor will serve; a thread waits on it with a wait set of its own and calls
the callback directly (~0.1 ms per message). Everything else on the node (parameters, timers,
other topics) stays on the node's executor.

This uses the same low-level rclpy calls as ``rclpy.wait_for_message`` (a ``WaitSet`` and
``take_message`` on the subscription handle), available in Jazzy and Kilted; when they are not,
:func:`create_intake` falls back to an ordinary executor-served subscription.
"""
import threading
import time

from rclpy.callback_groups import CallbackGroup


class NotExecutorServed(CallbackGroup):
    """A callback group whose entities no executor waits on or runs."""

    def can_execute(self, entity):
        """Never: the executor leaves the entity out of its wait set."""
        return False

    def beginning_execution(self, entity):
        """Never."""
        return False

    def ending_execution(self, entity):
        """Nothing to release."""


class DedicatedIntake:
    """One subscription served by a dedicated thread.

    With ``max_lag`` set, a queue deeper than 1 absorbs short scheduling stalls without losing
    measurements, yet never builds a backlog: when the message taken was received more than
    ``max_lag`` seconds ago, the queue is drained and only the newest message is handed on.

    :param node: the node owning the subscription
    :param callback: called with each message, in the intake thread; exceptions are logged
    :param max_lag: skip to the newest message when the oldest queued one is older than this, s
        (None: hand on every message taken)
    :param on_error: called with an exception the callback raised (default: log it)

    Counters (read them from any thread): ``taken``, ``skipped`` (drained for being stale) and
    ``lost`` (gaps in the publishers' sequence numbers: never reached this subscription, e.g.
    overwritten in a full queue or lost in transport).
    """

    def __init__(self, node, msg_type, topic, callback, qos_profile, raw=False, max_lag=None,
                 on_error=None):
        from rclpy.impl.implementation_singleton import rclpy_implementation

        self._node = node
        self._callback = callback
        self._on_error = on_error
        self._max_lag_ns = None if max_lag is None else int(max_lag * 1e9)
        self._sequences = {}
        self.taken = self.skipped = self.lost = 0
        self._wait_set = rclpy_implementation.WaitSet(1, 0, 0, 0, 0, 0, node.context.handle)
        self.subscription = node.create_subscription(
            msg_type, topic, callback, qos_profile, callback_group=NotExecutorServed(), raw=raw)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True,
                                        name='intake_' + topic.replace('/', '_'))

    def start(self):
        """Start serving."""
        self._thread.start()

    def stop(self, timeout=2.0):
        """Stop serving (before the node or the subscription is destroyed)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self):
        subscription, wait_set = self.subscription, self._wait_set
        handle, msg_type, raw = subscription.handle, subscription.msg_type, subscription.raw
        context = self._node.context
        while not self._stop.is_set() and context.ok():
            try:
                with handle:
                    wait_set.clear_entities()
                    wait_set.add_subscription(handle)
                    wait_set.wait(50_000_000)  # ns: the stop flag is checked at least at 20 Hz
                    if not wait_set.get_ready_entities('subscription'):
                        continue
                    taken = handle.take_message(msg_type, raw)
                    if taken is None:
                        continue
                    self._count(taken[1])
                    if self._max_lag_ns is not None and self._stale(taken[1]):
                        while True:  # drain: only the newest measurement matters now
                            newer = handle.take_message(msg_type, raw)
                            if newer is None:
                                break
                            self._count(newer[1])
                            self.skipped += 1
                            taken = newer
                self._callback(taken[0])
            except Exception as error:  # a failing callback must not end the intake
                if self._stop.is_set() or not context.ok():
                    return
                if self._on_error is not None:
                    self._on_error(error)
                else:
                    self._node.get_logger().error('intake of %s failed: %r'
                                                  % (subscription.topic_name, error),
                                                  throttle_duration_sec=2.0)


    def _stale(self, info):
        received = info.get('received_timestamp') if isinstance(info, dict) else None
        return bool(received) and time.time_ns() - received > self._max_lag_ns

    def _count(self, info):
        self.taken += 1
        if not isinstance(info, dict):
            return
        sequence = info.get('publication_sequence_number')
        gid = info.get('publisher_gid')
        if not sequence or gid is None:
            return
        key = bytes(gid.get('data', b'')) if isinstance(gid, dict) else bytes(gid)
        last = self._sequences.get(key)
        if last is not None and sequence > last + 1:
            self.lost += sequence - last - 1
        self._sequences[key] = sequence


def create_intake(node, msg_type, topic, callback, qos_profile, dedicated=True, raw=False,
                  max_lag=None, fallback_qos=None):
    """Return a started :class:`DedicatedIntake`, or None after an ordinary subscription.

    :param dedicated: False (or an rclpy without the low-level calls) gives an ordinary
        subscription served by the node's executor, with ``fallback_qos`` (default the same)
    """
    if dedicated:
        try:
            intake = DedicatedIntake(node, msg_type, topic, callback, qos_profile, raw=raw,
                                     max_lag=max_lag)
        except (AttributeError, ImportError, TypeError) as error:
            node.get_logger().warning('no dedicated intake thread for %s (%r): using the '
                                      'executor' % (topic, error))
        else:
            intake.start()
            return intake
    node.create_subscription(msg_type, topic, callback, fallback_qos or qos_profile, raw=raw)
    return None
