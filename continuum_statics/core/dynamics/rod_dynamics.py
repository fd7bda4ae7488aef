"""The rod and its cables in motion: Till, Aloi & Rucker's real-time Cosserat dynamics (2019).

Each time step is a shooting problem in s like the statics' (:mod:`dynamics_kernel`), with the
time derivatives discretised by BDF-alpha (Till et al. 2019, eq. 13):

    y_t(t_i) = c0 y(t_i) + y_h,   y_h = c1 y(t_i-1) + c2 y(t_i-2) + d1 y_t(t_i-1)
    c0 = (1.5 + alpha) / (dt (1 + alpha)),  c1 = -2 / dt,  c2 = (0.5 + alpha) / (dt (1 + alpha)),
    d1 = alpha / (1 + alpha)

for y = the strains v, u and the velocities q, w at every node. alpha -> -0.5 is the trapezoidal
rule (energy kept), alpha = 0 BDF2 (high frequencies damped); Till et al. use -0.2. -0.45 is the
least allowed (``robot_file.MIN_ALPHA``: at -0.5 a spurious mode of the discrete rod grows).

Scope today: the rod with gravity, a tip load, guide-disk masses and the point-moment cable
model driven by tensions (the paper's model). Lengths as inputs (real tendons: slack, stretch,
friction) and the distributed cable model are refused with a message, not approximated.
"""
import functools
from typing import NamedTuple

import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.description.layout import (
    BENDING,
    DYN_HIST_ANGULAR_AT,
    DYN_HIST_BENDING_AT,
    DYN_HIST_STRETCH_AT,
    DYN_HIST_VELOCITY_AT,
    DYN_HISTORY_SIZE,
    DYN_MOMENT_AT,
    DYN_PARAMS_SIZE,
    DYN_POSITION_AT,
    DYN_ROTATION_AT,
    DYNAMIC_STATE,
    MOMENT,
    POSITION,
    ROTATION,
    STATE_SIZE,
    STRETCH,
    CableInputs,
    DynamicsModel,
)
from continuum_statics.core.description.robot_file import check_dynamics
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.statics.length_statics import motion_since, problem_constants

#: Newton iterations per step at most (a warm step takes one or two)
MAX_ITERATIONS = 30
#: residual of a solved step, each value in its unit (DynamicsModel.scales): ~1e-8 m at the
#: tip (1e-8 took a fourth evaluation in the median step for 1e-9 m)
TOLERANCE = 1e-7


