"""Serve high-rate subscriptions from a thread of their own, outside the rclpy executor.

rclpy's Python executors rebuild their wait set and schedule a task for every message: ~0.4 ms of
CPU per message for the single-threaded executor and over 1 ms for the multi-threaded one on this
class of machine, which alone would cap a 1 kHz input (and keeps an idle tip_controller, which
hears three 200 Hz topics, at a full core). Subscriptions added to a :class:`DedicatedIntake` are
created normally (they are on the ROS graph, with their QoS) but in a callback group no executor
serves; one thread waits on all of them with a wait set of its own and calls the callbacks
directly (~0.1 ms per message). Everything else on the node (parameters, services, timers) stays
on the node's executor.

statics' ``cable_states``: newest measurement, no backlog. A short queue (``input_queue_depth``)
absorbs millisecond scheduling stalls; as soon as the oldest queued measurement is older than
``max_input_lag`` the queue is drained and only the newest is solved (with depth 1, stalls of a
few ms on a loaded 2-core machine lost 5-10 % of a 1 kHz stream).

This uses the same low-level rclpy calls as ``rclpy.wait_for_message`` (a ``WaitSet`` and
``take_message`` on the subscription handle), available in Jazzy and Kilted; where they are not,
:func:`make_intake` returns an :class:`ExecutorIntake` that creates ordinary subscriptions.
"""
import threading
import time

from rclpy.callback_groups import CallbackGroup

from continuum_statics.nodes.node_runner import hooks


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


class IntakeEntry:
    """One subscription of an intake, with its counters (readable from any thread).

    :ivar taken: messages taken from the subscription
    :ivar skipped: messages drained unread because a newer one was waiting (``max_lag``)
    :ivar lost: gaps in the publishers' sequence numbers: messages that never reached this
        subscription (overwritten in a full queue, or lost in transport); -1 when not counted
    """

    def __init__(self, subscription, callback, max_lag=None, counted=True):
        self.subscription = subscription
        self.callback = callback
        self.max_lag_ns = None if max_lag is None else int(max_lag * 1e9)
        self.taken = 0
        self.skipped = 0
        self.lost = 0 if counted else -1
        self._sequences = {}

    def count(self, info):
        """Count one taken message and any gap in its publisher's sequence numbers."""
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

    def stale(self, info):
        """Return True if the message was received longer than ``max_lag`` ago."""
        if self.max_lag_ns is None or not isinstance(info, dict):
            return False
        received = info.get('received_timestamp')
        return bool(received) and time.time_ns() - received > self.max_lag_ns


