"""Real tendons: per-cable stiffness, pretension, guide friction and tension limits (no ROS).

A cable's *length* is what its motor sets and ``cable_states`` reports (motor side): at the homed
straight pose it reads ``robot.straight_cable_lengths``. Its *free length* Lf is the unstretched
length of the part between the motor's reference point and the end disk:

    Lf = length - straight + straight / (1 + pretension / EA) + zero_offset

so at the homed pose a cable of stiffness EA carries its pretension (a path ``straight`` spans
Lf (1 + t / EA)). A cable is taut (tension t = EA (p / Lf - 1) > 0 for its path p, uniform
without friction) or slack (t = 0, p <= Lf): cables cannot push. An inextensible cable (EA = inf,
the default) is taut with p = Lf and any tension >= 0. The equilibrium of rod and cables for given
lengths is :mod:`continuum_statics.core.statics.length_statics`.
"""
from dataclasses import dataclass
import functools

import numpy as np

#: Keys of a ``tendons:`` block (top level, per section, or on a cable entry).
TENDON_KEYS = ('stiffness', 'pretension', 'friction', 'tension_limits', 'stick_length')


def full_circle_tension(robot):
    """Return a tension (N) bending the whole rod into a full circle from its outermost hole.

    2 pi E I / (L r): no plausible cable tension of the robot exceeds it.
    """
    offsets = robot.cable_offsets
    radius = float(np.max(np.hypot(offsets[:, 0], offsets[:, 1]), initial=1e-3))
    return 2.0 * np.pi * float(robot.c[0]) / (robot.length * radius)


@dataclass(frozen=True)
class Tendons:
    """Tendon parameters of every cable, ``robot.cable_names`` order (read-only arrays).

    :ivar stiffness: (n,) axial stiffness EA (N); ``inf`` = inextensible
    :ivar pretension: (n,) tension at the homed straight pose (N)
    :ivar friction: (n,) capstan coefficient mu at the guide holes (1)
    :ivar tension_limits: (n, 2) [min, max] tension the cable and its motor may take (N)
    :ivar zero_offset: (n,) m added to the free length (a cable homed too long: > 0)
    :ivar stick_length: (n,) m of motor travel over which a reversed cable's friction turns
        over (its guides stick first); 0: at once (:func:`length_statics.motion_since`)
    """

    stiffness: np.ndarray
    pretension: np.ndarray
    friction: np.ndarray
    tension_limits: np.ndarray
    zero_offset: np.ndarray
    stick_length: np.ndarray = None

    def __post_init__(self):
        if self.stick_length is None:  # files and callers from before stick zones
            stick = np.zeros(len(self.stiffness))
            stick.setflags(write=False)
            object.__setattr__(self, 'stick_length', stick)

    @classmethod
    def default(cls, n_cables):
        """Inextensible, frictionless cables without pretension or a tension limit."""
        limits = np.tile([0.0, np.inf], (n_cables, 1))
        return cls(np.full(n_cables, np.inf), np.zeros(n_cables), np.zeros(n_cables), limits,
                   np.zeros(n_cables), np.zeros(n_cables))

    @functools.cached_property
    def compliance(self):
        """1 / EA (1/N), 0 for inextensible cables."""
        return 1.0 / self.stiffness

    @functools.cached_property
    def is_ideal(self):
        """Inextensible, frictionless, no pretension or zero offset: lengths are paths."""
        return bool(np.all(np.isinf(self.stiffness)) and not np.any(self.pretension)
                    and not np.any(self.friction) and not np.any(self.zero_offset))

    @property
    def has_friction(self):
        """Whether any cable rubs on its guides."""
        return bool(np.any(self.friction > 0.0))

    def free_lengths(self, lengths, straight_lengths):
        """Free (unstretched) lengths Lf (m) of cables whose motors hold ``lengths`` (m)."""
        straight = np.asarray(straight_lengths, dtype=float)
        homed = straight / (1.0 + self.pretension * self.compliance)
        return np.asarray(lengths, dtype=float) - straight + homed + self.zero_offset

    def lengths_for(self, free_lengths, straight_lengths):
        """Motor-side lengths (m) that give the free lengths ``free_lengths`` (m)."""
        straight = np.asarray(straight_lengths, dtype=float)
        homed = straight / (1.0 + self.pretension * self.compliance)
        return np.asarray(free_lengths, dtype=float) + straight - homed - self.zero_offset
