"""Where each cable runs: its hole positions along the rod, named once (paper eq. 11; R&W 2011).

A cable's route is l(s), the position of its hole in the rod's local frame (m, z = 0: the hole
lies in the plane of its disk), and l'(s) = dl/ds. Three kinds, chosen per cable in the robot
file (``offset``, ``offsets`` or ``helix``):

- :class:`Straight`: one constant offset, parallel to the backbone (the paper's robots);
- :class:`GuideOffsets`: one offset per disk of the cable's path (the base disk, then every guide
  up to its end disk), linear in s between disks, so l' jumps at a disk where the cable turns;
- :class:`Helix`: l = radius (cos phi, sin phi, 0), phi = start_angle + 2 pi turns_per_metre s
  (Rucker & Webster 2011, "Statics and dynamics of continuum robots with general tendon routing
  and external loading", IEEE T-RO 27(6), sec. III and their helical example).

:class:`Routing` builds, once per robot, every table the compiled code reads:
``hole_offsets`` (n_cables, G, 3) the hole at each guide node (eq. 11: hole = r + R l; cable
lengths, capstan wraps, markers), ``stage_routes`` (3 (N - 1), 6 n_cables): row 3 i + k holds, for
every cable j, l (columns 6 j..6 j + 2) then l' (6 j + 3..6 j + 5) at the Runge-Kutta point k
(0 start, 1 middle, 2 end) of integration interval i (the distributed model's tendon tangent
v + u x l + l', R&W eq. 12 in the body frame; one 2-D table so the kernel's inner loop indexes
it like the constant offsets it replaces; a single row when every cable is straight),
``route_kinks`` (N - 1,) whether some cable's l' jumps at the start of interval i (the strain
jumps there, at a disk where a cable turns), and
``end_offsets`` (n_cables, 3) the hole at each cable's end disk (its pull's arm, e3 x l).
"""
import dataclasses
from dataclasses import dataclass
import math

import numba
import numpy as np

from continuum_statics.core.description.layout import POSITION_AT, ROTATION_AT


@dataclass(frozen=True)
class Straight:
    """A cable parallel to the backbone at a constant hole ``offset`` (3,), m."""

    offset: np.ndarray

    def at(self, s, inside=None):
        """Return l (k, 3) and l' (k, 3) at arc lengths ``s`` (k,), m."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        return np.tile(self.offset, (len(s), 1)), np.zeros((len(s), 3))


@dataclass(frozen=True)
class Helix:
    """A cable wound round the rod: hole radius (m), angle at s = 0 (rad), turns per metre."""

    radius: float
    start_angle: float
    turns_per_metre: float

    def at(self, s, inside=None):
        """Return l (k, 3) and l' (k, 3) at arc lengths ``s`` (k,), m."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        rate = 2.0 * math.pi * self.turns_per_metre
        phi = self.start_angle + rate * s
        zero = np.zeros_like(s)
        offsets = self.radius * np.stack([np.cos(phi), np.sin(phi), zero], axis=1)
        tangents = self.radius * rate * np.stack([-np.sin(phi), np.cos(phi), zero], axis=1)
        return offsets, tangents

    def turned(self, angle, scale=1.0):
        """Return this helix turned about the backbone by ``angle`` (rad), radius x ``scale``."""
        return dataclasses.replace(self, radius=self.radius * scale,
                                   start_angle=self.start_angle + angle)


