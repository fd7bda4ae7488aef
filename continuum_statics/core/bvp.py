"""Boundary-value problem by shooting on the base bending u(0) (paper section III.E).

The IVP from the base gives a tip moment m(L) = R(L) C u(L); Newton's method with a
finite-difference Jacobian (one batched kernel call per iteration) and a backtracking line search
drives m(L) - tau to zero. When a direct solve fails (very large loads from a poor start), the
loads are applied in increasing fractions (load continuation), each solve warm-started from the
previous one.
"""
import numpy as np

from continuum_statics.core.kernel import pack_params


class ConvergenceError(RuntimeError):
    """A solver did not reach its tolerance within its iteration limit."""


def linear_guess(robot, tip_force, tip_moment, body_force=None):
    """u(0) that balances the loads on the straight rod: the small-deflection solution.

    m(0) = tau + L d x F + (L^2 / 2) d x f for a straight rod along d (eqs. 3, 5 integrated).
    """
    body_force = robot.body_force if body_force is None else body_force
    axis = robot.base_rotation[:, 2]
    length = robot.length
    base_moment = (tip_moment + length * np.cross(axis, tip_force)
                   + 0.5 * length ** 2 * np.cross(axis, body_force))
    return (robot.base_rotation.T @ base_moment) / robot.c


def _newton(robot, params, tip_force, tip_moment, u0):
    """Shooting from ``u0``; returns (u0, converged, iterations)."""
    settings = robot.solver
    scale = robot.length / robot.c[0]  # tip moment (N m) -> change of tip angle (rad)
    h = robot.bending_step()
    forces = np.tile(tip_force, (4, 1))
    offsets = np.vstack([np.zeros(3), h * np.eye(3)])

    def residuals(bendings):
        tips = robot.integrate(forces[:len(bendings)], bendings, params)[:, -1]
        rot = tips[:, 3:12].reshape(-1, 3, 3)
        moments = np.einsum('bij,bj->bi', rot, robot.c * tips[:, 15:18])
        return (moments - tip_moment) * scale

    res = residuals(u0 + offsets)
    for iteration in range(1, settings.max_iterations + 1):
        error = np.linalg.norm(res[0])
        if not np.isfinite(error):
            return u0, False, iteration
        if error <= settings.bvp_tolerance:
            return u0, True, iteration
        jac = (res[1:] - res[0]).T / h
        try:
            step = -np.linalg.solve(jac, res[0])
        except np.linalg.LinAlgError:
            step = -np.linalg.lstsq(jac, res[0], rcond=None)[0]
        # backtracking on |residual|^2 (Armijo); each trial is a full batched evaluation
        alpha = 1.0
        for _ in range(12):
            trial = u0 + alpha * step
            trial_res = residuals(trial + offsets)
            if np.linalg.norm(trial_res[0]) <= (1.0 - 1e-4 * alpha) * error:
                break
            alpha *= 0.5
        else:
            return u0, False, iteration
        u0, res = trial, trial_res
    return u0, np.linalg.norm(res[0]) <= settings.bvp_tolerance, settings.max_iterations


def solve_bvp(robot, tip_force, tip_moment, u0_guess=None):
    """u(0) (1/m) such that the rod carries the tip force F and tip moment tau (global frame).

    Direct Newton from ``u0_guess`` (default: the small-deflection solution); on failure, load
    continuation in 4, 16 then 64 increments of F, tau and gravity from the unloaded rod.
    """
    start = linear_guess(robot, tip_force, tip_moment) if u0_guess is None else u0_guess
    u0, converged, _ = _newton(robot, robot.params, tip_force, tip_moment, start)
    if converged:
        return u0
    for increments in (4, 16, 64):
        u0 = np.zeros(3)
        for k in range(1, increments + 1):
            fraction = k / increments
            body_force = fraction * robot.body_force
            params = pack_params(robot.c, robot.d, body_force, robot.base_position,
                                 robot.base_rotation)
            force, moment = fraction * tip_force, fraction * tip_moment
            if k == 1:
                u0 = linear_guess(robot, force, moment, body_force)
            u0, converged, _ = _newton(robot, params, force, moment, u0)
            if not converged:
                break
        if converged:
            return u0
    raise ConvergenceError(
        'BVP did not converge for tip force %s N and tip moment %s N m (tolerance %g, %d '
        'iterations, continuation up to 64 increments)'
        % (np.round(tip_force, 6).tolist(), np.round(tip_moment, 6).tolist(),
           robot.solver.bvp_tolerance, robot.solver.max_iterations))
