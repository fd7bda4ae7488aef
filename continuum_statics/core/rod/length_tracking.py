"""Compiled warm-started solve of the displacement-driven statics (what a node runs per cycle).

The quasi-Newton chord iteration of :func:`length_statics.solve_lengths` on the previous solve's
Jacobian pieces, Broyden-updated after every step, as one compiled call: the residual of
:class:`length_statics._Problem` (tip balance; per cable the semismooth min(kappa t, g)) from one
IVP per iteration, the Jacobian assembled for each cable's branch of now, and no Python between
the iterations. It gives up (``ok`` False) as soon as a step gains less than half, and the
caller then solves afresh (:func:`length_statics._newton`).
"""
from typing import NamedTuple

import numba
import numpy as np

from continuum_statics.core.description.layout import LENGTH_ROWS_AT, MOMENT_AT
from continuum_statics.core.rod.kernel import (
    POINT_MOMENT,
    batch_loads,
    integrate_with_lengths,
    probe,
)
from continuum_statics.core.rod.tendon_kernel import path_stretch

#: Balance tolerance (relative) of a converged solve; cable rows: the estimate tolerance (m).
BALANCE_TOLERANCE = 1e-9
#: Layout of ``model_values`` (3 + 3 n): tip balance (3), then per cable the free length its path
#: takes (m), its motor-side and its mean tension (N): the model at z, whatever the free lengths.
MODEL_VALUES = ('balance', 'consumed', 'motor', 'mean')


class TendonArgs(NamedTuple):
    """The tendon problem at one measurement (``length_statics._Problem``'s constants)."""

    moment_map: np.ndarray  #: the robot's ``tension_moment_map`` (any array of it otherwise)
    free: np.ndarray  #: (n,) free lengths Lf (m)
    friction: np.ndarray  #: (n,) mu times the sign of motion
    compliance: np.ndarray  #: (n,) 1 / EA (1/N)
    base_axis: np.ndarray  #: (3,) the rod's axis at the base, global
    kappa: float  #: m/N, the semismooth residual's scale of a slack cable's tension
    radius: float  #: m, the scale of the cable rows


class Evaluation(NamedTuple):
    """What :func:`evaluate_at` returns: the residual at z and the model there."""

    residual: np.ndarray  #: (3 + n,) scaled as ``_Problem.evaluate``
    x: np.ndarray  #: solver state of z
    fixed: np.ndarray  #: (n,) fixed tensions of z (N)
    states: np.ndarray  #: (N, 21) node states
    motor: np.ndarray  #: (n,) motor-side tensions (N)
    gap: np.ndarray  #: (n,) free length minus what the path takes (m)
    taut: np.ndarray  #: (n,) bool
    mean: np.ndarray  #: (n,) mean tensions (N), what each stretch follows
    model_values: np.ndarray  #: (3 + 3 n,) :data:`MODEL_VALUES`


class Pieces(NamedTuple):
    """The Jacobian's pieces at z (m per unscaled z)."""

    balance: np.ndarray  #: (3, 3 + n) d balance / dz
    d_consumed: np.ndarray  #: (n, 3 + n) d consumed free length / dz


class ChordLimits(NamedTuple):
    """How far one :func:`chord` call may go."""

    tolerance: float  #: on the cable rows (m)
    balance_tolerance: float  #: on the balance rows (relative, :data:`BALANCE_TOLERANCE`)
    max_iterations: int
    refreshes: int  #: Jacobian refreshes allowed after a step that gained less than half


class Chorded(NamedTuple):
    """What :func:`chord` returns."""

    z: np.ndarray
    ok: bool
    iterations: int
    residual: np.ndarray
    x: np.ndarray
    fixed: np.ndarray
    states: np.ndarray
    motor: np.ndarray
    gap: np.ndarray
    taut: np.ndarray
    pieces: Pieces  #: Broyden-updated: they start the next call
    runs: int  #: IVPs integrated
    model_values: np.ndarray  #: the model at z (:data:`MODEL_VALUES`)


