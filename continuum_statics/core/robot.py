"""The robot model: a validated description plus the solvers that act on it (no ROS).

Solver state. Every solve works on one vector x = [u(0) (3, 1/m); per section, the coordinates of
the bending moment its cables apply, in an orthonormal basis of the moments they can apply (the
span of e3 x l_j: 0, 1 or 2 coordinates), divided by E I (1/m)] plus ``fixed_tensions`` (N,
measured or given tensions). The point_moment model applies each section's moment at its end
disk; the distributed model turns it into the least-norm non-negative cable tensions (antagonists
slack) and loads the rod with them all along the cables. Equilibrium is the tip moment balance
(:func:`kernel.probe` rows ``balance``): three equations whatever the number of sections.
"""
import copy
import dataclasses
import functools
import math

import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.description.layout import (
    POSITION,
    ROTATION,
    STATE_SIZE,
    KernelModel,
    Probe,
    ProbeRows,
)
from continuum_statics.core.description.obstacles import in_base_frame
from continuum_statics.core.description.robot_file import read_robot_description
from continuum_statics.core.description.routing import Routing
from continuum_statics.core.description.sensors import default_model_uncertainty
from continuum_statics.core.description.tendons import Tendons
from continuum_statics.core.estimation import load_estimation, shape_estimation, state_estimation
from continuum_statics.core.rod.kernel import DISTRIBUTED, POINT_MOMENT, pack_params
from continuum_statics.core.rod.model import Model
from continuum_statics.core.rod.rotations import quaternion_to_rotation
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.statics import bvp, contact, length_statics, tip_goal


def load_robot(path) -> 'Robot':
    """Load a robot file (YAML) into a :class:`Robot`; ``ValueError`` names any bad field."""
    return Robot(read_robot_description(path))


