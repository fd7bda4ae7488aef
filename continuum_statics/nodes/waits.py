"""Waiting without holding an executor thread: futures a coroutine callback can ``await``.

A service, action or subscription callback that waits for another callback's progress (fresh
state, the end of a goal) must not block the thread it runs in: a multi-threaded executor has a
few threads, and eight blocked callbacks once stopped the control timer, cancel requests,
diagnostics and Ctrl-C for good. Such callbacks are coroutines instead (rclpy runs ``async def``
callbacks as tasks) and await a :class:`Waits` future, which a steady timer completes as soon as
the condition holds or the deadline passes. Waiting costs no thread, and however many callbacks
wait, the executor serves everything else.
"""
import threading
import time

from rclpy.task import Future

from continuum_statics.nodes.timers import steady_timer


def _wake(_future):
    """Do nothing: as a done callback rclpy runs it on the executor, which wakes the waiter."""


class Waits:
    """Futures completed when a condition holds or a deadline (monotonic s) passes.

    :param node: the node whose executor runs the awaiting coroutines
    :param period: how often conditions are checked while someone waits, s
    :param callback_group: the checking timer's group (its own: never behind a busy callback)
    """

    def __init__(self, node, period, callback_group):
        self._node = node
        self._lock = threading.Lock()
        self._pending = []  # (condition, deadline, future)
        self._timer = steady_timer(node, period, self._check, callback_group=callback_group)
        self._timer.cancel()  # runs only while someone waits

    def until(self, condition, deadline):
        """Return a future whose result is ``condition()`` once it holds or ``deadline`` passes.

        ``await waits.until(...)`` in an ``async def`` callback of the node.
        """
        future = Future(executor=self._node.executor)
        future.add_done_callback(_wake)  # completed from the timer's thread: wake the executor
        if condition():
            future.set_result(True)
            return future
        with self._lock:
            self._pending.append((condition, deadline, future))
            self._timer.reset()
        return future

    def release_all(self):
        """Complete every pending future with its condition's value now (shutdown)."""
        with self._lock:
            pending, self._pending = self._pending, []
        for condition, _, future in pending:
            future.set_result(bool(condition()))

    def _check(self):
        now = time.monotonic()
        done = []
        with self._lock:
            keep = []
            for entry in self._pending:
                condition, deadline, _ = entry
                if condition() or now >= deadline:
                    done.append(entry)
                else:
                    keep.append(entry)
            self._pending = keep
            if not keep:
                self._timer.cancel()
        for condition, _, future in done:
            future.set_result(bool(condition()))


class InFlight:
    """How many goal callbacks (action executes, service calls) have not answered yet.

    ``with in_flight:`` around a goal's body; at shutdown the runner keeps the executors running
    until it reads zero, so that every released goal sends its result.
    """

    def __init__(self):
        self._count = 0
        self._lock = threading.Lock()
        self._owed = []  # callables: results asked for and not sent yet

    def also(self, owed):
        """Count ``owed()`` too (an action server's results not sent yet)."""
        self._owed.append(owed)

    def __enter__(self):
        with self._lock:
            self._count += 1
        return self

    def __exit__(self, *_):
        with self._lock:
            self._count -= 1

    def __call__(self):
        """Return the number of goals not answered yet (running, or their result not sent)."""
        return self._count + sum(owed() for owed in self._owed)