@numba.njit(cache=True, nogil=True)
def _solve_linear(matrix, rhs):
    """Solve matrix x = rhs: LU with partial pivoting, least norm when (nearly) singular."""
    n = rhs.shape[0]
    a = matrix.copy()
    b = rhs.copy()
    largest = np.max(np.abs(a))
    for k in range(n):
        pivot = k + np.argmax(np.abs(a[k:, k]))
        if not abs(a[pivot, k]) > 1e-13 * largest:
            return np.linalg.lstsq(matrix, rhs, rcond=1e-12)[0]
        if pivot != k:
            for c in range(n):
                a[k, c], a[pivot, c] = a[pivot, c], a[k, c]
            b[k], b[pivot] = b[pivot], b[k]
        for r in range(k + 1, n):
            factor = a[r, k] / a[k, k]
            if factor != 0.0:
                for c in range(k, n):
                    a[r, c] -= factor * a[k, c]
                b[r] -= factor * b[k]
    x = np.empty(n)
    for k in range(n - 1, -1, -1):
        acc = b[k]
        for c in range(k + 1, n):
            acc -= a[k, c] * x[c]
        x[k] = acc / a[k, k]
    return x


@numba.njit(cache=True, nogil=True)
def evaluate_at(model, tip_force, tip_moment, z, tendon):
    """Return the residual F(z) and the model there: an :class:`Evaluation`.

    ``model`` the robot's :class:`~continuum_statics.core.description.layout.KernelModel`,
    ``tendon`` a
    :class:`TendonArgs`; ``Evaluation.mean`` is each cable's mean tension (N), what its stretch
    follows; ``model_values`` what the residual at any free lengths follows from.
    """
    n = model.cable_offsets.shape[0]
    code = model.code
    x = np.empty(tendon.moment_map.shape[0] + 3)
    fixed = np.empty(n)
    _state_of(z, code, tendon.moment_map, x, fixed)
    probed = probe(model, tip_force, tip_moment, fixed, x, np.int64(0))  # not Literal[int]
    values, states = probed.values, probed.states
    friction, compliance = tendon.friction, tendon.compliance
    tensions = np.ascontiguousarray(z[3:])
    consumed = np.empty(n)
    motor = np.empty(n)
    mean = np.empty(n)
    with_friction = False
    for j in range(n):
        with_friction = with_friction or friction[j] != 0.0
    if with_friction:
        path_stretch(states, model.guide_nodes, model.cable_last_guide, model.hole_offsets,
                     tendon.base_axis, tensions, friction, compliance, consumed, motor, mean)
    else:
        for j in range(n):
            consumed[j] = values[LENGTH_ROWS_AT + j] / (1.0 + tensions[j] * compliance[j])
            motor[j] = tensions[j]
            mean[j] = tensions[j]
    model_values = np.empty(3 + 3 * n)
    for i in range(3):
        model_values[i] = values[LENGTH_ROWS_AT + n + i]  # the balance rows of ProbeRows
    model_values[3:3 + n] = consumed
    model_values[3 + n:3 + 2 * n] = motor
    model_values[3 + 2 * n:] = mean
    residual, gap, taut = _residual(z, model_values, tendon.free, tendon.kappa, tendon.radius)
    return Evaluation(residual, x, fixed, states, motor, gap, taut, mean, model_values)


@numba.njit(cache=True, nogil=True)
def _residual(z, model_values, free, kappa, radius):
    """Residual, gap (m) and taut of z from the model there (:data:`MODEL_VALUES` layout)."""
    n = free.shape[0]
    residual = np.empty(3 + n)
    gap = np.empty(n)
    taut = np.empty(n, dtype=np.bool_)
    for i in range(3):
        residual[i] = model_values[i]
    for j in range(n):
        t = z[3 + j]
        gap[j] = free[j] - model_values[3 + j]
        taut[j] = kappa * t >= gap[j]
        residual[3 + j] = (gap[j] if taut[j] else kappa * t) / radius
    return residual, gap, taut


