"""The rod and its cables in motion: Till, Aloi & Rucker's real-time Cosserat dynamics (2019).

Each time step is a shooting problem in s like the statics' (:mod:`dynamics_kernel`), with the
time derivatives discretised by BDF-alpha (Till et al. 2019, eq. 13):

    y_t(t_i) = c0 y(t_i) + y_h,   y_h = c1 y(t_i-1) + c2 y(t_i-2) + d1 y_t(t_i-1)
    c0 = (1.5 + alpha) / (dt (1 + alpha)),  c1 = -2 / dt,  c2 = (0.5 + alpha) / (dt (1 + alpha)),
    d1 = alpha / (1 + alpha)

for y = the strains v, u and the velocities q, w at every node. alpha = -0.5 is the trapezoidal
rule (energy kept), alpha = 0 BDF2 (high frequencies damped); Till et al. use -0.2.

Scope today: the rod with gravity, a tip load, guide-disk masses and the point-moment cable
model driven by tensions (the paper's model). Lengths as inputs (real tendons: slack, stretch,
friction) and the distributed cable model are refused with a message, not approximated.
"""
from dataclasses import dataclass

import numpy as np

from continuum_statics.core.layout import (
    DYN_FORCE_AT,
    DYN_HISTORY_SIZE,
    DYN_PARAMS_SIZE,
    DYN_POSITION_AT,
    DYN_ROTATION_AT,
    DYNAMIC_STATE,
    DynamicsModel,
)
from continuum_statics.core.robot_file import check_dynamics
from continuum_statics.core.shape import Shape

#: Newton iterations per step at most (a warm step takes one or two)
MAX_ITERATIONS = 30
#: tip force and moment residual, relative to E I / L^2 and E I / L
TOLERANCE = 1e-10


@dataclass(frozen=True)
class DynamicState:
    """The rod at one instant of :class:`RodDynamics`.

    :ivar time: s since ``start``
    :ivar shape: the backbone (positions, rotations, strains) as the statics' :class:`Shape`
    :ivar velocity: (N, 3) m/s of every node, global frame
    :ivar angular_velocity: (N, 3) rad/s of every node, global frame
    :ivar tensions: (n_cables,) N, what the cables pulled with
    :ivar converged: the step's shooting problem was solved
    :ivar iterations: forward integrations the step took
    :ivar states: (N, 24) the node states (:mod:`layout`'s ``DYNAMIC_STATE``)
    """

    time: float
    shape: Shape
    velocity: np.ndarray
    angular_velocity: np.ndarray
    tensions: np.ndarray
    converged: bool
    iterations: int
    states: np.ndarray

    @property
    def tip_position(self):
        """(3,) m, global."""
        return self.shape.tip_position


def bdf_alpha(dt, alpha):
    """Return (c0, c1, c2, d1) of BDF-alpha (Till et al. 2019, eq. 13)."""
    return ((1.5 + alpha) / (dt * (1.0 + alpha)), -2.0 / dt,
            (0.5 + alpha) / (dt * (1.0 + alpha)), alpha / (1.0 + alpha))


def dynamics_params(robot):
    """Return the kernel's rod constants of ``robot`` (:mod:`layout`'s ``DYN_*_AT``)."""
    rod = robot.description.rod
    rho_j = rod.density * np.array([rod.second_moment, rod.second_moment, rod.polar_moment])
    params = np.concatenate([
        robot.d, np.full(3, rod.shear_damping), robot.c, np.full(3, rod.bending_damping),
        [rod.mass_per_length], rho_j, np.asarray(robot.gravity, dtype=float),
        robot.base_position, np.asarray(robot.base_rotation).ravel()])
    assert params.shape == (DYN_PARAMS_SIZE,)
    return params


def _node_masses(robot):
    """(N,) kg of guide disk at each node."""
    mass = np.zeros(len(robot.s_grid))
    for section in robot.sections:
        for guide in section.guides if section.disk_mass else ():
            mass[int(np.argmin(np.abs(robot.s_grid - guide)))] += section.disk_mass
    return mass


