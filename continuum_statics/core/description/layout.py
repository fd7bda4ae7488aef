"""The array layouts shared by the kernels and their Python callers, stated once.

Node state (one row of ``kernel.integrate_batch``'s output, :data:`STATE_SIZE` = 21), SI units:
r (3, m), R row-major (9), the stretch v - e3 (3; kept instead of v so ~1e-5 axial strains keep
full precision), the bending u (3, 1/m), M (3, N m: the moment of every load beyond s, after any
point moment at the node).

Rows of ``kernel.probe``'s values (and its Jacobian): tip position (3, m), tip z axis (3),
cable lengths (n_cables, m), tip moment balance (3, (M_end - tau) L / (E I), zero at equilibrium).
"""
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

# node state: first index of each block (the compiled code reads these) and the slices
POSITION_AT, ROTATION_AT, STRETCH_AT, BENDING_AT, MOMENT_AT = 0, 3, 12, 15, 18
STATE_SIZE = 21
POSITION = slice(POSITION_AT, ROTATION_AT)
ROTATION = slice(ROTATION_AT, STRETCH_AT)
STRETCH = slice(STRETCH_AT, BENDING_AT)
BENDING = slice(BENDING_AT, MOMENT_AT)
MOMENT = slice(MOMENT_AT, STATE_SIZE)

# the rod constants vector of ``kernel.pack_params`` (PARAMS_SIZE values): first index of C
# (3, N m^2), 1 / C, D (3, N), 1 / D, the body force (3, N/m), r(0) (3, m), R(0) row-major (9)
C_AT, C_INV_AT, D_AT, D_INV_AT, BODY_FORCE_AT, BASE_POSITION_AT, BASE_ROTATION_AT = (
    0, 3, 6, 9, 12, 15, 18)
PARAMS_SIZE = 27


# the dynamic node state of ``dynamics_kernel`` (DYNAMIC_STATE values): p (3, m), R row-major
# (9), n (3, N, global), m (3, N m, global), q (3, m/s, local), w (3, rad/s, local)
(DYN_POSITION_AT, DYN_ROTATION_AT, DYN_FORCE_AT, DYN_MOMENT_AT, DYN_VELOCITY_AT,
 DYN_ANGULAR_AT) = 0, 3, 12, 15, 18, 21
DYNAMIC_STATE = 24
# p and R where the statics' node state has r and R: the holes' code (routing.hole_in) reads both
assert (DYN_POSITION_AT, DYN_ROTATION_AT) == (POSITION_AT, ROTATION_AT)
#: a node's BDF-alpha history: v_h (3), u_h (3), q_h (3), w_h (3)
DYN_HISTORY_SIZE = 12
# first index of each block of a history, and of the v, u, q, w the kernel writes in its place
DYN_HIST_STRETCH_AT, DYN_HIST_BENDING_AT, DYN_HIST_VELOCITY_AT, DYN_HIST_ANGULAR_AT = 0, 3, 6, 9
# the kernel loops over n, m and over q, w as six values each
assert DYN_MOMENT_AT == DYN_FORCE_AT + 3 and DYN_ANGULAR_AT == DYN_VELOCITY_AT + 3
# the dynamics' rod constants: K_se = diag(GA, GA, EA) (3, N), B_se (3, N s), K_bt =
# diag(EI, EI, GJ) (3, N m^2), B_bt (3, N m^2 s), rho A (kg/m), rho J (3, kg m), the gravity
# acceleration (3, m/s^2, global), p(0) (3, m), R(0) row-major (9)
(DYN_K_SE_AT, DYN_B_SE_AT, DYN_K_BT_AT, DYN_B_BT_AT, DYN_MASS_AT, DYN_RHO_J_AT, DYN_GRAVITY_AT,
 DYN_BASE_POSITION_AT, DYN_BASE_ROTATION_AT) = 0, 3, 6, 9, 12, 13, 16, 19, 22
DYN_PARAMS_SIZE = 31


# rows of ``kernel.probe``'s values (and its Jacobian): first index of each block; the balance
# block follows the n_cables lengths (the compiled code reads these)
TIP_ROWS_AT, AXIS_ROWS_AT, LENGTH_ROWS_AT = 0, 3, 6


@dataclass(frozen=True)
class ProbeRows:
    """Row blocks of ``kernel.probe`` for a robot with ``n_cables`` cables."""

    n_cables: int

    tip = slice(TIP_ROWS_AT, AXIS_ROWS_AT)
    axis = slice(AXIS_ROWS_AT, LENGTH_ROWS_AT)

    @property
    def lengths(self):
        """Cable lengths, m."""
        return slice(LENGTH_ROWS_AT, LENGTH_ROWS_AT + self.n_cables)

    @property
    def balance(self):
        """Tip moment balance (zero at equilibrium)."""
        return slice(LENGTH_ROWS_AT + self.n_cables, LENGTH_ROWS_AT + 3 + self.n_cables)

    @property
    def size(self):
        """Number of rows."""
        return LENGTH_ROWS_AT + 3 + self.n_cables


