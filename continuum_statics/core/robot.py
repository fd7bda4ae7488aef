"""The robot model: a validated description plus the solvers that act on it (no ROS)."""
import dataclasses
import math

import numpy as np

from continuum_statics.core import bvp, estimation, tip_goal
from continuum_statics.core.inputs import as_vector
from continuum_statics.core.kernel import (
    cable_lengths_batch,
    integrate_batch,
    pack_params,
    probe,
    tip_jacobian,
)
from continuum_statics.core.robot_file import read_robot_description
from continuum_statics.core.rotations import quaternion_to_rotation
from continuum_statics.core.shape import Shape


def load_robot(path):
    """Load a robot file (YAML) into a :class:`Robot`; ``ValueError`` names any bad field."""
    return Robot(read_robot_description(path))


def _grid(length, guides, steps):
    """Integration nodes with a node at every guide, and the guide node indices.

    Each stretch between breakpoints gets ceil(steps * stretch / L) RK4 steps, so no step is
    longer than L / steps. The cable path starts at the base disk, node 0.
    """
    breaks = np.unique(np.concatenate([[0.0, length], guides]))
    pieces, guide_nodes = [np.zeros(1)], [0]
    for a, b in zip(breaks[:-1], breaks[1:]):
        count = max(1, math.ceil(steps * (b - a) / length - 1e-9))
        pieces.append(np.linspace(a, b, count + 1)[1:])
    grid = np.concatenate(pieces)
    for g in guides:
        node = int(np.argmin(np.abs(grid - g)))
        if node != 0:
            guide_nodes.append(node)
    return grid, np.array(guide_nodes, dtype=np.int64)


