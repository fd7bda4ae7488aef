"""Compiled warm-started solve of the displacement-driven statics (what a node runs per cycle).

The quasi-Newton chord iteration of :func:`length_statics.solve_lengths` on the previous solve's
Jacobian pieces, Broyden-updated after every step, as one compiled call: the residual of
:class:`length_statics._Problem` (tip balance; per cable the semismooth min(kappa t, g)) from one
IVP per iteration, the Jacobian assembled for each cable's branch of now, and no Python between
the iterations. It gives up (``ok`` False) as soon as a step gains less than half, and the
caller then solves afresh (:func:`length_statics._newton`).
"""
import numba
import numpy as np

from continuum_statics.core.kernel import (
    POINT_MOMENT,
    cable_lengths_batch,
    integrate_batch,
    loads_from_state,
    probe,
)
from continuum_statics.core.layout import MOMENT_AT
from continuum_statics.core.tendon_kernel import path_stretch

#: Balance tolerance (relative) of a converged solve; cable rows: the estimate tolerance (m).
BALANCE_TOLERANCE = 1e-9
#: What :func:`chord` returns, in order (x, fixed, states, motor, gap, taut: ``_Problem``'s info).
CHORD_RESULT = ('z', 'ok', 'iterations', 'residual', 'x', 'fixed', 'states', 'motor', 'gap',
                'taut', 'balance', 'd_consumed', 'runs', 'model_values')
#: Layout of ``model_values`` (3 + 3 n): tip balance (3), then per cable the free length its path
#: takes (m), its motor-side and its mean tension (N): the model at z, whatever the free lengths.
MODEL_VALUES = ('balance', 'consumed', 'motor', 'mean')


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
def evaluate_at(s_grid, params, model, tip_force, tip_moment, step, section_state_index,
              section_bases, section_ranks, section_cables, section_cable_count, cable_offsets,
              guide_nodes, cable_last_guide, cable_end_node, section_end_node, hole_offsets,
              stage_routes, route_kinks, z, moment_map,
              free, friction, compliance, base_axis, kappa, radius):
    """Residual F(z) (3 + n, scaled as ``_Problem.evaluate``), state, tensions, states, gap, taut.

    Returns (residual, x, fixed, states, motor, gap, taut, mean, model_values): ``mean`` each
    cable's mean tension (N), what its stretch follows; ``model_values`` what the residual at
    any free lengths follows from (:data:`MODEL_VALUES`).
    """
    n = cable_offsets.shape[0]
    x = np.empty(moment_map.shape[0] + 3)
    fixed = np.empty(n)
    _state_of(z, model, moment_map, x, fixed)
    values, _, states = probe(s_grid, params, model, tip_force, tip_moment, x, 0, step, fixed,
                              section_state_index, section_bases, section_ranks, section_cables,
                              section_cable_count, cable_offsets, guide_nodes, cable_last_guide,
                              cable_end_node, section_end_node, hole_offsets, stage_routes,
                              route_kinks)
    tensions = np.ascontiguousarray(z[3:])
    consumed = np.empty(n)
    motor = np.empty(n)
    mean = np.empty(n)
    with_friction = False
    for j in range(n):
        with_friction = with_friction or friction[j] != 0.0
    if with_friction:
        path_stretch(states, guide_nodes, cable_last_guide, hole_offsets, base_axis, tensions,
                     friction, compliance, consumed, motor, mean)
    else:
        for j in range(n):
            consumed[j] = values[6 + j] / (1.0 + tensions[j] * compliance[j])
            motor[j] = tensions[j]
            mean[j] = tensions[j]
    model_values = np.empty(3 + 3 * n)
    for i in range(3):
        model_values[i] = values[6 + n + i]  # rows: core/layout.py ProbeRows
    model_values[3:3 + n] = consumed
    model_values[3 + n:3 + 2 * n] = motor
    model_values[3 + 2 * n:] = mean
    residual, gap, taut = _residual(z, model_values, free, kappa, radius)
    return residual, x, fixed, states, motor, gap, taut, mean, model_values


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
def _state_of(z, model, moment_map, x, fixed):
    """Fill the solver state x and fixed tensions of z (``_Problem.state_of``)."""
    n = fixed.shape[0]
    x[:] = 0.0
    fixed[:] = 0.0
    for i in range(3):
        x[i] = z[i]
    if model == POINT_MOMENT:
        for r in range(moment_map.shape[0]):
            acc = 0.0
            for j in range(n):
                acc += moment_map[r, j] * z[3 + j]
            x[3 + r] = acc
    else:
        for j in range(n):
            fixed[j] = z[3 + j]