class DedicatedIntake:
    """Subscriptions served by one dedicated thread; add them, then :meth:`start`.

    With ``max_lag`` set on a subscription, a queue deeper than 1 absorbs short scheduling stalls
    without losing messages, yet never builds a backlog: when the message taken was received more
    than ``max_lag`` seconds ago, the queue is drained and only the newest is handed on.

    :param node: the node owning the subscriptions
    :param name: thread name (for debugging)
    """

    def __init__(self, node, name='intake'):
        from rclpy.impl.implementation_singleton import rclpy_implementation

        self._wait_set_class = rclpy_implementation.WaitSet  # AttributeError: not available
        self._node = node
        self._group = NotExecutorServed()
        self._entries = []
        self._wait_set = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=name)

    def add(self, msg_type, topic, callback, qos_profile, raw=False, max_lag=None,
            fallback_qos=None):
        """Subscribe; ``callback`` runs in the intake thread. Returns the :class:`IntakeEntry`.

        ``fallback_qos`` is used by :class:`ExecutorIntake` only.
        """
        if self._thread.is_alive():
            raise RuntimeError('add subscriptions before start()')
        subscription = self._node.create_subscription(
            msg_type, topic, callback, qos_profile, callback_group=self._group, raw=raw)
        entry = IntakeEntry(subscription, callback, max_lag)
        self._entries.append(entry)
        return entry

    def start(self):
        """Start serving."""
        self._wait_set = self._wait_set_class(
            len(self._entries), 0, 0, 0, 0, 0, self._node.context.handle)
        self._thread.start()

    def stop(self, timeout=2.0):
        """Stop serving (before the node or its subscriptions are destroyed)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self):
        wait_set, context = self._wait_set, self._node.context
        entries = [(entry, entry.subscription.handle, entry.subscription.msg_type,
                    entry.subscription.raw) for entry in self._entries]
        while not self._stop.is_set() and context.ok():
            try:
                wait_set.clear_entities()
                for _, handle, _, _ in entries:
                    with handle:
                        wait_set.add_subscription(handle)
                wait_set.wait(50_000_000)  # ns: the stop flag is checked at least at 20 Hz
                ready = wait_set.get_ready_entities('subscription')
                if not ready:
                    continue
                for entry, handle, msg_type, raw in entries:
                    if handle.pointer in ready:
                        # Take until the queue is empty: no wait-set round trip per message.
                        message = self._take(entry, handle, msg_type, raw)
                        while message is not None:
                            entry.callback(message)
                            message = self._take(entry, handle, msg_type, raw)
            except Exception as error:  # a failing callback must not end the intake
                if self._stop.is_set() or not context.ok():
                    return
                self._node.get_logger().error('intake failed: %r' % (error,),
                                              throttle_duration_sec=2.0)
                hooks(self._node).on_node_failure('intake failed: %r' % (error,))

    @staticmethod
    def _take(entry, handle, msg_type, raw):
        with handle:
            taken = handle.take_message(msg_type, raw)
            if taken is None:
                return None
            entry.count(taken[1])
            if entry.stale(taken[1]):
                while True:  # drain: only the newest message matters now
                    newer = handle.take_message(msg_type, raw)
                    if newer is None:
                        break
                    entry.count(newer[1])
                    entry.skipped += 1
                    taken = newer
        return taken[0]


class ExecutorIntake:
    """The same interface as :class:`DedicatedIntake`, with ordinary executor subscriptions."""

    def __init__(self, node, name='intake'):
        self._node = node

    def add(self, msg_type, topic, callback, qos_profile, raw=False, max_lag=None,
            fallback_qos=None):
        """Subscribe with ``fallback_qos`` (default ``qos_profile``); counters stay at 0/-1."""
        subscription = self._node.create_subscription(
            msg_type, topic, callback, fallback_qos or qos_profile, raw=raw)
        return IntakeEntry(subscription, callback, counted=False)

    def start(self):
        """Nothing to start: the node's executor serves the subscriptions."""

    def stop(self, timeout=2.0):
        """Nothing to stop."""


def make_intake(node, dedicated=True, name='intake'):
    """Return a :class:`DedicatedIntake`, or an :class:`ExecutorIntake` when not wanted/possible.

    :param dedicated: False gives ordinary subscriptions served by the node's executor
    """
    if dedicated:
        try:
            return DedicatedIntake(node, name)
        except (AttributeError, ImportError) as error:
            node.get_logger().warning('no dedicated intake thread (%r): subscriptions are '
                                      'served by the executor' % (error,))
    return ExecutorIntake(node, name)


class PeriodicThread:
    """Call ``callback()`` at ``rate`` Hz from a thread of its own (steady clock, no drift).

    A 200 Hz rclpy timer costs ~1 ms of executor overhead per tick; this costs a sleep. A late
    tick is not made up with a burst: the schedule restarts from now. Exceptions are logged.

    :param node: the node whose logger reports failures and whose context ends the loop
    :param rate: ticks per second; change it at any time with :attr:`rate`
    """

    def __init__(self, node, rate, callback, name='periodic'):
        self._node = node
        self.rate = float(rate)
        self._callback = callback
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name=name)

    def start(self):
        """Start ticking."""
        self._thread.start()

    def stop(self, timeout=2.0):
        """Stop ticking and wait for the thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    def _run(self):
        context = self._node.context
        next_tick = time.monotonic()
        while not self._stop.is_set() and context.ok():
            period = 1.0 / self.rate
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < -period:  # more than a tick late: restart the schedule, no burst
                next_tick = time.monotonic()
            elif delay > 0.0 and self._stop.wait(delay):
                return
            try:
                self._callback()
            except Exception as error:
                if self._stop.is_set() or not context.ok():
                    return
                self._node.get_logger().error('periodic %s failed: %r' % (
                    self._thread.name, error), throttle_duration_sec=2.0)
