"""The solved backbone: a small immutable record of arrays, base to tip."""
import numpy as np

from continuum_statics.core.description.layout import BENDING, POSITION, ROTATION, STRETCH
from continuum_statics.core.rod.backbone_sampling import BackboneSampler
from continuum_statics.core.rod.rotations import rotation_to_quaternion


class Shape:
    """Backbone state at every integration node, base (index 0) to tip (index -1).

    Built from the kernel's (N, 18) state array without copying; the array views below are
    read-only.

    :ivar s: (N,) unstretched arc length (m)
    :ivar positions: (N, 3) backbone points r(s), global frame (m)
    :ivar rotations: (N, 3, 3) orientations R(s), local -> global
    :ivar v: (N, 3) local shear/stretch strain (1 = unstretched along local z)
    :ivar u: (N, 3) local bending and twist (1/m)
    :ivar u0: (3,) base bending u(0) the shape was integrated from (1/m)
    :ivar tip_force: (3,) tip force F, global frame (N)
    :ivar c: (3,) or (N, 3) per node: bending/torsional stiffness diagonal C (N m^2)
    :ivar d: (3,) shear/axial stiffness diagonal D (N)
    :ivar state: solver state (see :mod:`continuum_statics.core.robot`), or None
    :ivar fixed_tensions: (n_cables,) tensions given to the solver (N), or None
    :ivar contacts: where the body presses on obstacles, a tuple of
        :class:`~continuum_statics.core.statics.contact.Contact` (empty: touching nothing)
    """

    __slots__ = ('s', 'states', 'u0', 'tip_force', 'c', 'd', 'state', 'fixed_tensions',
                 'contacts')

    def __init__(self, s, states, u0, tip_force, c, d, state=None, fixed_tensions=None):
        states.setflags(write=False)
        self.s, self.states, self.u0, self.tip_force, self.c, self.d = (
            s, states, u0, tip_force, c, d)
        # the solver state this shape was integrated from (warm starts, interpolation)
        self.state, self.fixed_tensions = state, fixed_tensions
        self.contacts = ()

    @property
    def positions(self):
        """(N, 3) backbone points r(s), global frame (m)."""
        return self.states[:, POSITION]

    @property
    def rotations(self):
        """(N, 3, 3) orientations R(s), local -> global."""
        return self.states[:, ROTATION].reshape(-1, 3, 3)

    @property
    def v(self):
        """(N, 3) local shear/stretch strain v (e3 when unstrained)."""
        return self.states[:, STRETCH] + np.array([0.0, 0.0, 1.0])

    @property
    def u(self):
        """(N, 3) local bending and twist (1/m)."""
        return self.states[:, BENDING]

    @property
    def tip_position(self):
        """Tip position r(L), global frame (m)."""
        return self.states[-1, POSITION]

    @property
    def tip_rotation(self):
        """Tip orientation R(L)."""
        return self.states[-1, ROTATION].reshape(3, 3)

    @property
    def n(self):
        """(N, 3) internal force n = R D (v - e3), global frame (N), eq. 6."""
        local = self.d * self.states[:, STRETCH]  # the kernel keeps v - e3 at full precision
        return np.einsum('nij,nj->ni', self.rotations, local)

    @property
    def m(self):
        """(N, 3) internal moment m = R C u, global frame (N m), eq. 7."""
        return np.einsum('nij,nj->ni', self.rotations, self.c * self.u)

    @property
    def tip_moment(self):
        """The rod's internal moment at the tip, m(L) = R C u (global, N m)."""
        return self.tip_rotation @ (np.broadcast_to(self.c, (len(self.s), 3))[-1]
                                    * self.states[-1, BENDING])

    def sample(self, count):
        """Evenly spaced poses along the backbone, base and tip included.

        Positions are interpolated linearly between nodes and orientations taken from the
        nearest node, which is exact at the ends and within the integration step elsewhere.
        For many shapes on one grid, keep a :class:`BackboneSampler` instead.

        :param count: number of poses (>= 2)
        :returns: s (count,) in m, positions (count, 3) in m, quaternions (count, 4) [x, y, z, w]
        """
        sampler = BackboneSampler(self.s, count)
        positions, quaternions = sampler.sample(self.positions, self.rotations)
        return sampler.s, positions, quaternions

    def to_dict(self):
        """Plain-Python form for JSON output (lists of floats, SI units)."""
        return {
            's': self.s.tolist(),
            'positions': self.positions.tolist(),
            'quaternions_xyzw': rotation_to_quaternion(self.rotations).tolist(),
            'u': self.u.tolist(),
            'v': self.v.tolist(),
            'n': self.n.tolist(),
            'm': self.m.tolist(),
            'u0': self.u0.tolist(),
            'tip_force': self.tip_force.tolist(),
        }