@numba.njit(cache=True, nogil=True)
def jacobian_pieces(s_grid, params, model, tip_force, tip_moment, step, section_state_index,
                    section_bases, section_ranks, section_cables, section_cable_count,
                    cable_offsets, guide_nodes, cable_last_guide, cable_end_node,
                    section_end_node, hole_offsets, stage_routes, route_kinks, z, moment_map,
                    compliance, mean, tension_step):
    """Return the Jacobian pieces (balance (3, 3 + n), d_consumed (n, 3 + n)) at z.

    Forward differences, every column in one batch of 4 + n IVPs (``_Problem.evaluate``'s
    pieces, the friction profile held: ``mean`` the cables' mean tensions at z, N); ``step``
    for u(0) (1/m), ``tension_step`` for tensions (N).
    """
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
        _state_of(trial, model, moment_map, x, fixed)
        loads_from_state(x, fixed, model, section_bases, section_ranks, params[0],
                         section_cables, section_cable_count, cable_offsets, moments[b],
                         tensions[b])
        for i in range(3):
            forces[b, i] = tip_force[i]
            bendings[b, i] = x[i]
    states = integrate_batch(s_grid, params, model, forces, bendings, moments, tensions,
                             stage_routes, route_kinks, cable_end_node, section_end_node)
    lengths = cable_lengths_batch(states, guide_nodes, hole_offsets, cable_last_guide)
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
    return balance, d_consumed


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
def chord(s_grid, params, model, tip_force, tip_moment, step, section_state_index,
          section_bases, section_ranks, section_cables, section_cable_count, cable_offsets,
          guide_nodes, cable_last_guide, cable_end_node, section_end_node, hole_offsets,
          stage_routes, route_kinks, z0, moment_map, free,
          friction, compliance, base_axis, kappa, radius, scale, balance0, d_consumed0,
          tolerance, balance_tolerance, max_iterations, refreshes, start_values, start_states):
    """Chord steps from ``z0``; returns the record :data:`CHORD_RESULT` names.

    The arguments up to ``route_kinks`` are those of :func:`kernel.probe` without the
    state, ``n_free`` and the fixed tensions (flat: a tuple argument costs numba's dispatcher
    time to type). ``z0`` = [u(0) (1/m); end tensions (N)]; ``moment_map`` the robot's
    ``tension_moment_map`` (point-moment model; any array of its shape otherwise); ``free``
    (n,) free lengths Lf (m); ``friction`` (n,) mu times the sign of motion; ``compliance`` 1/EA
    (1/N); ``kappa`` (m/N), ``radius`` (m) and ``scale`` (3 + n) the problem's scales;
    ``balance0`` (3, 3 + n) and ``d_consumed0`` (n, 3 + n) the previous Jacobian pieces (m per
    unscaled z), returned Broyden-updated; ``tolerance`` on the cable rows (m) and
    ``balance_tolerance`` on the balance rows (relative, :data:`BALANCE_TOLERANCE`). A step that
    gains less than half is retried on Jacobian pieces refreshed by forward differences at z
    (:func:`jacobian_pieces`, 4 + n IVPs), at most ``refreshes`` times; then ``ok`` is False.
    ``start_values`` (:data:`MODEL_VALUES`) and ``start_states`` the model at ``z0`` when known
    from the solve before (same tip load and friction directions): the first IVP is saved;
    empty: integrate it. The record ends with the IVPs integrated and the model at z.
    """
    args = (s_grid, params, model, tip_force, tip_moment, step, section_state_index,
            section_bases, section_ranks, section_cables, section_cable_count, cable_offsets,
            guide_nodes, cable_last_guide, cable_end_node, section_end_node, hole_offsets,
            stage_routes, route_kinks)
    n = cable_offsets.shape[0]
    balance = balance0.copy()
    d_consumed = d_consumed0.copy()
    z = z0.copy()
    if start_values.shape[0] == 3 + 3 * n:
        model_values = start_values
        states = start_states.copy()  # the caller's stays writable (a Shape of it would not be)
        x = np.empty(moment_map.shape[0] + 3)
        fixed = np.empty(n)
        _state_of(z, model, moment_map, x, fixed)
        res, gap, taut = _residual(z, model_values, free, kappa, radius)
        motor = model_values[3 + n:3 + 2 * n].copy()
        mean = model_values[3 + 2 * n:].copy()
        runs = 0
    else:
        res, x, fixed, states, motor, gap, taut, mean, model_values = evaluate_at(
            *args, z, moment_map, free, friction, compliance, base_axis, kappa, radius)
        runs = 1
    error = res @ res
    iteration = 0
    limit = max_iterations
    while iteration < limit:
        if _done(res, radius, tolerance, balance_tolerance):
            return (z, True, iteration, res, x, fixed, states, motor, gap, taut, balance,
                    d_consumed, runs, model_values)
        iteration += 1
        jacobian = _jacobian(balance, d_consumed, taut, kappa, radius, scale)
        scaled = -_solve_linear(jacobian, res)
        trial = z + scaled * scale
        t_res, t_x, t_fixed, t_states, t_motor, t_gap, t_taut, t_mean, t_values = evaluate_at(
            *args, trial, moment_map, free, friction, compliance, base_axis, kappa, radius)
        runs += 1
        t_error = t_res @ t_res
        if not t_error <= 0.25 * error:
            if refreshes == 0:
                return (z, False, iteration, res, x, fixed, states, motor, gap, taut, balance,
                        d_consumed, runs, model_values)
            # the secant pieces point nowhere useful: the model's own at z, then retry
            refreshes -= 1
            tension_step = 1e-7 * scale[3] if n else 1.0
            balance, d_consumed = jacobian_pieces(*args, z, moment_map, compliance, mean,
                                                  tension_step)
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
    return (z, _done(res, radius, tolerance, balance_tolerance), iteration, res, x, fixed,
            states, motor, gap, taut, balance, d_consumed, runs, model_values)
