"""Boundary-value problems with known loads, by shooting on the base bending u(0) (sec. III.E).

The cable loads (section moments and/or tensions) and the tip load are given; the IVP from the
base yields the tip moment balance (M(L) minus the external tip moment, three equations), and
Newton's method with a finite-difference Jacobian (one batched kernel call per iteration) and a
backtracking line search drives it to zero. When a direct solve fails (very large loads from a
poor start), all loads, gravity included, are applied in increasing fractions (load continuation),
each solve warm-started from the previous one.
"""
import numpy as np

from continuum_statics.core.description.layout import ProbeRows


class ConvergenceError(RuntimeError):
    """A solver did not reach its tolerance within its iteration limit."""


def linear_guess(robot, tip_force, tip_moment, gravity_fraction=1.0, loads=None, fixed=None):
    """u(0) that balances the loads on the straight rod: the small-deflection solution.

    m(0) = tau + L d x F + (L^2 / 2) d x f for a straight rod along d (eqs. 3, 5 integrated),
    plus the disks' weights (sum over intervals of h d x W, W the weight beyond) and the cables'
    moments, which the straight rod carries unchanged down to the base. Gravity is scaled by
    ``gravity_fraction`` (continuation).
    """
    body_force = gravity_fraction * robot.body_force
    axis = robot.base_rotation[:, 2]
    length = robot.length
    base_moment = (tip_moment + length * _cross(axis, tip_force)
                   + 0.5 * length ** 2 * _cross(axis, body_force))
    if robot.interval_weight is not None:
        beyond = gravity_fraction * np.diff(robot.s_grid) @ robot.interval_weight
        base_moment = base_moment + _cross(axis, beyond)
    local = robot.base_rotation.T @ base_moment
    if loads is not None and len(robot.cable_names):
        moments, tensions = robot.loads(loads, fixed)
        local = local + moments.sum(axis=0)
        if robot.cable_model == 'distributed':  # tensions act on the cross-section: t (e3 x l)
            local = local + np.cross([0.0, 0.0, 1.0], robot.hole_offsets[:, 0]).T @ tensions
    return local / robot.c


def _cross(a, b):
    """Return a x b for 3-vectors (np.cross costs ~10 us a call, this ~1 us)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


def _newton(robot, params, loads, fixed, tip_force, tip_moment):
    """Shooting on ``loads[:3]`` = u(0) with the rest of the state held; (state, converged)."""
    settings = robot.solver
    n_cables = len(robot.cable_names)
    balance = ProbeRows(n_cables).balance
    state = np.array(loads, dtype=float)

    def residual(x):
        probed = robot.probe(x, 3, tip_force, tip_moment, fixed, params)
        values, jac = probed.values, probed.jacobian
        return values[balance], jac[balance]

    res, jac = residual(state)
    for _ in range(settings.max_iterations):
        error = np.linalg.norm(res)
        if not np.isfinite(error):
            return state, False
        if error <= settings.bvp_tolerance:
            return state, True
        try:
            step = -np.linalg.solve(jac, res)
        except np.linalg.LinAlgError:
            step = -np.linalg.lstsq(jac, res, rcond=None)[0]
        # backtracking on |residual|^2 (Armijo); each trial is one batched evaluation
        alpha = 1.0
        for _ in range(12):
            trial = state.copy()
            trial[:3] += alpha * step
            trial_res, trial_jac = residual(trial)
            if np.linalg.norm(trial_res) <= (1.0 - 1e-4 * alpha) * error:
                break
            alpha *= 0.5
        else:
            return state, False
        state, res, jac = trial, trial_res, trial_jac
    return state, bool(np.linalg.norm(res) <= settings.bvp_tolerance)


def solve_fixed_loads(robot, loads, fixed, tip_force, tip_moment):
    """Direct shooting from ``loads[:3]``; returns (state, converged). Never raises."""
    return _newton(robot, robot.params, loads, fixed, tip_force, tip_moment)


def solve_loaded(robot, loads, fixed, tip_force, tip_moment, start=None):
    """Solver state (u(0) solved, cable loads from ``loads[3:]`` and ``fixed``) at equilibrium.

    :param loads: solver state whose section-moment coordinates are held (u(0) is ignored)
    :param fixed: cable tensions (N) or None
    :param start: state whose u(0) starts the Newton iteration (default the linear guess)
    :raises ConvergenceError: no convergence, even with load continuation in 64 increments
    """
    loads = np.array(loads, dtype=float)
    fixed = robot.tensions_or_zero(fixed)
    if start is not None:
        loads[:3] = start[:3]
    else:
        loads[:3] = linear_guess(robot, tip_force, tip_moment, loads=loads, fixed=fixed)
    state, converged = _newton(robot, robot.params, loads, fixed, tip_force, tip_moment)
    if converged:
        return state
    for increments in (4, 16, 64):
        state = np.zeros_like(loads)
        for k in range(1, increments + 1):
            fraction = k / increments
            params = robot.params_for(fraction)
            step_loads = fraction * loads
            force, moment = fraction * tip_force, fraction * tip_moment
            if k == 1:
                step_loads[:3] = linear_guess(robot, force, moment, fraction, step_loads,
                                              fraction * fixed)
            else:
                step_loads[:3] = state[:3]
            state, converged = _newton(robot, params, step_loads, fraction * fixed, force,
                                       moment)
            if not converged:
                break
        if converged:
            return state
    raise ConvergenceError(
        'BVP did not converge for tip force %s N, tip moment %s N m and cable loads %s '
        '(tolerance %g, %d iterations, continuation up to 64 increments)'
        % (np.round(tip_force, 6).tolist(), np.round(tip_moment, 6).tolist(),
           np.round(robot.loads(loads, fixed)[1], 4).tolist(), robot.solver.bvp_tolerance,
           robot.solver.max_iterations))
