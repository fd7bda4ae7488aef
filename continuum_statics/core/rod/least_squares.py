"""Damped Gauss-Newton with exact equality constraints, for three unknowns (u(0)).

Minimises |r(x)|^2 subject to c(x) = 0. Each step satisfies the linearised constraints exactly
(minimum-norm particular step) and takes a Levenberg-Marquardt step for r in the null space of
the constraint Jacobian, so a goal off the reachable set converges to its nearest reachable point
instead of bending the physics to get closer.
"""
from dataclasses import dataclass

import numba
import numpy as np


@dataclass
class LeastSquaresResult:
    """Outcome of :func:`constrained_gauss_newton`; ``evaluation`` is the model at ``x``."""

    x: np.ndarray
    residual: np.ndarray
    constraint: np.ndarray
    iterations: int
    stationary: bool
    evaluation: object
    jacobians: tuple = None


@numba.njit(cache=True, nogil=True)
def constrained_step(res, jac, con, con_jac, damping):
    """Constrained damped Gauss-Newton step and its predicted change of the residual.

    The particular step is the minimum-norm solution of the linearised constraints; the rest of
    the step is a Levenberg-Marquardt step for the residual within their null space.
    """
    n = con_jac.shape[1]
    particular = np.zeros(n)
    null = np.eye(n)
    if con.shape[0] > 0:
        u, sing, vt = np.linalg.svd(con_jac)
        rank = 0
        for value in sing:
            if value > 1e-12 * max(sing[0], 1e-300):
                rank += 1
        coeff = (np.ascontiguousarray(u[:, :rank].T) @ con) / sing[:rank]
        particular = -(np.ascontiguousarray(vt[:rank].T) @ coeff)
        null = vt[rank:].T.copy()
    step = particular
    if res.shape[0] > 0 and null.shape[1] > 0:
        a = jac @ null
        g = res + jac @ particular
        normal = a.T @ a
        scale = damping * (np.trace(normal) / normal.shape[0] + 1e-300)
        for i in range(normal.shape[0]):
            normal[i, i] += scale
        step = particular - null @ np.linalg.solve(normal, a.T @ g)
    return step, jac @ step


def constrained_gauss_newton(evaluate, x0, max_iterations, step_tolerance, constraint_weight):
    """Solve min |r(x)|^2 s.t. c(x) = 0 from ``x0``.

    :param evaluate: x -> (r, dr/dx, c, dc/dx, evaluation), all numpy arrays except the last,
        which is handed back with the result (e.g. the solved states)
    :param step_tolerance: stop when the predicted change of r and the constraint correction
        (weighted) are both below this (units of r)
    :param constraint_weight: converts constraint units to residual units in the merit function
    """
    x = np.array(x0, dtype=float)
    res, jac, con, con_jac, evaluation = evaluate(x)
    if not all(np.all(np.isfinite(a)) for a in (res, jac, con, con_jac)):
        raise ValueError('the rod model is not finite at the start state %s (1/m): is the tip '
                         'load far beyond what the rod can carry?' % np.round(x, 4).tolist())
    damping = 1e-6

    # constraints are physics, the residual is a wish: in the merit function a constraint
    # violation costs a thousand times its residual-unit equivalent, so a step that restores
    # a constraint is accepted even when it moves the tip away from the goal
    penalty = (1e3 * constraint_weight) ** 2

    def merit(r, c):
        return float(r @ r + penalty * (c @ c))

    def result(iteration, stationary):
        return LeastSquaresResult(x, res, con, iteration, bool(stationary), evaluation,
                                  (jac, con_jac))

    current = merit(res, con)
    for iteration in range(1, max_iterations + 1):
        step, predicted = constrained_step(res, jac, con, con_jac, damping)
        small = (predicted @ predicted <= step_tolerance ** 2
                 and constraint_weight ** 2 * (con @ con) <= step_tolerance ** 2)
        if small or not np.all(np.isfinite(step)):
            return result(iteration, small)
        for _ in range(12):
            trial = x + step
            t_res, t_jac, t_con, t_con_jac, t_eval = evaluate(trial)
            t_merit = merit(t_res, t_con)
            if not (np.isfinite(t_merit) and t_merit < current) and len(t_con):
                # second-order correction: the step left the curved constraint surface; pull the
                # trial back onto it before judging it (avoids the Maratos effect's tiny steps)
                correction, _ = constrained_step(np.zeros(0), np.zeros((0, len(x))), t_con,
                                                 t_con_jac, 0.0)
                if np.all(np.isfinite(correction)):
                    c_trial = trial + correction
                    c_eval = evaluate(c_trial)
                    c_merit = merit(c_eval[0], c_eval[2])
                    if np.isfinite(c_merit) and c_merit < current:
                        trial, (t_res, t_jac, t_con, t_con_jac, t_eval) = c_trial, c_eval
                        t_merit = c_merit
            if np.isfinite(t_merit) and t_merit < current:
                damping = max(damping / 4.0, 1e-9)
                break
            damping *= 8.0
            step, predicted = constrained_step(res, jac, con, con_jac, damping)
        else:
            return result(iteration, False)
        x, res, jac, con, con_jac, evaluation = trial, t_res, t_jac, t_con, t_con_jac, t_eval
        current = t_merit
    return result(max_iterations, False)