@dataclass(frozen=True)
class GuideOffsets:
    """A hole per disk, straight in the local frame between disks.

    ``disks`` (k,) arc lengths from the base disk (0) to the end disk, m; ``offsets`` (k, 3)
    the hole in each, m.
    """

    disks: np.ndarray
    offsets: np.ndarray

    def at(self, s, inside=None):
        """Return l (k, 3) and l' (k, 3) at ``s`` (k,), m.

        On the piece between disks holding ``inside`` (default ``s``): at a disk, l' is
        one-sided. Beyond the end disk, l stays and l' = 0.
        """
        s = np.atleast_1d(np.asarray(s, dtype=float))
        inside = s if inside is None else np.atleast_1d(np.asarray(inside, dtype=float))
        piece = np.clip(np.searchsorted(self.disks, inside, side='right') - 1, 0,
                        len(self.disks) - 2)
        a, b = self.disks[piece], self.disks[piece + 1]
        slope = (self.offsets[piece + 1] - self.offsets[piece]) / (b - a)[:, None]
        beyond = inside > self.disks[-1]
        slope[beyond] = 0.0
        offsets = self.offsets[piece] + slope * (np.minimum(s, b) - a)[:, None]
        offsets[beyond] = self.offsets[-1]
        return offsets, slope

    def turned(self, angle, scale=1.0):
        """Return these holes turned about the backbone by ``angle`` (rad), radius x ``scale``."""
        c, s = math.cos(angle), math.sin(angle)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) * scale
        return dataclasses.replace(self, offsets=self.offsets @ turn.T)


@dataclass(frozen=True)
class Routing:
    """The route tables of one robot (module docstring; all in the rod's local frame, m)."""

    hole_offsets: np.ndarray  # (n_cables, G, 3) hole at each guide node, guide 0 = base disk
    stage_routes: np.ndarray  # (3 (N - 1), 6 n_cables) l, l' at each interval's RK points (1 row:
    # every cable straight)
    route_kinks: np.ndarray  # (N - 1,) bool: some cable's l' jumps where interval i starts
    end_offsets: np.ndarray  # (n_cables, 3) hole at each cable's end disk
    straight: bool  # every cable is parallel to the backbone (l' = 0, l constant)

    @classmethod
    def build(cls, routes, s_grid, guide_nodes, cable_last_guide):
        """Tables of ``routes`` on the integration nodes ``s_grid`` (N,), m.

        ``routes``: one :class:`Straight`, :class:`Helix` or :class:`GuideOffsets` per cable.
        """
        s_grid = np.asarray(s_grid, dtype=float)
        start, end = s_grid[:-1], s_grid[1:]
        middle = 0.5 * (start + end)
        n, intervals, guides = len(routes), len(s_grid) - 1, len(guide_nodes)
        holes = np.zeros((n, guides, 3))
        straight = all(isinstance(route, Straight) for route in routes)
        stages = np.zeros((intervals, 3, n, 6))
        for j, route in enumerate(routes):
            holes[j] = route.at(s_grid[guide_nodes])[0]
            for stage, s in enumerate((start, middle, end)):
                stages[:, stage, j, :3], stages[:, stage, j, 3:] = route.at(s, inside=middle)
        kinks = np.zeros(intervals, dtype=bool)
        kinks[1:] = np.any(stages[1:, 0, :, 3:] != stages[:-1, 2, :, 3:], axis=(1, 2))
        ends = holes[np.arange(n), np.asarray(cable_last_guide, dtype=np.int64)]
        stages = stages.reshape(3 * intervals, 6 * n)
        if straight:  # one row for all: the kernel's loads stay in one cache line
            stages = stages[:1]
        return cls(np.ascontiguousarray(holes), np.ascontiguousarray(stages), kinks,
                   np.ascontiguousarray(ends), straight)


@numba.njit(cache=True, nogil=True, inline='always')
def hole_in(y, offset):
    """Eq. 11 (with the errata): the hole r + R l of local ``offset`` l (3,) at node state ``y``.

    ``y`` is one node row (layout ``core/description/layout.py``): r at POSITION_AT, R row-major at
    ROTATION_AT; returns the global point as a 3-tuple (m).
    """
    r, q = POSITION_AT, ROTATION_AT
    l0, l1, l2 = offset[0], offset[1], offset[2]
    return (y[r] + (y[q] * l0 + y[q + 1] * l1 + y[q + 2] * l2),
            y[r + 1] + (y[q + 3] * l0 + y[q + 4] * l1 + y[q + 5] * l2),
            y[r + 2] + (y[q + 6] * l0 + y[q + 7] * l1 + y[q + 8] * l2))


def holes_at(positions, rotations, offsets):
    """Eq. 11 for arrays: holes (..., 3) = positions (..., 3) + rotations (..., 3, 3) offsets."""
    return np.asarray(positions) + np.einsum('...ij,...j->...i', rotations, offsets)