@numba.njit(cache=True, nogil=True)
def _state_of(z, code, moment_map, x, fixed):
    """Fill the solver state x and fixed tensions of z (``_Problem.state_of``)."""
    n = fixed.shape[0]
    x[:] = 0.0
    fixed[:] = 0.0
    for i in range(3):
        x[i] = z[i]
    if code == POINT_MOMENT:
        for r in range(moment_map.shape[0]):
            acc = 0.0
            for j in range(n):
                acc += moment_map[r, j] * z[3 + j]
            x[3 + r] = acc
    else:
        for j in range(n):
            fixed[j] = z[3 + j]


@numba.njit(cache=True, nogil=True)
def jacobian_pieces(model, tip_force, tip_moment, z, moment_map, compliance, mean,
                    tension_step):
    """Return the Jacobian :class:`Pieces` at z.

    Forward differences, every column in one batch of 4 + n IVPs (``_Problem.evaluate``'s
    pieces, the friction profile held: ``mean`` the cables' mean tensions at z, N); the model's
    ``step`` for u(0) (1/m), ``tension_step`` for tensions (N).
    """
    s_grid, params, code, step = model.s_grid, model.params, model.code, model.step
    cable_offsets = model.cable_offsets
    section_bases = model.section_bases
    n = cable_offsets.shape[0]
    size = 3 + n
    n_sections = section_bases.shape[0]
    batch = 1 + size
    forces = np.empty((batch, 3))
    bendings = np.empty((batch, 3))
    moments = np.empty((batch, n_sections, 3))
    tensions = np.empty((batch, n))
    x = np.empty(moment_map.shape[0] + 3)
    fixed = np.empty(n)
    trial = np.empty(size)
    for b in range(batch):
        trial[:] = z
        if b > 0:
            trial[b - 1] += step if b <= 3 else tension_step
        _state_of(trial, code, moment_map, x, fixed)
        batch_loads(model, x, fixed, tip_force, b, forces, bendings, moments, tensions)
    states, lengths = integrate_with_lengths(model, forces, bendings, moments, tensions)
    tip = s_grid.shape[0] - 1
    scale = s_grid[tip] / params[0]  # balance rows: (M_end - tau) L / (E I), as kernel.probe
    balance = np.empty((3, size))
    d_consumed = np.empty((n, size))
    for c in range(size):
        h = step if c < 3 else tension_step
        for i in range(3):
            balance[i, c] = ((states[1 + c, tip, MOMENT_AT + i] - states[0, tip, MOMENT_AT + i])
                            * scale / h)
        for j in range(n):
            stretch = 1.0 + mean[j] * compliance[j]
            d_consumed[j, c] = (lengths[1 + c, j] - lengths[0, j]) / h / stretch
    for j in range(n):
        stretch = 1.0 + mean[j] * compliance[j]
        d_consumed[j, 3 + j] -= lengths[0, j] * compliance[j] / (stretch * stretch)
    return Pieces(balance, d_consumed)


@numba.njit(cache=True, nogil=True)
def _jacobian(balance, d_consumed, taut, kappa, radius, scale):
    """Jacobian in scaled z for the cables' branches ``taut`` (``_Problem.jacobian``)."""
    n = taut.shape[0]
    size = 3 + n
    jacobian = np.zeros((size, size))
    for c in range(size):
        for i in range(3):
            jacobian[i, c] = balance[i, c] * scale[c]
        for j in range(n):
            if taut[j]:
                jacobian[3 + j, c] = -d_consumed[j, c] / radius * scale[c]
    for j in range(n):
        if not taut[j]:
            jacobian[3 + j, 3 + j] = kappa / radius * scale[3 + j]
    return jacobian


@numba.njit(cache=True, nogil=True)
def _done(residual, radius, tolerance, balance_tolerance):
    n = residual.shape[0]
    for i in range(3):
        if not abs(residual[i]) <= balance_tolerance:
            return False
    for i in range(3, n):
        if not abs(residual[i]) * radius <= tolerance:
            return False
    return True


