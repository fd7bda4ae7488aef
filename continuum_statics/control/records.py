"""Timed inputs of the control logic and their single expiry rule.

Times are ``time.monotonic()`` seconds of *arrival* (a sender's stamp may be zero or jump with a
simulated clock; arrival times never do); stamps are kept only to pair messages with each other.
"""
from dataclasses import dataclass

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

    def current(self, now, timeout, hold=False):
        """Return the wrench, or zero once :meth:`expired` unless ``hold``.

        ``hold``: an estimated load (``tip_wrench_source: estimate``) is kept when its estimator
        is late, since a payload does not vanish with its estimate; zero moved the model tip
        10 mm under a 0.14 N load while one estimate took 3-4 s and goals were judged there.
        """
        return ZERO_LOAD if self.expired(now, timeout) and not hold else self.wrench


def current_load(load, now, timeout, hold=False):
    """Wrench of a :class:`TipLoad` or zero when there is none or it expired (see ``hold``)."""
    return ZERO_LOAD if load is None else load.current(now, timeout, hold)