class DynamicState:
    """The rod at one instant of :class:`RodDynamics` (its arrays are built when read).

    :ivar time: s since ``start``
    :ivar shape: the backbone (positions, rotations, strains) as the statics' :class:`Shape`
    :ivar velocity: (N, 3) m/s of every node, global frame
    :ivar angular_velocity: (N, 3) rad/s of every node, global frame
    :ivar tensions: (n_cables,) N at the motors (driven by lengths) or as given
    :ivar end_tensions: (n_cables,) N at the end disks, what bends the rod
    :ivar converged: the step's shooting problem was solved
    :ivar iterations: forward integrations the step took (a Jacobian refresh counts its cost)
    :ivar states: (N, 24) the node states (:mod:`layout`'s ``DYNAMIC_STATE``)
    """

    def __init__(self, robot, time, states, nodes, base_force, tensions, end_tensions,
                 converged, iterations):
        self._robot, self._nodes, self._base_force = robot, nodes, base_force
        self.time, self.states, self.tensions = time, states, tensions
        self.end_tensions, self.converged, self.iterations = end_tensions, converged, iterations

    @functools.cached_property
    def shape(self):
        """The backbone as a :class:`Shape` (strains: each node's left limit)."""
        states, nodes, robot = self.states, self._nodes, self._robot
        static = np.empty((len(states), STATE_SIZE))
        static[:, POSITION] = states[:, DYN_POSITION_AT:DYN_POSITION_AT + 3]
        static[:, ROTATION] = states[:, DYN_ROTATION_AT:DYN_ROTATION_AT + 9]
        stretch = nodes[:, DYN_HIST_STRETCH_AT:DYN_HIST_STRETCH_AT + 3]
        bending = nodes[:, DYN_HIST_BENDING_AT:DYN_HIST_BENDING_AT + 3]
        static[:, STRETCH] = stretch - np.array([0.0, 0.0, 1.0])
        static[:, BENDING] = bending
        static[:, MOMENT] = states[:, DYN_MOMENT_AT:DYN_MOMENT_AT + 3]
        return Shape(robot.s_grid, static, bending[0].copy(), self._base_force,
                     robot.node_c, robot.d, fixed_tensions=self.end_tensions)

    @functools.cached_property
    def velocity(self):
        """(N, 3) m/s, global."""
        return np.einsum('nij,nj->ni', self._rotations(),
                         self._nodes[:, DYN_HIST_VELOCITY_AT:DYN_HIST_VELOCITY_AT + 3])

    @functools.cached_property
    def angular_velocity(self):
        """(N, 3) rad/s, global."""
        return np.einsum('nij,nj->ni', self._rotations(),
                         self._nodes[:, DYN_HIST_ANGULAR_AT:DYN_HIST_ANGULAR_AT + 3])

    @property
    def tip_position(self):
        """(3,) m, global."""
        return self.states[-1, DYN_POSITION_AT:DYN_POSITION_AT + 3]

    def _rotations(self):
        return self.states[:, DYN_ROTATION_AT:DYN_ROTATION_AT + 9].reshape(-1, 3, 3)

    def failed(self, iterations):
        """Return this state as kept by a step that failed after ``iterations``."""
        return DynamicState(self._robot, self.time, self.states, self._nodes, self._base_force,
                            self.tensions, self.end_tensions, False, iterations)


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

    Cables are driven either by tensions (N at the end disks) or, for real tendons, by the
    motors' lengths (m, as ``solve_lengths``: stretch, slack, pretension and capstan friction
    with its direction of motion); ``start`` chooses which for the whole run.

    :param robot: the :class:`~continuum_statics.core.robot.Robot`
    :param dt: time step (s); None: the robot file's ``dynamics.dt``
    :param alpha: BDF-alpha in [-0.45, 0]; None: the robot file's ``dynamics.alpha``
    :param tip_mass: kg of payload at the tip (its weight and inertia; rotary inertia ignored)
    """

    def __init__(self, robot, dt=None, alpha=None, tip_mass=0.0):
        settings = robot.description.dynamics
        self.dt, self.alpha = check_dynamics(
            settings.dt if dt is None else dt, settings.alpha if alpha is None else alpha,
            'dynamics')
        if robot.cable_model != 'point_moment' and len(robot.cable_names):
            raise NotImplementedError('dynamics: the %r cable model is not modelled in motion '
                                      'yet (point_moment is)' % robot.cable_model)
        self.robot = robot
        self.c0, self.c1, self.c2, self.d1 = bdf_alpha(self.dt, self.alpha)
        self._coefficients = (self.c0, self.c1, self.c2, self.d1)
        tip_mass = float(tip_mass)
        if not (np.isfinite(tip_mass) and tip_mass >= 0.0):
            raise ValueError('tip_mass must be finite and >= 0 kg, got %r' % tip_mass)
        self.tip_mass = tip_mass
        self.record = dynamics_model(robot, self.dt, self.c0, tip_mass)
        self.segments = len(self.record.bounds) - 1
        self._model = robot.model
        self._friction = problem_constants(robot).friction
        # free length = motor length + this (Tendons.free_lengths, fixed per robot)
        self._free_offset = robot.tendons.free_lengths(np.zeros(len(robot.cable_names)),
                                                       robot.straight_cable_lengths)
        n = len(robot.s_grid)
        self._states = np.zeros((n, DYNAMIC_STATE))
        self._left = np.zeros((n, 6))
        self._stages = np.zeros((n - 1, 4, DYN_HISTORY_SIZE))  # v, u, q, w at the RK4 stages
        self._motor = np.zeros(len(robot.cable_names))  # motor-side tensions (N)
        # BDF-alpha memory per RK4 stage: y(t_i-1), y(t_i), y_t(t_i) -> the next history
        self._previous = np.zeros_like(self._stages)
        self._current = np.zeros_like(self._stages)
        self._rate = np.zeros_like(self._stages)
        self._history = np.zeros_like(self._stages)
        self._memory = (self._previous, self._current, self._rate, self._history)
        self.driven_by_lengths = False
        self._motion = None  # length-driven: each cable's friction state (length_statics)
        self.time = None
        self.state = None

    # -- the two calls of the contract ----------------------------------------------------
    def start(self, lengths=None, tensions=None, tip_force=(0.0, 0.0, 0.0),
              tip_moment=(0.0, 0.0, 0.0)) -> DynamicState:
        """Start at rest in static equilibrium under these loads (time 0).

        ``lengths`` (m, the motors') drive the cables from now on; else ``tensions`` (N; None:
        slack cables).
        """
        robot = self.robot
        self.driven_by_lengths = lengths is not None
        if self.driven_by_lengths and robot.tendons.is_ideal:
            raise NotImplementedError('dynamics: lengths drive real tendons (a tendons block: '
                                      'stretch, pretension); ideal cables take tensions')
        tip = _tip(tip_force, tip_moment)
        # the statics carry the payload as a tip force: its weight
        weight = self.tip_mass * np.asarray(robot.gravity, dtype=float)
        if self.driven_by_lengths:
            lengths = as_vector(lengths, len(robot.cable_names), 'lengths')
            static = robot.solve_lengths(lengths, tip[:3] + weight, tip[3:])
            if not static.converged:
                raise ValueError('dynamics: no static equilibrium at these lengths: %s'
                                 % static.message)
            self._motion = static
            end_tensions = static.end_tensions
            shape = static.shape
        else:
            end_tensions = self._tensions(tensions)
            shape = robot.solve_tensions(end_tensions, tip[:3] + weight, tip[3:]) \
                if len(end_tensions) else robot.solve_bvp(tip[:3] + weight, tip[3:])
        # the unknowns: n(0), m(0), the state at each later segment's start, then (driven by
        # lengths) each cable's end tension
        rest = _unknowns_at_rest(robot, self.record, shape, tip)
        self._x = np.concatenate([rest, end_tensions]) if self.driven_by_lengths else rest
        self._last_x = np.array([self._x, self._x])  # the two steps before (the predictor's)
        self._jacobian = np.zeros((len(self._x), len(self._x)))  # its inverse (Broyden)
        self._pivots = np.zeros(len(self._x), dtype=np.int64)
        # the static solution starts Newton's method at c0 = 0 (no time derivative: the same
        # kernel solves the statics of this discretisation)
        self._history[:] = 0.0
        converged, _ = self._solve(0.0, self._cables(lengths, end_tensions), tip, refresh=True)
        if not converged:
            raise ValueError('dynamics: no static equilibrium to start from under these loads')
        self._last_x[:] = self._x[None, :]
        self._previous[:] = self._stages
        self._current[:] = self._stages
        self._rate[:] = 0.0
        self.time = 0.0
        self.state = self._state(True, 0)
        return self.state

    def step(self, lengths=None, tensions=None, tip_force=(0.0, 0.0, 0.0),
             tip_moment=(0.0, 0.0, 0.0)) -> DynamicState:
        """Advance one dt under these inputs; the result is also ``self.state``.

        A step whose shooting problem fails keeps the last state (``converged`` False).
        """
        if self.time is None:
            raise RuntimeError('dynamics: call start() before step()')
        if self.driven_by_lengths != (lengths is not None):
            raise ValueError('dynamics: started driven by %s: give %s every step'
                             % (('lengths', 'lengths') if self.driven_by_lengths
                                else ('tensions', 'tensions')))
        tip = _tip(tip_force, tip_moment)
        cables = self._cables(lengths, tensions)
        converged, ivps, _ = self._model.dynamics_advance(
            self.record, self._coefficients, self._memory, self._x, self._last_x,
            self._jacobian, self._pivots, tip, cables, self._states, self._left, self._stages,
            self._motor, TOLERANCE, MAX_ITERATIONS)
        if not converged:  # every array as before the step: the last state stands
            return self.state.failed(ivps)
        self.time += self.dt
        self.state = self._state(True, ivps)
        return self.state

    # -- helpers --------------------------------------------------------------------------
    def _tensions(self, tensions):
        n = len(self.robot.cable_names)
        tensions = np.zeros(n) if tensions is None else np.asarray(tensions, dtype=float)
        if tensions.shape != (n,) or not np.all(np.isfinite(tensions)) or np.any(tensions < 0):
            raise ValueError('tensions must be %d finite numbers >= 0 N, got %s'
                             % (n, np.asarray(tensions).tolist()))
        return tensions

    def _cables(self, lengths, tensions):
        """Return the step's :class:`CableInputs`; driven by lengths, friction moves on."""
        robot = self.robot
        if not self.driven_by_lengths:
            tensions = self._tensions(tensions)
            return CableInputs(tensions, _NONE, np.zeros(len(tensions)))
        free = as_vector(lengths, len(robot.cable_names), 'lengths') + self._free_offset
        motion, reference = motion_since(robot, free, self._motion)
        self._motion = _Motion(free, reference, motion)
        return CableInputs(_NONE, free, self._friction * motion + 0.0)

    def _solve(self, c0, cables, tip, refresh=False):
        converged, ivps, _ = self._model.dynamics_solve(
            self.record, c0, self._history, self._x, self._jacobian, self._pivots, tip,
            cables, self._states, self._left, self._stages, self._motor, TOLERANCE, MAX_ITERATIONS,
            refresh)
        return converged, ivps

    def _state(self, converged, ivps):
        # each node's v, u, q, w: the first stage at the base, the last of the interval before
        # elsewhere (the strains' left limit, as the statics' shapes keep them)
        nodes = np.concatenate([self._current[:1, 0], self._current[:, 3]])
        n_cables = len(self.robot.cable_names)
        end = self._x[len(self._x) - n_cables:] if self.driven_by_lengths else self._motor
        return DynamicState(self.robot, self.time, self._states.copy(), nodes,
                            self._x[:3].copy(), self._motor.copy(), end.copy(), converged, ivps)


