"""Fast evenly spaced backbone poses for the statics hot path (no ROS).

Every shape of a robot shares the same integration grid, so the interpolation weights and nearest
nodes are computed once per (grid, count) and each shape is then sampled in one compiled call
(~2 us). ``Shape.sample`` uses the same code.
"""
import numba
import numpy as np

from continuum_statics.core.rod.rotations import quaternion_into


@numba.njit(cache=True, nogil=True)
def _sample(positions, rotations, lower, upper, weight, nearest, points, quaternions):
    for k in range(lower.shape[0]):
        a, b, f = lower[k], upper[k], weight[k]
        for i in range(3):
            points[k, i] = positions[a, i] + f * (positions[b, i] - positions[a, i])
        quaternion_into(rotations[nearest[k]], quaternions[k])


class BackboneSampler:
    """Evenly spaced poses base -> tip for every shape on one integration grid.

    :param s_nodes: (N,) arc lengths of the grid's nodes, m (increasing)
    :param count: number of poses (>= 2); base and tip included
    """

    def __init__(self, s_nodes, count):
        s_nodes = np.asarray(s_nodes, dtype=float)
        count = int(count)
        if count < 2:
            raise ValueError('sample count must be >= 2, got %d' % count)
        self.s_nodes = s_nodes
        self.count = count
        self.s = np.linspace(s_nodes[0], s_nodes[-1], count)
        upper = np.clip(np.searchsorted(s_nodes, self.s, side='right'), 1, len(s_nodes) - 1)
        lower = upper - 1
        span = s_nodes[upper] - s_nodes[lower]
        safe_span = np.where(span > 0.0, span, 1.0)
        self._lower, self._upper = lower.astype(np.int64), upper.astype(np.int64)
        self._weight = np.where(span > 0.0, (self.s - s_nodes[lower]) / safe_span, 0.0)
        nearest = np.clip(np.searchsorted(s_nodes, self.s), 0, len(s_nodes) - 1)
        below = np.clip(nearest - 1, 0, None)
        closer_below = np.abs(s_nodes[below] - self.s) < np.abs(s_nodes[nearest] - self.s)
        self._nearest = np.where(closer_below, below, nearest).astype(np.int64)

    def matches(self, s_nodes, count):
        """Return True if this sampler serves ``count`` poses on grid ``s_nodes``."""
        return count == self.count and (s_nodes is self.s_nodes or np.array_equal(
            s_nodes, self.s_nodes))

    def sample(self, positions, rotations):
        """Return positions (count, 3), m, and quaternions (count, 4) [x, y, z, w]."""
        points = np.empty((self.count, 3))
        quaternions = np.empty((self.count, 4))
        _sample(_writable(positions), _writable(rotations), self._lower, self._upper,
                self._weight, self._nearest, points, quaternions)
        return points, quaternions


def _writable(array):
    """``array`` as a writable C float64 array (one kernel specialisation; a copy if need be)."""
    array = np.ascontiguousarray(array, dtype=float)
    return array if array.flags.writeable else array.copy()