class KernelModel(NamedTuple):
    """Everything the compiled solvers read of one robot, passed to them as one argument.

    Built once per robot (:class:`continuum_statics.core.rod.model.Model`); a solve under other rod
    constants (gravity continuation, calibration) passes ``_replace(params=...)``. Numba types a
    record of this shape in ~2.5 us per call (flat arrays: ~1.5 us), so only
    ``kernel.integrate_batch``, the single IVP of ``Robot.solve_ivp``, keeps flat arguments.
    """

    s_grid: np.ndarray  # (N,) integration nodes, unstretched arc length (m)
    params: np.ndarray  # rod constants (``kernel.pack_params``)
    code: int  # cable model: ``kernel.POINT_MOMENT`` or ``kernel.DISTRIBUTED``
    step: float  # finite-difference step for u(0) and section moments (1/m)
    section_state_index: np.ndarray  # (S,) first solver-state column of each section, or -1
    section_bases: np.ndarray  # (S, 3, 2) orthonormal bases of the moments a section can apply
    section_ranks: np.ndarray  # (S,) columns of each basis used (0, 1 or 2)
    section_cables: np.ndarray  # (S, width) cable indices of each section, -1 padded
    section_cable_count: np.ndarray  # (S,) cables of each section
    cable_offsets: np.ndarray  # (n_cables, 3) hole at each cable's end disk (its pull's arm), m
    guide_nodes: np.ndarray  # (G,) integration node of each guide disk (0: the base disk)
    cable_last_guide: np.ndarray  # (n_cables,) guide index of each cable's end disk
    cable_end_node: np.ndarray  # (n_cables,) node of each cable's end disk
    section_end_node: np.ndarray  # (S,) node of each section's end disk
    hole_offsets: np.ndarray  # (n_cables, G, 3) hole at each guide, local frame, m (routing.py)
    stage_routes: np.ndarray  # (3 (N - 1), 6 n_cables) l and l' at each interval's RK points
    route_kinks: np.ndarray  # (N - 1,) bool: a cable turns where interval i starts


class Probe(NamedTuple):
    """What ``kernel.probe`` returns."""

    values: np.ndarray  # (ProbeRows.size,) rows as :class:`ProbeRows`
    jacobian: np.ndarray  # (ProbeRows.size, n_free) forward differences
    states: np.ndarray  # (N, 21) node states at the state probed


class DynamicsModel(NamedTuple):
    """What ``dynamics_kernel`` reads of one robot in motion, one argument (SI units).

    :ivar s_grid: (N,) node arc lengths (m)
    :ivar params: (DYN_PARAMS_SIZE,) rod constants and base pose (the ``DYN_*_AT`` layout)
    :ivar disk_mass: (N,) guide-disk mass at each node (kg)
    :ivar bending_scale: (N - 1,) factor on K_bt and B_bt over each interval
    :ivar cable_offsets: (n_cables, 3) each cable's hole at its end disk, local (m)
    :ivar cable_end_node: (n_cables,) node of each cable's end disk
    :ivar scales: (DYNAMIC_STATE,) the unit of each state value in the residual and the
        finite differences: L for p, 1 for R, E I / L^2 for n, E I / L for m, L / s for q,
        1 / s for w
    :ivar bounds: (K + 1,) node index where each shooting segment starts, then the tip's
    :ivar guide_nodes, cable_last_guide, hole_offsets, base_axis, compliance: the cables' paths
        and stretch, as the statics' (``tendon_kernel.path_stretch``)
    :ivar kappa: m per N in the cable rows' min(kappa t, gap); ``radius`` (m) their unit
    :ivar tension_scale: N, the unit of the tension unknowns' finite differences
    """

    s_grid: np.ndarray
    params: np.ndarray
    disk_mass: np.ndarray
    bending_scale: np.ndarray
    cable_offsets: np.ndarray
    cable_end_node: np.ndarray
    scales: np.ndarray
    bounds: np.ndarray
    guide_nodes: np.ndarray
    cable_last_guide: np.ndarray
    hole_offsets: np.ndarray
    base_axis: np.ndarray
    compliance: np.ndarray
    kappa: float
    radius: float
    tension_scale: float


class CableInputs(NamedTuple):
    """What drives the cables in one time step of ``dynamics_kernel.solve_step``.

    :ivar tensions: (n,) N at the end disks when tensions drive the rod (else unused)
    :ivar free: (n,) free lengths (m) when the motors' lengths drive it, or (0,): tensions do
    :ivar friction: (n,) capstan coefficient times each cable's direction of motion
    """

    tensions: np.ndarray
    free: np.ndarray
    friction: np.ndarray