@numba.njit(cache=True, nogil=True)
def chord(model, tip_force, tip_moment, z0, tendon, scale, pieces, limits, start_values,
          start_states):
    """Chord steps from ``z0``; returns a :class:`Chorded`.

    ``model`` the robot's :class:`~continuum_statics.core.description.layout.KernelModel`; ``z0``
    = [u(0)
    (1/m); end tensions (N)]; ``tendon`` the problem's :class:`TendonArgs`; ``scale`` (3 + n)
    its scales of z; ``pieces`` the previous Jacobian :class:`Pieces` (m per unscaled z),
    returned Broyden-updated; ``limits`` a :class:`ChordLimits`. A step that gains less than
    half is retried on Jacobian pieces refreshed by forward differences at z
    (:func:`jacobian_pieces`, 4 + n IVPs), at most ``limits.refreshes`` times; then ``ok`` is
    False. ``start_values`` (:data:`MODEL_VALUES`) and ``start_states`` the model at ``z0`` when
    known from the solve before (same tip load and friction directions): the first IVP is
    saved; empty: integrate it.
    """
    n = model.cable_offsets.shape[0]
    moment_map, free, kappa, radius = (tendon.moment_map, tendon.free, tendon.kappa,
                                       tendon.radius)
    balance0, d_consumed0 = pieces.balance, pieces.d_consumed
    tolerance, balance_tolerance = limits.tolerance, limits.balance_tolerance
    max_iterations, refreshes = limits.max_iterations, limits.refreshes
    balance = balance0.copy()
    d_consumed = d_consumed0.copy()
    z = z0.copy()
    if start_values.shape[0] == 3 + 3 * n:
        model_values = start_values
        states = start_states.copy()  # the caller's stays writable (a Shape of it would not be)
        x = np.empty(moment_map.shape[0] + 3)
        fixed = np.empty(n)
        _state_of(z, model.code, moment_map, x, fixed)
        res, gap, taut = _residual(z, model_values, free, kappa, radius)
        motor = model_values[3 + n:3 + 2 * n].copy()
        mean = model_values[3 + 2 * n:].copy()
        runs = 0
    else:
        res, x, fixed, states, motor, gap, taut, mean, model_values = evaluate_at(
            model, tip_force, tip_moment, z, tendon)
        runs = 1
    error = res @ res
    iteration = 0
    limit = max_iterations
    while iteration < limit:
        if _done(res, radius, tolerance, balance_tolerance):
            return Chorded(z, True, iteration, res, x, fixed, states, motor, gap, taut,
                           Pieces(balance, d_consumed), runs, model_values)
        iteration += 1
        jacobian = _jacobian(balance, d_consumed, taut, kappa, radius, scale)
        scaled = -_solve_linear(jacobian, res)
        trial = z + scaled * scale
        t_res, t_x, t_fixed, t_states, t_motor, t_gap, t_taut, t_mean, t_values = evaluate_at(
            model, tip_force, tip_moment, trial, tendon)
        runs += 1
        t_error = t_res @ t_res
        if not t_error <= 0.25 * error:
            if refreshes == 0:
                return Chorded(z, False, iteration, res, x, fixed, states, motor, gap, taut,
                               Pieces(balance, d_consumed), runs, model_values)
            # the secant pieces point nowhere useful: the model's own at z, then retry
            refreshes -= 1
            tension_step = 1e-7 * scale[3] if n else 1.0
            balance, d_consumed = jacobian_pieces(model, tip_force, tip_moment, z, moment_map,
                                                  tendon.compliance, mean, tension_step)
            runs += 4 + n
            limit = iteration + max_iterations
            continue
        # Broyden's rank-one update of the assembled Jacobian, put back into its pieces: the
        # balance rows and the taut cables' rows (a slack cable's row is exact)
        update = np.outer(t_res - res - jacobian @ scaled, scaled) / (scaled @ scaled)
        for c in range(3 + n):
            for i in range(3):
                balance[i, c] += update[i, c] / scale[c]
            for j in range(n):
                if taut[j]:
                    d_consumed[j, c] -= update[3 + j, c] * radius / scale[c]
        z, res, x, fixed, states, motor, gap, taut, mean, error, model_values = (
            trial, t_res, t_x, t_fixed, t_states, t_motor, t_gap, t_taut, t_mean, t_error,
            t_values)
    return Chorded(z, _done(res, radius, tolerance, balance_tolerance), iteration, res, x,
                   fixed, states, motor, gap, taut, Pieces(balance, d_consumed), runs,
                   model_values)
