"""Timed inputs of the control logic and their single expiry rule.

Times are ``time.monotonic()`` seconds of *arrival* (a sender's stamp may be zero or jump with a
simulated clock; arrival times never do); stamps are kept only to pair messages with each other.
"""
from dataclasses import dataclass
import math
import time

import numpy as np


@dataclass(frozen=True, eq=False)
class Measurement:
    """One ``cable_states``: lengths (n_cables,) in m, robot order."""

    lengths: np.ndarray
    stamp_ns: int
    received: float

    def age(self, now):
        """Seconds since it arrived."""
        return now - self.received


@dataclass(frozen=True, eq=False)
class TipSample:
    """One ``tip_pose``: position (3,) in m, base frame."""

    position: np.ndarray
    stamp_ns: int
    received: float

    def age(self, now):
        """Seconds since it arrived."""
        return now - self.received


def tracked_tip(marker_position, tip_rotation, marker_offset):
    """Tip position (m) of a tracker's marker (m), ``marker_offset`` (m) on the tip frame.

    The tip's rotation is the model's (a tracker's marker frame is arbitrary).
    """
    return np.asarray(marker_position, dtype=float) - np.asarray(tip_rotation) @ marker_offset


ZERO_LOAD = np.zeros(6)
ZERO_LOAD.setflags(write=False)


@dataclass(frozen=True, eq=False)
class TipLoad:
    """A tip-load estimate: force (N) and moment (N m) in the base frame, as one (6,) wrench."""

    wrench: np.ndarray
    received: float

    def expired(self, now, timeout):
        """Return True when older than ``timeout`` s (0: never expires)."""
        return timeout > 0.0 and now - self.received > timeout


class TipLoadInput:
    """The tip load a node takes from ``topic``: the newest, whether it expired, what to say.

    ``hold`` (``tip_wrench_source: estimate``): the load is kept past the timeout, since a
    payload does not vanish with its estimate (zero load moved the model tip 10 mm under a
    0.14 N load while one estimate took 3-4 s, and goals were judged there); :meth:`status`
    says so for a WARN on /diagnostics.
    ``warn`` and ``info`` log once when the load expires and when it comes again.
    """

    def __init__(self, topic, hold, warn, info, clock=time.monotonic):
        self.topic, self.hold = topic, hold
        self.load = None  # the newest TipLoad
        self.expired = False
        self._warn, self._info, self._clock = warn, info, clock

    def take(self, wrench):
        """Use ``wrench`` (6,) N and N m (checked by the caller) from now on."""
        self.load = TipLoad(wrench, self._clock())
        if self.expired:
            self.expired = False
            self._info('%s received again' % self.topic)

    def drop(self):
        """Forget the load (the model cannot take it): zero until the next one."""
        self.load = None

    def current(self, timeout):
        """Return the wrench (6,) to use now (zero without one); say once that it expired."""
        load = self.load
        expired = load is not None and load.expired(self._clock(), timeout)
        if expired and not self.expired:
            self.expired = True
            self._warn('%s is older than %.3g s: %s' % (
                self.topic, timeout, 'its last load kept (the estimator is late or stopped)'
                if self.hold else 'using zero tip load'))
        return ZERO_LOAD if load is None or (expired and not self.hold) else load.wrench

    def age(self):
        """Seconds since the newest load arrived (inf without one)."""
        return math.inf if self.load is None else self._clock() - self.load.received

    def status(self):
        """Return why a kept load is old ('' while fresh): for a WARN on /diagnostics."""
        if not (self.expired and self.hold and self.load is not None):
            return ''
        return '%s %.3g s old: its last load kept' % (self.topic, self.age())
