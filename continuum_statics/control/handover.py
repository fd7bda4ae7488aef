"""Who commands the cables: goals and teleoperation hand over by arrival, the later one wins.

A goal is solved outside the node's lock (milliseconds to tens of them) and teleoperation starts
from an estimate made outside it too; whatever arrives in between must not be overtaken by the
older request finishing later (a goal parked behind a twist stream once ran after the operator's
dead-man stop). Each request takes a ticket when it arrives and may start only while it holds
the newest one. No ROS; thread-safe.
"""
import threading


class Handover:
    """Tickets in arrival order; ``holder`` names who took the newest."""

    def __init__(self):
        self._lock = threading.Lock()
        self._newest = 0
        self.holder = 'nobody'

    def take(self, who):
        """Take the newest ticket for ``who`` (e.g. 'teleoperation'); return it."""
        with self._lock:
            self._newest += 1
            self.holder = who
            return self._newest

    def holds(self, ticket):
        """Return True while nothing arrived after ``ticket``."""
        return ticket == self._newest