class _Motion(NamedTuple):
    """Each cable's friction state between steps (what ``motion_since`` reads)."""

    free_lengths: np.ndarray
    motion_reference: np.ndarray
    motion: np.ndarray


_NONE = np.zeros(0)


def _tip(tip_force, tip_moment):
    tip = np.concatenate([as_vector(tip_force, 3, 'tip_force'),
                          as_vector(tip_moment, 3, 'tip_moment')])
    return tip


def dynamics_model(robot, dt, c0, tip_mass=0.0):
    """Return the robot's :class:`DynamicsModel` (what the kernel reads) for this time step."""
    n = len(robot.s_grid)
    scale = robot.interval_scale
    constants = problem_constants(robot)
    masses = _node_masses(robot)
    masses[-1] += tip_mass
    return DynamicsModel(
        robot.s_grid, dynamics_params(robot), masses,
        np.ones(n - 1) if scale is None else np.asarray(scale, dtype=float),
        np.ascontiguousarray(robot.cable_offsets, dtype=float).reshape(-1, 3),
        robot.cable_end_node, _scales(robot, dt), _bounds(robot, c0), robot.guide_nodes,
        robot.cable_last_guide, robot.hole_offsets, constants.base_axis,
        np.ascontiguousarray(constants.compliance, dtype=float), float(constants.kappa),
        float(constants.radius), float(constants.t_ref))


