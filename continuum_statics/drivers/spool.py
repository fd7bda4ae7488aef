"""Cable length <-> actuator position on a spool: the one conversion every real backend shares.

doc/architecture.md, "Actuator backends" (contract)::

    L_j = L0_j + direction_j * 2 pi r_j * (p_j - zero_j) / (counts_per_rev * gear_ratio)

``L0_j`` is cable j's straight-rod length (the homed pose), ``p_j`` the actuator position in
counts and ``zero_j`` its position at the straight pose; ``direction_j = +1`` means a rising
position lengthens the cable.
"""
from dataclasses import dataclass
import math

import numpy as np


def per_cable(name, value, n_cables, integer=False):
    """Return ``value`` as an (n_cables,) array: one value for all cables or one per cable.

    :raises ValueError: wrong count, non-finite values
    """
    array = np.atleast_1d(np.asarray(value, dtype=float)).ravel()
    if array.size == 1:
        array = np.full(n_cables, array[0])
    if array.size != n_cables:
        raise ValueError('%s needs 1 or %d values (one per cable, robot-file order), got %d'
                         % (name, n_cables, array.size))
    if not np.all(np.isfinite(array)):
        raise ValueError('%s must be finite, got %s' % (name, list(array)))
    if integer:
        if np.any(array != np.round(array)):
            raise ValueError('%s must be whole numbers, got %s' % (name, list(array)))
        return array.astype(np.int64)
    return array


@dataclass(frozen=True)
class Spool:
    """Cable spools of all cables: lengths (m) <-> actuator positions (counts).

    :param straight_lengths: L0, cable lengths of the straight rod, m, (n,)
    :param directions: +1 or -1 per cable, (n,)
    :param zeros: actuator positions at the straight pose, counts, (n,)
    :param radius: spool radius per cable, m, (n,)
    :param counts_per_rev: encoder counts per motor revolution
    :param gear_ratio: motor revolutions per spool revolution
    """

    straight_lengths: np.ndarray
    directions: np.ndarray
    zeros: np.ndarray
    radius: np.ndarray
    counts_per_rev: float
    gear_ratio: float = 1.0

    @classmethod
    def from_options(cls, straight_lengths, directions, zeros, radius, counts_per_rev,
                     gear_ratio=1.0):
        """Validate backend options (scalars broadcast to every cable) and build a Spool."""
        straight = np.asarray(straight_lengths, dtype=float).ravel()
        n = straight.size
        directions = per_cable('directions', directions, n)
        if not np.all(np.isin(directions, (-1.0, 1.0))):
            raise ValueError('directions must be +1 or -1 per cable, got %s' % list(directions))
        radius = per_cable('spool_radius', radius, n)
        if np.any(radius <= 0.0):
            raise ValueError('spool_radius must be > 0 m, got %s' % list(radius))
        zeros = per_cable('zero positions', zeros, n)
        if not (math.isfinite(counts_per_rev) and counts_per_rev > 0):
            raise ValueError('counts_per_rev must be > 0, got %r' % counts_per_rev)
        if not (math.isfinite(gear_ratio) and gear_ratio > 0):
            raise ValueError('gear_ratio must be > 0, got %r' % gear_ratio)
        return cls(straight, directions, zeros, radius, float(counts_per_rev), float(gear_ratio))

    @property
    def metres_per_count(self):
        """Cable travel per count, m, (n,) (always positive)."""
        return 2.0 * math.pi * self.radius / (self.counts_per_rev * self.gear_ratio)

    def lengths(self, positions):
        """Cable lengths, m, from actuator positions (counts)."""
        positions = np.asarray(positions, dtype=float)
        return self.straight_lengths + self.directions * self.metres_per_count * (
            positions - self.zeros)

    def positions(self, lengths):
        """Actuator positions (counts, float) for cable lengths in m."""
        lengths = np.asarray(lengths, dtype=float)
        return self.zeros + self.directions * (lengths - self.straight_lengths) / \
            self.metres_per_count

    def speeds(self, position_rates):
        """Cable speeds, m/s, from actuator speeds in counts/s."""
        return self.directions * self.metres_per_count * np.asarray(position_rates, dtype=float)

    def tensions(self, torques):
        """Cable tensions, N, from spool torques, N m (positive torque lengthens the cable).

        A pulling cable loads the spool towards shortening, so tension = -direction * torque /
        radius, and a slack cable (negative result) reads 0 N.
        """
        return np.maximum(0.0, -self.directions * np.asarray(torques, dtype=float) / self.radius)

    def with_zeros(self, zeros):
        """Return a copy with new zero positions (homing)."""
        return Spool(self.straight_lengths, self.directions,
                     per_cable('zero positions', zeros, self.straight_lengths.size),
                     self.radius, self.counts_per_rev, self.gear_ratio)