class RodDynamics:
    """Time steps of one robot's rod (``Robot.dynamics``): ``start`` then ``step`` each dt.

    :param robot: the :class:`~continuum_statics.core.robot.Robot`
    :param dt: time step (s); None: the robot file's ``dynamics.dt``
    :param alpha: BDF-alpha in [-0.5, 0]; None: the robot file's ``dynamics.alpha``
    """

    def __init__(self, robot, dt=None, alpha=None):
        settings = robot.description.dynamics
        self.dt, self.alpha = check_dynamics(
            settings.dt if dt is None else dt, settings.alpha if alpha is None else alpha,
            'dynamics')
        if robot.cable_model != 'point_moment' and len(robot.cable_names):
            raise NotImplementedError('dynamics: the %r cable model is not modelled in motion '
                                      'yet (point_moment is)' % robot.cable_model)
        self.robot = robot
        self.c0, self.c1, self.c2, self.d1 = bdf_alpha(self.dt, self.alpha)
        n = len(robot.s_grid)
        scale = robot.interval_scale
        ei, length = robot.c[0], robot.length
        self.record = DynamicsModel(
            robot.s_grid, dynamics_params(robot), _node_masses(robot),
            np.ones(n - 1) if scale is None else np.asarray(scale, dtype=float),
            np.ascontiguousarray(robot.cable_offsets, dtype=float).reshape(-1, 3),
            robot.cable_end_node, np.array([ei / length ** 2] * 3 + [ei / length] * 3))
        self._model = robot.model
        self._states = np.zeros((n, DYNAMIC_STATE))
        self._left = np.zeros((n, 6))
        self._base = np.zeros(6)
        self._last_base = np.zeros(6)  # the step before's (the predictor's)
        self._jacobian = np.eye(6)
        # BDF-alpha memory per node and side: y(t_i-1), y(t_i), y_t(t_i) -> the next history
        self._previous = np.zeros((n, 2, DYN_HISTORY_SIZE))
        self._current = np.zeros((n, 2, DYN_HISTORY_SIZE))
        self._rate = np.zeros((n, 2, DYN_HISTORY_SIZE))
        self._history = np.zeros((n, 2, DYN_HISTORY_SIZE))
        self.time = None
        self.state = None

    # -- the two calls of the contract ----------------------------------------------------
    def start(self, lengths=None, tensions=None, tip_force=(0.0, 0.0, 0.0),
              tip_moment=(0.0, 0.0, 0.0)) -> DynamicState:
        """Start at rest in static equilibrium under these loads (time 0)."""
        tensions, tip = self._loads(lengths, tensions, tip_force, tip_moment)
        static = self.robot.solve_tensions(tensions, tip[:3], tip[3:]) if len(tensions) \
            else self.robot.solve_bvp(tip[:3], tip[3:])
        # the static solution's base force and moment start Newton's method at c0 = 0 (no
        # time derivative: the same kernel solves the statics of this discretisation)
        rotation0 = static.rotations[0]
        c = self.robot.node_c[0]
        self._base[:3] = _base_force(self.robot, self.record.disk_mass, tip[:3])
        self._base[3:] = rotation0 @ (c * static.u[0])
        self._history[:] = 0.0
        self._first_solve(0.0, tensions, tip)
        self._last_base[:] = self._base
        values = self._values(0.0)
        self._previous[:] = values
        self._current[:] = values
        self._rate[:] = 0.0
        self.time = 0.0
        self.state = self._state(tensions, True, 0)
        return self.state

    def step(self, lengths=None, tensions=None, tip_force=(0.0, 0.0, 0.0),
             tip_moment=(0.0, 0.0, 0.0)) -> DynamicState:
        """Advance one dt under these loads; the result is also ``self.state``.

        A step whose shooting problem fails keeps the last state (``converged`` False).
        """
        if self.time is None:
            raise RuntimeError('dynamics: call start() before step()')
        tensions, tip = self._loads(lengths, tensions, tip_force, tip_moment)
        # y_h = c1 y(t_i-1) + c2 y(t_i-2) + d1 y_t(t_i-1) (eq. 13)
        self._history[:] = (self.c1 * self._current + self.c2 * self._previous
                            + self.d1 * self._rate)
        saved = self._base.copy(), self._states.copy(), self._left.copy()
        # predictor: the base's force and moment extrapolated from the last two steps
        self._base += self._base - self._last_base
        converged, ivps = self._solve(self.c0, tensions, tip)
        if not converged:
            self._base[:], self._states[:], self._left[:] = saved
            return DynamicState(self.state.time, self.state.shape, self.state.velocity,
                                self.state.angular_velocity, tensions, False, ivps,
                                self.state.states)
        self._last_base[:] = saved[0]
        values = self._values(self.c0)
        self._rate[:] = self.c0 * values + self._history
        self._previous[:] = self._current
        self._current[:] = values
        self.time += self.dt
        self.state = self._state(tensions, True, ivps)
        return self.state

    # -- helpers --------------------------------------------------------------------------
    def _loads(self, lengths, tensions, tip_force, tip_moment):
        if lengths is not None:
            raise NotImplementedError('dynamics: cable lengths as inputs (real tendons) are not '
                                      'modelled in motion yet; give tensions')
        n = len(self.robot.cable_names)
        tensions = np.zeros(n) if tensions is None else np.asarray(tensions, dtype=float)
        if tensions.shape != (n,) or not np.all(np.isfinite(tensions)) or np.any(tensions < 0):
            raise ValueError('tensions must be %d finite numbers >= 0 N, got %s'
                             % (n, np.asarray(tensions).tolist()))
        tip = np.concatenate([np.asarray(tip_force, dtype=float).reshape(3),
                              np.asarray(tip_moment, dtype=float).reshape(3)])
        if not np.all(np.isfinite(tip)):
            raise ValueError('tip_force and tip_moment must be finite, got %s' % tip.tolist())
        return tensions, tip

    def _solve(self, c0, tensions, tip):
        converged, ivps, _ = self._model.dynamics_solve(
            self.record, c0, self._history, self._base, self._jacobian, tip, tensions,
            self._states, self._left, TOLERANCE, MAX_ITERATIONS)
        return converged, ivps

    def _first_solve(self, c0, tensions, tip):
        """Solve with a Jacobian of forward differences at the start (no last step's)."""
        work = np.empty((6, DYNAMIC_STATE))
        scales = self.record.scales

        def residual(x):
            self._model.dynamics_shoot(self.record, c0, self._history, x, tensions,
                                       self._states, self._left, work)
            return (self._states[-1, DYN_FORCE_AT:DYN_FORCE_AT + 6] - tip) / scales

        r0 = residual(self._base)
        for j in range(6):
            x = self._base.copy()
            x[j] += 1e-7 * scales[j]
            self._jacobian[:, j] = (residual(x) - r0) / (1e-7 * scales[j])
        converged, ivps = self._solve(c0, tensions, tip)
        if not converged:
            raise ValueError('dynamics: no static equilibrium to start from under these loads')
        return ivps + 7

    def _values(self, c0):
        out = np.empty_like(self._current)
        self._model.dynamics_values(self.record, self._states, self._left, self._history, c0,
                                    out)
        return out

    def _state(self, tensions, converged, ivps):
        states = self._states.copy()
        rotations = states[:, DYN_ROTATION_AT:DYN_ROTATION_AT + 9].reshape(-1, 3, 3)
        values = self._current[:, 1]
        static = np.empty((len(states), 21))
        static[:, 0:3] = states[:, DYN_POSITION_AT:DYN_POSITION_AT + 3]
        static[:, 3:12] = states[:, DYN_ROTATION_AT:DYN_ROTATION_AT + 9]
        static[:, 12:15] = self._current[:, 0, 0:3] - np.array([0.0, 0.0, 1.0])
        static[:, 15:18] = self._current[:, 0, 3:6]
        static[:, 18:21] = states[:, DYN_FORCE_AT + 3:DYN_FORCE_AT + 6]
        shape = Shape(self.robot.s_grid, static, self._current[0, 1, 3:6].copy(),
                      self._base[:3].copy(), self.robot.node_c, self.robot.d,
                      fixed_tensions=tensions)
        velocity = np.einsum('nij,nj->ni', rotations, values[:, 6:9])
        angular = np.einsum('nij,nj->ni', rotations, values[:, 9:12])
        return DynamicState(self.time, shape, velocity, angular, tensions.copy(), converged,
                            ivps, states)


def _base_force(robot, masses, tip_force):
    """n(0) at rest (N, global): the tip force and every weight (eq. 10 integrated)."""
    weight = (robot.description.rod.mass_per_length * robot.length + masses.sum()) * np.asarray(
        robot.gravity, dtype=float)
    return weight + tip_force