#: growth of a perturbation along one shooting segment, e-folds (exp(4) = 55)
SEGMENT_GROWTH = 4.0


def _bounds(robot, c0):
    """Node index of each shooting segment's start, then the tip's.

    The time-discretised bending equations grow a perturbation like exp(s lambda),
    lambda = (rho A c0^2 / E I)^(1/4) (the beam equation E I w^(4) = -rho A c0^2 w): the rod
    is cut where it has grown by SEGMENT_GROWTH e-folds, so Newton's method sees a mild problem.
    """
    rod = robot.description.rod
    growth = (rod.mass_per_length * c0 ** 2 / robot.c[0]) ** 0.25 * robot.length
    n_intervals = len(robot.s_grid) - 1
    segments = int(min(max(1, np.ceil(growth / SEGMENT_GROWTH)), n_intervals))
    return np.round(np.linspace(0, n_intervals, segments + 1)).astype(np.int64)


def _scales(robot, dt):
    """Units of the state values in the residual (``DynamicsModel.scales``)."""
    ei, length = robot.c[0], robot.length
    return np.concatenate([np.full(3, length), np.ones(9), np.full(3, ei / length ** 2),
                           np.full(3, ei / length), np.full(3, length / dt), np.full(3, 1 / dt)])


def _unknowns_at_rest(robot, record, static, tip):
    """Return the unknowns of a rod at rest in ``static``: n, m at the base and each cut."""
    weight = np.asarray(robot.gravity, dtype=float)
    mass_beyond = (robot.description.rod.mass_per_length * (robot.length - robot.s_grid)
                   + np.cumsum(record.disk_mass[::-1])[::-1] - record.disk_mass)
    last = len(robot.s_grid) - 1
    x = []
    for j, node in enumerate(record.bounds[:-1]):
        rotation = static.rotations[node]
        force = tip[:3] + mass_beyond[node] * weight  # eq. 10 integrated
        after = min(node + 1, last)  # the strain just past the node
        moment = rotation @ (robot.node_c[after] * static.u[after])
        if j == 0:
            x += [force, moment]
        else:
            x += [static.positions[node], rotation.ravel(), force, moment, np.zeros(6)]
    return np.concatenate(x)