def _grid(length, guides, steps):
    """Integration nodes with a node at every guide, and the guide node indices.

    Each stretch between breakpoints gets ceil(steps * stretch / L) steps, so no step is longer
    than L / steps. The cable path starts at the base disk, node 0.
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


def _interval_scale(s_grid, sections):
    """Factor on C over each integration interval (N - 1,), or None when every one is 1.

    Section k covers the arc lengths from the previous section's end disk to its own.
    """
    scales = [getattr(section, 'bending_scale', 1.0) for section in sections]
    if all(scale == 1.0 for scale in scales):
        return None
    middle = 0.5 * (s_grid[:-1] + s_grid[1:])
    ends = np.array([section.end for section in sections])
    index = np.minimum(np.searchsorted(ends, middle), len(sections) - 1)
    return np.asarray(scales, dtype=float)[index]


def _interval_weight(s_grid, sections, gravity):
    """Weight (N, global) of the guide disks beyond each interval (N - 1, 3), or None.

    A disk at node i is beyond every interval ending at or after it (its own end included:
    the node's strain is the left limit, before the disk's point force).
    """
    weight = np.zeros(len(s_grid))
    for section in sections:
        mass = getattr(section, 'disk_mass', 0.0)
        for guide in section.guides if mass else ():
            weight[int(np.argmin(np.abs(s_grid - guide)))] += mass
    if not np.any(weight):
        return None
    beyond = np.cumsum(weight[::-1])[::-1]  # mass at node i and beyond
    return beyond[1:, None] * np.asarray(gravity, dtype=float)[None, :]


def _moment_basis(offsets):
    """Orthonormal basis (3, rank) of the local moments t (e3 x l) a set of cables can apply."""
    arms = np.cross([0.0, 0.0, 1.0], np.reshape(offsets, (-1, 3)))
    if arms.shape[0] == 0:
        return np.zeros((3, 0))
    _, sing, vt = np.linalg.svd(arms)
    rank = int(np.sum(sing > 1e-9 * max(sing[0], 1e-300)))
    return vt[:rank].T.copy()


@dataclasses.dataclass(frozen=True, eq=False)
class Equilibrium:
    """A model equilibrium for given cable loads (:meth:`Robot.equilibrium_between`).

    :ivar shape: backbone; ``shape.state`` and ``shape.fixed_tensions`` are the solver state
    :ivar cable_lengths: (n_cables,) m, ``robot.cable_names`` order
    :ivar converged: the tip moment balance reached its tolerance
    """

    shape: Shape
    cable_lengths: np.ndarray
    converged: bool

    @property
    def state(self):
        """Solver state x (see the module docstring)."""
        return self.shape.state


class Robot:
    """A continuum robot: rod, base pose, gravity, sections with cables, solver settings.

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
        self.cable_length_limits = description.cable_length_limits
        self.guides = description.guides
        self.sections = description.sections
        self.cable_model = description.cable_model
        self.model_code = DISTRIBUTED if self.cable_model == 'distributed' else POINT_MOMENT
        self.solver = description.solver
        self.tendons = description.tendons or Tendons.default(len(self.cable_names))
        # sensors besides the cables and the model's own error (state_estimation); sensors
        # without a stated model error correct the defaults', which calibrate replaces
        self.sensors = description.sensors
        self.model_uncertainty = description.model_uncertainty
        # a measured tension's sigma (N or 'P%'): with it, measured tensions are a measurement
        # of the fused state like a sensor's readings (state_estimation); None: they are not
        self.tension_noise = description.tension_noise
        if self.sensors and self.model_uncertainty is None:
            self.model_uncertainty = default_model_uncertainty(rod.bending_stiffness[0],
                                                               rod.length)
        # the point a tip tracker follows, in the tip frame (m): calibration and tip_pose_measured
        self.tip_marker = (np.zeros(3) if description.tip_marker is None
                           else np.array(description.tip_marker, dtype=float))
        self.clearance = description.clearance
        self.obstacles = in_base_frame(description.obstacles, self.base_frame_id)
        self.c = rod.bending_stiffness
        self.d = rod.shear_stiffness
        # distributed weight rho*A*g*e_g (N/m), the body force f of eqs. 3, 4 and 8
        self.body_force = rod.mass_per_length * np.asarray(self.gravity)
        self.s_grid, self.guide_nodes = _grid(rod.length, self.guides, self.solver.steps)
        self.interval_scale = _interval_scale(self.s_grid, self.sections)
        self.interval_weight = _interval_weight(self.s_grid, self.sections, self.gravity)
        self.params = self.params_for()
        # C at each node (left limit, as the node's strains; the base: the first interval's),
        # N m^2: the shapes' moments
        scale = (np.ones(len(self.s_grid) - 1) if self.interval_scale is None
                 else self.interval_scale)
        self.node_c = self.c * np.concatenate([scale[:1], scale])[:, None]
        # the tip load carried in the fused state (the file's load_model; checked here: a
        # 'weight' needs gravity), and with it the fused estimator's unmodelled loads
        self.load_model = None
        if description.load is not None:
            name, direction, prior = description.load
            self.load_model = load_estimation.load_model(
                self, ('direction', direction) if name == 'direction' else name, prior=prior)
            if self.model_uncertainty is None:
                self.model_uncertainty = default_model_uncertainty(rod.bending_stiffness[0],
                                                                   rod.length)
        self._layout()
        self.straight_cable_lengths = self.cable_lengths(self._straight_shape())
        limits = np.asarray(self.cable_length_limits, dtype=float).reshape(-1, 2)
        for name, length, (low, high) in zip(self.cable_names, self.straight_cable_lengths,
                                             limits):
            if not low <= length <= high:  # the homed robot would be outside its own limits
                raise ValueError('cable %r: length_limits [%g, %g] m exclude its straight '
                                 'length %.6g m (the homed pose): check the limits, the hole '
                                 'offset and the guides' % (name, low, high, length))

    def params_for(self, fraction=1.0) -> np.ndarray:
        """Return the kernel's rod constants (:func:`kernel.pack_params`).

        Gravity is scaled by ``fraction``: the rod's weight and the disks' (continuation).
        """
        weight = None if self.interval_weight is None else fraction * self.interval_weight
        return pack_params(self.c, self.d, fraction * self.body_force, self.base_position,
                           self.base_rotation, self.interval_scale, weight)

    def _layout(self):
        """Index tables the kernel reads: disks, cable ends, routes, moment bases, layout."""
        n_sections, n_cables = max(len(self.sections), 1), len(self.cable_names)
        self.section_end_node = np.full(n_sections, -1, dtype=np.int64)
        self.cable_end_node = np.zeros(n_cables, dtype=np.int64)
        self.cable_last_guide = np.zeros(n_cables, dtype=np.int64)
        self.cable_section = np.zeros(n_cables, dtype=np.int64)
        self.section_bases = np.zeros((n_sections, 3, 2))
        self.section_ranks = np.zeros(n_sections, dtype=np.int64)
        self.section_state_index = np.full(n_sections, -1, dtype=np.int64)
        width = max([len(s.cable_indices) for s in self.sections] + [1])
        self.section_cables = np.full((n_sections, width), -1, dtype=np.int64)
        self.section_cable_count = np.zeros(n_sections, dtype=np.int64)
        column = 3
        for k, section in enumerate(self.sections):
            node = int(np.argmin(np.abs(self.s_grid - section.end)))
            self.section_end_node[k] = node
            guide = int(np.nonzero(self.guide_nodes == node)[0][0])
            cables = list(section.cable_indices)
            self.section_cables[k, :len(cables)] = cables
            self.section_cable_count[k] = len(cables)
            self.cable_end_node[cables] = node
            self.cable_last_guide[cables] = guide
            self.cable_section[cables] = k
        self.routing = Routing.build(self.description.routes(), self.s_grid, self.guide_nodes,
                                     self.cable_last_guide)
        self.cable_offsets = self.routing.end_offsets  # the arm of each cable's end-disk pull
        self.hole_offsets = self.routing.hole_offsets
        self.stage_routes = self.routing.stage_routes
        self.route_kinks = self.routing.route_kinks
        for k, section in enumerate(self.sections):
            cables = list(section.cable_indices)
            basis = _moment_basis(self.cable_offsets[cables])
            rank = basis.shape[1]
            self.section_bases[k, :, :rank] = basis
            self.section_ranks[k] = rank
            self.section_state_index[k] = column if rank else -1
            column += rank
        # the index tables by their record names (the robot's attributes of the same names)
        tables = {name: getattr(self, name) for name in KernelModel._fields[4:]}
        self.model = Model(KernelModel(self.s_grid, self.params, self.model_code,
                                       self.bending_step(), **tables), self.force_step())
        self.state_size = column
        self.observable_bending = column - 3
        # what must clear an obstacle (m): the file's body_radius, else the outermost cable
        # hole (the disks reach at least that far), else the rod's own radius
        holes = np.hypot(self.hole_offsets[..., 0], self.hole_offsets[..., 1])
        self.body_radius = (self.description.body_radius if self.description.body_radius
                            else max(float(np.max(holes, initial=0.0)), 0.5 * self.rod.diameter))
        # IVPs in one probe with Jacobians: point moments at the tip have exact columns
        tip = len(self.s_grid) - 1
        exact = sum(int(r) for r, n in zip(self.section_ranks, self.section_end_node)
                    if n == tip) if self.model_code == POINT_MOMENT else 0
        self.probe_runs = 1 + column - exact

    @functools.cached_property
    def tension_moment_map(self):
        """(state_size - 3, n_cables): section moment coordinates (1/m) per N of end tension.

        The point moment of section k is sum_j t_j (e3 x l_j) over its cables (local frame);
        its coordinates in the section's basis, divided by E I, are the solver state's.
        """
        table = np.zeros((self.state_size - 3, len(self.cable_names)))
        arms = np.cross([0.0, 0.0, 1.0], self.cable_offsets)
        for k, section in enumerate(self.sections):
            first, rank = self.section_state_index[k], self.section_ranks[k]
            if first >= 0:
                cables = list(section.cable_indices)
                table[first - 3:first - 3 + rank, cables] = (
                    self.section_bases[k][:, :rank].T @ arms[cables].T / self.c[0])
        return table

    def with_solver(self, **settings) -> 'Robot':
        """Copy of this robot with some solver settings replaced (e.g. ``steps=200``)."""
        solver = dataclasses.replace(self.solver, **settings)
        return Robot(dataclasses.replace(self.description, solver=solver))

    def with_node_forces(self, forces) -> 'Robot':
        """Copy of this robot with point forces (N, global; (N, 3), one per node) on the rod.

        Carried as the disks' weights are (eq. 3 with point loads: n jumps at the node): the
        contact forces of :mod:`contact`. Every solver runs on the copy unchanged.
        """
        beyond = np.cumsum(np.asarray(forces, dtype=float)[::-1], axis=0)[::-1][1:]
        other = copy.copy(self)
        other.interval_weight = (beyond if self.interval_weight is None
                                 else self.interval_weight + beyond)
        other.params = other.params_for()
        other.model = Model(self.model.record._replace(params=other.params),
                            self.model.force_step)
        return other

    def obstacles_or_file(self, obstacles):
        """Return the obstacles of a solve: the robot file's for None, else these (base frame)."""
        return self.obstacles if obstacles is None else in_base_frame(obstacles,
                                                                      self.base_frame_id)

    def with_model_uncertainty(self, uncertainty) -> 'Robot':
        """Copy of this robot with another :class:`sensors.ModelUncertainty` (None: none)."""
        return Robot(dataclasses.replace(self.description, model_uncertainty=uncertainty))

    def without_load_model(self) -> 'Robot':
        """Copy of this robot without the file's ``load_model`` (the model's error alone)."""
        if self.load_model is None:
            return self
        return Robot(dataclasses.replace(self.description, load=None))

    # -- state and loads ---------------------------------------------------------------------
    def passive_state(self, u0=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Solver state with base bending ``u0`` and no cable load."""
        x = np.zeros(self.state_size)
        x[:3] = u0
        return x

    def loads(self, state, fixed_tensions=None) -> tuple:
        """Section point moments (S, 3; local, N m) and cable tensions (n_cables, N) of a state."""
        return self.model.loads(np.asarray(state, dtype=float),
                                self.tensions_or_zero(fixed_tensions))

    def tensions_or_zero(self, fixed_tensions):
        """Return fixed cable tensions (n_cables,) in N as a float array; zero for None."""
        if fixed_tensions is None:
            return np.zeros(len(self.cable_names))
        return np.array(fixed_tensions, dtype=float)  # a copy: never a read-only view

    def integrate_state(self, state, tip_force, fixed_tensions=None, params=None) -> np.ndarray:
        """(N, 21) kernel states of one solver state under a tip force F (N, global)."""
        moments, tensions = self.loads(state, fixed_tensions)
        return self.model.integrate(np.array(tip_force, dtype=float)[None],
                                    np.asarray(state[:3], dtype=float)[None], moments[None],
                                    tensions[None], params)[0]

    def probe(self, state, n_free, tip_force, tip_moment, fixed_tensions=None,
              params=None) -> Probe:
        """Tip, tip axis, cable lengths, tip balance and their Jacobian (:meth:`Model.probe`).

        Unchecked fast path for the solvers: arguments must be float arrays.
        """
        # tip loads copied: a read-only view (the nodes' zero load) is another numba signature
        return self.model.probe(state, n_free, np.array(tip_force, dtype=float),
                                np.array(tip_moment, dtype=float),
                                self.tensions_or_zero(fixed_tensions), params)

    def make_shape(self, state, tip_force, states, fixed_tensions=None) -> Shape:
        """Wrap kernel states in a :class:`Shape` that remembers its solver state."""
        return Shape(self.s_grid, states, np.array(state[:3]), tip_force, self.node_c, self.d,
                     state=np.array(state, dtype=float), fixed_tensions=self.tensions_or_zero(
                         fixed_tensions).copy())

    # -- initial- and boundary-value problems -------------------------------------------------
    def solve_ivp(self, u0, tip_force=(0.0, 0.0, 0.0)) -> Shape:
        """Shape for a base bending u(0) (1/m, local) and a tip force F (N, global), no cables.

        Integrates eqs. 1, 2, 8, 9 from the base with v(0) from eq. 10: no iteration, which is
        what makes the paper's approach real-time.
        """
        # finiteness is checked by the kernel (0.4 us a vector here): then again, to say which
        u0 = as_vector(u0, 3, 'u0', finite=False)
        tip_force = as_vector(tip_force, 3, 'tip_force', finite=False)
        # the passive state's loads are zero: no loads_from_state call (a per-call fast path)
        states = self.model.integrate_passive(tip_force, u0)
        if not len(states):
            as_vector(u0, 3, 'u0')
            as_vector(tip_force, 3, 'tip_force')
        state = np.zeros(self.state_size)
        state[:3] = u0
        # no fixed tensions (None, as Shape allows): one allocation fewer per call
        return Shape(self.s_grid, states, u0, tip_force, self.node_c, self.d, state=state)

    def solve_bvp(self, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0), u0_guess=None,
                  warm_start=None) -> Shape:
        """Shape of the rod with slack cables under a tip force F (N) and moment (N m), global.

        ``warm_start``: a previous result whose u(0) starts the solve. See
        :func:`continuum_statics.core.statics.bvp.solve_loaded`; raises ``ConvergenceError``.
        """
        tip_force = as_vector(tip_force, 3, 'tip_force')
        tip_moment = as_vector(tip_moment, 3, 'tip_moment')
        start = _warm_or_guess(self, warm_start, u0_guess)
        state = bvp.solve_loaded(self, self.passive_state(), None, tip_force, tip_moment, start)
        return self.make_shape(state, tip_force, self.integrate_state(state, tip_force))

    def dynamics(self, dt=None, alpha=None, tip_mass=0.0):
        """Return the rod in motion (:class:`~continuum_statics.core.dynamics.RodDynamics`).

        ``dt`` (s) and ``alpha`` (BDF-alpha, [-0.45, 0]); None: the robot file's ``dynamics``.
        ``tip_mass``: kg of payload at the tip.
        """
        from continuum_statics.core.dynamics.rod_dynamics import (
            RodDynamics,  # its kernel compiles on use
        )
        return RodDynamics(self, dt, alpha, tip_mass)

    def solve_tensions(self, tensions, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
                       warm_start=None, obstacles=None) -> Shape:
        """Forward statics: the shape under cable tensions (N, >= 0) and a tip load (global).

        A boundary-value problem on u(0) with the robot's cable model; ``warm_start`` is a
        previous result (shape, estimate or solution). ``obstacles``: a sequence of
        :class:`~continuum_statics.core.description.obstacles.Obstacle` in the base frame
        (None: the robot file's; ``()``: none): the body rests on them, ``shape.contacts``
        says where (:mod:`contact`). Raises ``ConvergenceError``.
        """
        tensions = as_vector(tensions, len(self.cable_names), 'tensions')
        if np.any(tensions < 0.0):
            raise ValueError('tensions must be >= 0 N (cables only pull), got %s'
                             % np.round(tensions, 6).tolist())
        tip_force = as_vector(tip_force, 3, 'tip_force')
        tip_moment = as_vector(tip_moment, 3, 'tip_moment')
        obstacles = self.obstacles_or_file(obstacles)
        if obstacles:
            def scaled(fraction):
                return lambda robot, warm: Robot.solve_tensions(
                    robot, fraction * tensions, fraction * tip_force, fraction * tip_moment,
                    warm, ())

            return contact.solve_in_contact(self, obstacles, self.body_radius, scaled(1.0),
                                            warm_start, scaled)
        start = _warm_state(self, warm_start)
        if start is not None:
            start = self.passive_state(start[:3])
        state = bvp.solve_loaded(self, self.passive_state(), tensions, tip_force, tip_moment,
                                 start)
        return self.make_shape(state, tip_force, self.integrate_state(state, tip_force, tensions),
                               tensions)

    def solve_lengths(self, lengths, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
                      warm_start=None, obstacles=None) -> length_statics.LengthSolution:
        """Equilibrium when the motors hold cable lengths (m): shape, tensions, slack cables.

        The tendon model of the robot file (stiffness, pretension, friction, zero offsets);
        ``warm_start`` is the previous result of the same sequence. See :mod:`length_statics`.
        ``obstacles`` as :meth:`solve_tensions`: ``solution.shape.contacts``.
        """
        obstacles = self.obstacles_or_file(obstacles)
        if obstacles:
            lengths = as_vector(lengths, len(self.cable_names), 'lengths')
            tip_force = as_vector(tip_force, 3, 'tip_force')
            tip_moment = as_vector(tip_moment, 3, 'tip_moment')
            rest = self.straight_cable_lengths

            def scaled(fraction):
                return lambda robot, warm: length_statics.solve_lengths(
                    robot, rest + fraction * (lengths - rest), fraction * tip_force,
                    fraction * tip_moment, warm)

            return contact.solve_in_contact(self, obstacles, self.body_radius, scaled(1.0),
                                            warm_start, scaled)
        return length_statics.solve_lengths(self, lengths, tip_force, tip_moment, warm_start)

    def equilibrium_between(self, start, goal, fraction, tip_force=(0.0, 0.0, 0.0),
                            tip_moment=(0.0, 0.0, 0.0), warm_start=None) -> 'Equilibrium':
        """Solve the equilibrium a fraction (0..1) of the way from one result's loads to another's.

        The section moments and fixed tensions are interpolated linearly and the base state is
        solved, so every intermediate is a shape of the robot (what a controller should command
        while it moves). Returns :class:`Equilibrium`; never raises for a failed solve (then
        ``converged`` is False and the best state is returned).
        """
        fraction = float(fraction)
        if not 0.0 <= fraction <= 1.0:
            raise ValueError('fraction must be in [0, 1], got %r' % fraction)
        a, b = _warm_state(self, start), _warm_state(self, goal)
        if a is None or b is None:
            raise ValueError('start and goal must be results of this robot (with a state)')
        fa, fb = _warm_tensions(self, start), _warm_tensions(self, goal)
        loads = (1.0 - fraction) * a + fraction * b
        fixed = (1.0 - fraction) * fa + fraction * fb
        tip_force = as_vector(tip_force, 3, 'tip_force')
        tip_moment = as_vector(tip_moment, 3, 'tip_moment')
        guess = _warm_state(self, warm_start)
        loads[:3] = loads[:3] if guess is None else guess[:3]
        state, converged = bvp.solve_fixed_loads(self, loads, fixed, tip_force, tip_moment)
        states = self.integrate_state(state, tip_force, fixed)
        shape = self.make_shape(state, tip_force, states, fixed)
        return Equilibrium(shape, self.cable_lengths(shape), converged)

    # -- cables ----------------------------------------------------------------------------
    def cable_lengths(self, shape) -> np.ndarray:
        """Cable lengths (n_cables,) in m of a shape, order ``cable_names`` (eq. 11, errata)."""
        states = np.ascontiguousarray(shape.states)
        if not states.flags.writeable:  # a Shape's: the kernel's one specialisation is writable
            states = states.copy()
        return self.model.cable_lengths(states[None])[0]

    # -- Jacobians -------------------------------------------------------------------------
    def force_step(self) -> float:
        """Finite-difference step for tip forces (N): 1e-7 of the load scale E I / L^2."""
        return 1e-7 * self.c[0] / self.length ** 2

    def bending_step(self) -> float:
        """Finite-difference step for u(0) and section moments (1/m): 1e-7 rad over L."""
        return 1e-7 / self.length

    def jacobian(self, u0, tip_force=(0.0, 0.0, 0.0)) -> np.ndarray:
        """6x6 tip Jacobian with slack cables: rows [linear (m); angle (rad)], cols [F (N); u(0)].

        Forward differences as in the paper (section V.B), all seven IVPs in one kernel call;
        the angular rows are vee(dR R^T) (the paper's omega-hat = R-dot R^T), global frame.
        """
        return self.model.tip_jacobian(as_vector(tip_force, 3, 'tip_force'),
                                       as_vector(u0, 3, 'u0'),
                                       np.zeros((len(self.section_ranks), 3)),
                                       np.zeros(len(self.cable_names)))

    def cable_jacobian(self, u0, tip_force=(0.0, 0.0, 0.0)) -> np.ndarray:
        """d(cable lengths)/d u(0) with slack cables, (n_cables, 3) in m per 1/m."""
        state = self.passive_state(as_vector(u0, 3, 'u0'))
        probed = self.probe(state, 3, as_vector(tip_force, 3, 'tip_force'), np.zeros(3))
        return probed.jacobian[ProbeRows(len(self.cable_names)).lengths]

    # -- inverse problems ------------------------------------------------------------------
    def estimate_shape(self, cable_lengths, tip_force=(0.0, 0.0, 0.0),
                       tip_moment=(0.0, 0.0, 0.0), tensions=None, warm_start=None,
                       u0_guess=None, tracking=None, exact=False, sensors=None,
                       stamp=None, obstacles=None) -> shape_estimation.ShapeEstimate:
        """Shape from measured cable lengths (m) and a tip load (N, N m); :mod:`estimation`.

        Warm-started (``warm_start`` the previous estimate), a call first does bounded work
        (:class:`shape_estimation.Tracking`'s defaults); when that does not finish, or leaves
        the fused estimate's load columns stale (rows far apart, as a recorded run or a
        low-rate client gives them), it is solved to the end from
        ``warm_start``, so the answer is ``exact=True``'s within the solver's tolerance (before,
        an unfinished estimate carried into the next call ran away: 16.6 mm against 3.2 mm on
        the v6 run's held-out rows). Only a caller that passes its own ``tracking`` (statics at
        the encoders' rate) gets a ``capped`` estimate, which its next call goes on from. A cold
        call (no ``warm_start``) and ``exact=True`` are solved to the solver's tolerances,
        whatever that costs (on noisy lengths 2-5x the median and up to 10x the slowest
        tracked call).

        With the robot file's ``model_uncertainty`` (or ``sensors``: {name:
        :class:`sensors.SensorReading`} of the file's sensors, base frame; a missing name is not
        seen this time) the estimate is the fused one of :mod:`state_estimation`, with
        ``position_covariance`` and ``tip_covariance``; ``stamp`` (s) times the unmodelled
        loads' decay since ``warm_start``. A non-finite ``stamp`` or reading stamp is refused
        (ValueError): it would carry NaN into every later warm-started estimate.
        ``obstacles`` as :meth:`solve_tensions`: ``estimate.shape.contacts``.
        """
        _check_stamps(stamp, sensors)
        obstacles = self.obstacles_or_file(obstacles)
        if obstacles:
            try:
                return contact.solve_in_contact(
                    self, obstacles, self.body_radius,
                    lambda robot, warm: Robot.estimate_shape(
                        robot, cable_lengths, tip_force, tip_moment, tensions, warm, u0_guess,
                        tracking, exact, sensors, stamp, ()), warm_start)
            except contact.ContactError as error:  # the lengths pin the shape: report it
                free = error.free
                note = 'contact not resolved: %s' % error
                return dataclasses.replace(free, message='; '.join(
                    filter(None, (free.message, note))))
        jacobians = getattr(warm_start, 'jacobians', None)
        if jacobians is not None and jacobians[0].shape != (len(self.cable_names),
                                                            self.state_size):
            jacobians = None
        finish = False  # a bounded try first, solved to the end if it does not finish
        if exact:
            tracking = None
        elif tracking is None and warm_start is not None:
            tracking, finish = shape_estimation.DEFAULT_TRACKING, True
        while True:
            if self.model_uncertainty is not None or sensors:
                estimate = state_estimation.estimate_state(
                    self, cable_lengths, tip_force, tip_moment, tensions, sensors, stamp,
                    _warm_or_guess(self, warm_start, u0_guess), jacobians, warm_start, tracking)
            else:
                estimate = shape_estimation.estimate_shape(
                    self, cable_lengths, tip_force, tip_moment, tensions,
                    _warm_or_guess(self, warm_start, u0_guess), jacobians, warm_start, tracking)
            if not (finish and (estimate.capped
                                or state_estimation.stale_columns(self, estimate))):
                return estimate
            tracking, finish = None, False

    def estimate_tip_wrench(self, lengths=None, tensions=None, tip_position=None,
                            tip_rotation=None, noise=None, moment=False,
                            warm_start=None, load=None,
                            load_prior=None) -> load_estimation.WrenchEstimate:
        """Tip force (N) and moment (N m), base frame, that explain the measurements given.

        Lengths (m) and tensions (N) at the motors, the tracked tip point (m) and orientation;
        ``load``: 'weight' (a payload's mass along gravity: ``.mass``, ``.mass_sigma`` kg) |
        'force' (default) | ('direction', (dx, dy, dz)) | 'wrench' (= ``moment=True``); see
        :mod:`load_estimation` (models, noise defaults, what each measurement observes).
        """
        return load_estimation.estimate_tip_wrench(self, lengths, tensions, tip_position,
                                                   tip_rotation, noise, moment, warm_start,
                                                   load, load_prior)

    def solve_tip_goal(self, goal_position, tip_force=(0.0, 0.0, 0.0), tolerance=None,
                       goal_direction=None, warm_start=None, tip_moment=(0.0, 0.0, 0.0),
                       u0_guess=None, clearance=None,
                       obstacles=None) -> tip_goal.TipGoalSolution:
        """Cable lengths that put the tip at a goal (m), inside their limits; :mod:`tip_goal`.

        With obstacles (None: the robot file's) the whole body keeps ``clearance`` (m; None: the
        file's) from them, at the answer and along the way from ``warm_start``
        (``solution.waypoints``), or the goal is not reached and the message names where.
        """
        return tip_goal.solve_tip_goal(self, goal_position, tip_force, tolerance,
                                       goal_direction, _warm_or_guess(self, warm_start, u0_guess),
                                       tip_moment, clearance, obstacles)

    def _straight_shape(self):
        """Return the straight, unloaded rod (for the reference cable lengths)."""
        s = self.s_grid
        states = np.zeros((len(s), STATE_SIZE))
        states[:, POSITION] = self.base_position + s[:, None] * self.base_rotation[:, 2]
        states[:, ROTATION] = self.base_rotation.ravel()
        state = self.passive_state()
        return self.make_shape(state, np.zeros(3), states)


def _warm_state(robot, result):
    """Solver state of a previous result (shape, estimate, solution, equilibrium) or None."""
    if result is None:
        return None
    shape = getattr(result, 'shape', result)
    state = getattr(shape, 'state', None)
    if state is None or len(state) != robot.state_size or not np.all(np.isfinite(state)):
        return None
    return np.array(state, dtype=float)


def _warm_tensions(robot, result):
    shape = getattr(result, 'shape', result)
    fixed = getattr(shape, 'fixed_tensions', None)
    if fixed is None or len(fixed) != len(robot.cable_names):
        return np.zeros(len(robot.cable_names))
    return np.array(fixed, dtype=float)


def _check_stamps(stamp, sensors):
    """Refuse a non-finite estimate stamp or reading stamp (s; None is allowed)."""
    if stamp is not None and not math.isfinite(stamp):
        raise ValueError('stamp must be a finite time in s (or None), got %r' % (stamp,))
    for name, reading in (sensors or {}).items():
        when = getattr(reading, 'stamp', None)  # a bare position has none
        if when is not None and not math.isfinite(when):
            raise ValueError('sensor %r: reading stamp must be a finite time in s (or None), '
                             'got %r' % (name, when))


def _warm_or_guess(robot, warm_start, u0_guess):
    """Start state from ``warm_start`` (a previous result) or the older ``u0_guess``."""
    state = _warm_state(robot, warm_start)
    if state is None and u0_guess is not None:
        state = robot.passive_state(as_vector(u0_guess, 3, 'u0_guess'))
    return state