class Robot:
    """A continuum robot: rod, base pose, gravity, cables and guides, solver settings.

    Immutable once built; every solve is a pure function of its arguments. SI units throughout:
    m, N, N m, 1/m for the bending strain u.
    """

    def __init__(self, description):
        self.description = description
        rod = description.rod
        self.rod = rod
        self.name = description.name
        self.length = rod.length
        self.base_frame_id = description.base_frame_id
        self.base_position = description.base_position
        self.base_rotation = quaternion_to_rotation(description.base_orientation)
        self.gravity = description.gravity
        self.cable_names = description.cable_names
        self.cable_offsets = description.cable_offsets
        self.cable_length_limits = description.cable_length_limits
        self.guides = description.guides
        self.solver = description.solver
        self.c = rod.bending_stiffness
        self.d = rod.shear_stiffness
        # distributed weight rho*A*g*e_g (N/m), the body force f of eqs. 3, 4 and 8
        self.body_force = rod.mass_per_length * np.asarray(self.gravity)
        self.params = pack_params(self.c, self.d, self.body_force, self.base_position,
                                  self.base_rotation)
        self.s_grid, self.guide_nodes = _grid(rod.length, self.guides, self.solver.steps)
        self.free_moment_basis = _free_moment_basis(self.cable_offsets)
        self.straight_cable_lengths = self.cable_lengths(
            self._shape(np.zeros(3), np.zeros(3), _straight_states(self)))

    def with_solver(self, **settings):
        """Copy of this robot with some solver settings replaced (e.g. ``steps=200``)."""
        solver = dataclasses.replace(self.solver, **settings)
        return Robot(dataclasses.replace(self.description, solver=solver))

    # -- initial-value problem -------------------------------------------------------------
    def integrate(self, tip_forces, base_bendings, params=None):
        """Batch IVP: (B, 3) tip forces and (B, 3) u(0) -> (B, N, 18) states (kernel layout)."""
        return integrate_batch(self.s_grid, self.params if params is None else params,
                               tip_forces, base_bendings)

    def _shape(self, u0, tip_force, states):
        return Shape(self.s_grid, states, u0, tip_force, self.c, self.d)

    def solve_ivp(self, u0, tip_force=(0.0, 0.0, 0.0)):
        """Shape for a base bending u(0) (1/m, local frame) and a tip force F (N, global).

        Integrates eqs. 1, 2, 8, 9 from the base with v(0) from eq. 10: no iteration, which is
        what makes the paper's approach real-time.
        """
        u0 = as_vector(u0, 3, 'u0')
        tip_force = as_vector(tip_force, 3, 'tip_force')
        states = self.integrate(tip_force[None, :], u0[None, :])
        return self._shape(u0, tip_force, states[0])

    def solve_bvp(self, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0), u0_guess=None):
        """Shape under a tip force F (N) and tip moment (N m), both global: shoots on u(0).

        See :func:`continuum_statics.core.bvp.solve_bvp`; raises :class:`bvp.ConvergenceError`.
        """
        tip_force = as_vector(tip_force, 3, 'tip_force')
        tip_moment = as_vector(tip_moment, 3, 'tip_moment')
        if u0_guess is not None:
            u0_guess = as_vector(u0_guess, 3, 'u0_guess')
        u0 = bvp.solve_bvp(self, tip_force, tip_moment, u0_guess)
        return self.solve_ivp(u0, tip_force)

    # -- cables ----------------------------------------------------------------------------
    def cable_lengths(self, shape):
        """Cable lengths (n_cables,) in m of a shape, order ``cable_names`` (eq. 11, errata)."""
        positions = np.ascontiguousarray(shape.positions)[None]
        rotations = np.ascontiguousarray(shape.rotations)[None]
        return cable_lengths_batch(positions, rotations, self.guide_nodes,
                                   self.cable_offsets)[0]

    # -- Jacobians -------------------------------------------------------------------------
    def force_step(self):
        """Finite-difference step for tip forces (N): 1e-7 of the load scale E I / L^2."""
        return 1e-7 * self.c[0] / self.length ** 2

    def bending_step(self):
        """Finite-difference step for u(0) (1/m): 1e-7 rad over the rod length."""
        return 1e-7 / self.length

    def jacobian(self, u0, tip_force=(0.0, 0.0, 0.0)):
        """6x6 tip Jacobian: rows [linear (m); angular (rad)], columns [F (N); u(0) (1/m)].

        Forward differences as in the paper (section V.B), all seven IVPs in one kernel call;
        the angular rows are vee(dR R^T) (the paper's omega-hat = R-dot R^T), global frame.
        """
        return tip_jacobian(self.s_grid, self.params, as_vector(tip_force, 3, 'tip_force'),
                            as_vector(u0, 3, 'u0'), self.force_step(), self.bending_step())

    def cable_jacobian(self, u0, tip_force=(0.0, 0.0, 0.0)):
        """d(cable lengths)/d u(0), (n_cables, 3) in m per 1/m; one batched kernel call."""
        _, jac, _ = self.probe(as_vector(u0, 3, 'u0'), as_vector(tip_force, 3, 'tip_force'),
                               np.zeros(3))
        return jac[3:3 + len(self.cable_names)]

    def probe(self, u0, tip_force, tip_moment):
        """Tip, cable lengths and free tip moments with their u(0) Jacobian (kernel.probe).

        Unchecked fast path for the solvers: arguments must be float (3,) arrays.
        """
        return probe(self.s_grid, self.params, tip_force, tip_moment, u0, self.bending_step(),
                     self.guide_nodes, self.cable_offsets, self.free_moment_basis)

    # -- inverse problems ------------------------------------------------------------------
    def estimate_shape(self, cable_lengths, tip_force=(0.0, 0.0, 0.0), u0_guess=None,
                       tip_moment=(0.0, 0.0, 0.0)):
        """Shape from measured cable lengths (m) and a tip load (N, N m); see :mod:`estimation`."""
        return estimation.estimate_shape(self, cable_lengths, tip_force, u0_guess, tip_moment)

    def solve_tip_goal(self, goal_position, tip_force=(0.0, 0.0, 0.0), u0_guess=None,
                       tolerance=None, tip_moment=(0.0, 0.0, 0.0)):
        """u(0) and cable lengths that put the tip at a goal (m); see :mod:`tip_goal`."""
        return tip_goal.solve_tip_goal(self, goal_position, tip_force, u0_guess, tolerance,
                                       tip_moment)


def _free_moment_basis(offsets):
    """Orthonormal basis (3, k) of tip moments (local frame) that no cable can apply.

    A cable ending at a hole l (local) pulls back along the backbone, so the moment it applies is
    parallel to e3 x l: never about the axis, and only in the plane its hole spans. These
    components of the tip moment are zero at equilibrium; they fix the twist and, with fewer
    than two independent hole directions, the bending the cables cannot observe.
    """
    arms = np.cross([0.0, 0.0, 1.0], np.reshape(offsets, (-1, 3)))
    if arms.shape[0] == 0:
        return np.eye(3)
    _, sing, vt = np.linalg.svd(arms)
    rank = int(np.sum(sing > 1e-9 * max(sing[0], 1e-300)))
    return vt[rank:].T.copy()


def _straight_states(robot):
    """Kernel states of the straight, unloaded rod (for the reference cable lengths)."""
    s = robot.s_grid
    states = np.zeros((len(s), 18))
    axis = robot.base_rotation[:, 2]
    states[:, 0:3] = robot.base_position + s[:, None] * axis
    states[:, 3:12] = robot.base_rotation.ravel()
    return states
