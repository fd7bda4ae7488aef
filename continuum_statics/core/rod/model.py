"""The engine room: the one place Python calls each compiled kernel of the rod model.

A :class:`Model` is built once per robot. It holds the robot's
:class:`~continuum_statics.core.description.layout.KernelModel` (everything the compiled solvers
read, one
argument) and has one method per kernel; the solvers above (shape estimation, tendon statics,
tip goals, load estimation, calibration) call these methods and read the named records they
return (:class:`~continuum_statics.core.description.layout.Probe`, :class:`tracking.Tracked`,
:class:`length_tracking.Chorded`, ...), never a kernel's argument list or a result by position.
``test/core/test_layout.py`` checks that each kernel is called here and nowhere else.
"""
import numpy as np

from continuum_statics.core.description.layout import KernelModel, Probe
from continuum_statics.core.rod import (
    dynamics_kernel,
    goal_tracking,
    kernel,
    length_tracking,
    tendon_kernel,
    tracking,
)


class Model:
    """Calls of the compiled rod model for one robot (unchecked: arguments are float arrays).

    :param record: the robot's :class:`KernelModel`
    :param force_step: finite-difference step for tip forces (N)
    """

    def __init__(self, record: KernelModel, force_step: float):
        self.record = record
        self.force_step = force_step
        # integrate_batch's arguments before and after the loads, unpacked once: a record's
        # field is an attribute lookup (~35 ns), seven of them per IVP call
        self._head = record.s_grid, record.code
        self._passive = record.s_grid, record.params
        self._tail = (record.stage_routes, record.route_kinks, record.cable_end_node,
                      record.section_end_node)
        n_sections = record.section_bases.shape[0]
        n_cables = record.cable_offsets.shape[0]
        # the loads of a passive state, batch of one (the kernel only reads them)
        self._no_moments = np.zeros((1, n_sections, 3))
        self._no_tensions = np.zeros((1, n_cables))

    def with_params(self, params) -> KernelModel:
        """Return the record with other rod constants (None: the robot's own)."""
        return self.record if params is None else self.record._replace(params=params)

    # -- one IVP and its loads ------------------------------------------------------------
    def integrate(self, tip_forces, base_bendings, disk_moments=None, tensions=None,
                  params=None) -> np.ndarray:
        """(B, N, 21) node states of a batch of IVPs (``kernel.integrate_batch``).

        ``tip_forces`` (B, 3) N, ``base_bendings`` (B, 3) 1/m, ``disk_moments`` (B, S, 3) N m
        and ``tensions`` (B, n_cables) N (None: a passive rod, batch of one). Flat arguments:
        the single IVP of ``Robot.solve_ivp`` is the path where a record's typing (~1 us) shows.
        """
        if disk_moments is None:
            disk_moments, tensions = self._no_moments, self._no_tensions
        s_grid, code = self._head
        routes, kinks, cable_end_node, section_end_node = self._tail
        return kernel.integrate_batch(s_grid, self.record.params if params is None else params,
                                      code, tip_forces, base_bendings, disk_moments, tensions,
                                      routes, kinks, cable_end_node, section_end_node)

    def integrate_passive(self, tip_force, base_bending) -> np.ndarray:
        """(N, 21) node states of one IVP with slack cables: F (3,) N, u(0) (3,) 1/m."""
        s_grid, params = self._passive
        return kernel.integrate_passive(s_grid, params, tip_force, base_bending)

    def loads(self, state, fixed_tensions) -> tuple:
        """Section point moments (S, 3; local, N m) and cable tensions (n_cables, N) of a state."""
        r = self.record
        moments = np.zeros((r.section_bases.shape[0], 3))
        tensions = np.zeros(r.cable_offsets.shape[0])
        kernel.loads_from_state(state, fixed_tensions, r.code, r.section_bases, r.section_ranks,
                                r.params[0], r.section_cables, r.section_cable_count,
                                r.cable_offsets, moments, tensions)
        return moments, tensions

    def cable_lengths(self, states) -> np.ndarray:
        """Cable lengths (B, n_cables), m, of a batch of node states (B, N, 21) (eq. 11)."""
        r = self.record
        return kernel.cable_lengths_batch(states, r.guide_nodes, r.hole_offsets,
                                          r.cable_last_guide)

    def section_tensions(self, moment, cables, out):
        """Least-norm tensions >= 0 of one section's cables applying ``moment`` (into ``out``)."""
        kernel.section_tensions(moment, cables, self.record.cable_offsets, out)

    def path_stretch(self, states, base_axis, tensions, friction, compliance):
        """Return (consumed, motor, mean) of each cable along its path (``path_stretch``)."""
        r = self.record
        n = tensions.shape[0]
        consumed, motor, mean = np.empty(n), np.empty(n), np.empty(n)
        tendon_kernel.path_stretch(states, r.guide_nodes, r.cable_last_guide, r.hole_offsets,
                                   base_axis, tensions, friction, compliance, consumed, motor,
                                   mean)
        return consumed, motor, mean

    # -- the model's outputs and Jacobians --------------------------------------------------
    def probe(self, state, n_free, tip_force, tip_moment, fixed_tensions,
              params=None) -> Probe:
        """Tip, tip axis, cable lengths, tip balance and their Jacobian (``kernel.probe``)."""
        return kernel.probe(self.with_params(params), tip_force, tip_moment, fixed_tensions,
                            state, n_free)

    def tip_jacobian(self, tip_force, base_bending, disk_moments, tensions):
        """6x6 tip Jacobian [position; angle] by [F; u(0)] (``kernel.tip_jacobian``)."""
        return kernel.tip_jacobian(self.record, tip_force, base_bending, disk_moments, tensions,
                                   self.force_step, self.record.step)

    # -- the compiled solvers ---------------------------------------------------------------
    def track(self, tip_force, tip_moment, fixed, measured, start: tracking.TrackStart,
              limits: tracking.TrackLimits) -> tracking.Tracked:
        """Run the shape estimator's constrained Gauss-Newton (``tracking.track``)."""
        return tracking.track(self.record, tip_force, tip_moment, fixed, measured, start, limits)

    def goal_solve(self, tip_force, tip_moment, fixed, x0, rows: goal_tracking.GoalRows,
                   limits: goal_tracking.GoalLimits) -> goal_tracking.GoalSolved:
        """Run the tip-goal solver's constrained Gauss-Newton (``goal_tracking.goal_solve``)."""
        return goal_tracking.goal_solve(self.record, tip_force, tip_moment, fixed, x0, rows,
                                        limits)

    def evaluate_at(self, tip_force, tip_moment, z, tendon: length_tracking.TendonArgs
                    ) -> length_tracking.Evaluation:
        """Return the tendon statics' residual and model at z (``length_tracking.evaluate_at``)."""
        return length_tracking.evaluate_at(self.record, tip_force, tip_moment, z, tendon)

    def jacobian_pieces(self, tip_force, tip_moment, z, moment_map, compliance, mean,
                        tension_step) -> length_tracking.Pieces:
        """Return the tendon statics' Jacobian pieces at z (``jacobian_pieces``)."""
        return length_tracking.jacobian_pieces(self.record, tip_force, tip_moment, z,
                                               moment_map, compliance, mean, tension_step)

    def chord(self, tip_force, tip_moment, z0, tendon, scale, pieces, limits, start_values,
              start_states) -> length_tracking.Chorded:
        """Run the tendon statics' compiled chord steps (``length_tracking.chord``)."""
        return length_tracking.chord(self.record, tip_force, tip_moment, z0, tendon, scale,
                                     pieces, limits, start_values, start_states)

    # -- the rod in motion (a robot's DynamicsModel record, built by
    # core/dynamics/rod_dynamics.py) -------
    @staticmethod
    def dynamics_solve(record, c0, history, x, jacobian, pivots, tip, cables, states, left,
                       stages, motor, tolerance, max_iterations, refresh_first):
        """Solve one time step (``dynamics_kernel.solve_step``): (converged, IVPs, refreshes)."""
        return dynamics_kernel.solve_step(record, c0, history, x, jacobian, pivots, tip, cables,
                                          states, left, stages, motor, tolerance,
                                          max_iterations, refresh_first)

    @staticmethod
    def dynamics_advance(record, coefficients, memory, x, last_x, inverse, pivots, tip, cables,
                         states, left, stages, motor, tolerance, max_iterations):
        """One time step with its history (``dynamics_kernel.advance``)."""
        return dynamics_kernel.advance(record, coefficients, memory, x, last_x, inverse, pivots,
                                       tip, cables, states, left, stages, motor, tolerance,
                                       max_iterations)
