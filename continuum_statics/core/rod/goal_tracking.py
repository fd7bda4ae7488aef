"""Compiled tip-goal solve: the constrained Gauss-Newton of :mod:`tip_goal` with no Python inside.

The same rows as ``tip_goal._Problem`` built them in Python (goal position, and the tip axis
times L; cables held at a limit; a steep penalty on leaving the length limits; the tip moment
balance as a constraint; in the redundant polish the least change of the section moments, the
goal a constraint) and the same iteration as :func:`least_squares.constrained_gauss_newton`
(damped steps in the constraints' null space, second-order correction, Levenberg-Marquardt
damping). One call costs the model's evaluations only: each is one ``probe`` with the full
finite-difference Jacobian (``probe_runs`` IVPs); in Python the rows' assembly and the loop
cost as much again as the IVPs (0.48 ms per single-section goal instead of ~0.3).
"""
from typing import NamedTuple

import numba
import numpy as np

from continuum_statics.core.description.layout import AXIS_ROWS_AT, LENGTH_ROWS_AT, TIP_ROWS_AT
from continuum_statics.core.rod.kernel import probe
from continuum_statics.core.rod.least_squares import constrained_step


class GoalRows(NamedTuple):
    """What one tip-goal solve asks (``tip_goal._Problem``'s rows)."""

    goal: np.ndarray  #: (3,) tip position goal (m, base frame)
    direction: np.ndarray  #: (3,) unit tip-axis goal, or (0,): none
    held: np.ndarray  #: (k,) int64 cables held at a length limit
    held_at: np.ndarray  #: (k,) the lengths they are held at (m)
    held_scale: float  #: m of cable -> rad of bending (1 / the largest hole radius)
    limits: np.ndarray  #: (n, 2) cable length limits (m)
    penalty: float  #: weight of a length-limit violation (``tip_goal.LIMIT_PENALTY``)
    redundant: bool  #: polish: least change of the section moments, the goal a constraint
    reference: np.ndarray  #: solver state whose section moments the polish stays near


class GoalLimits(NamedTuple):
    """How far one :func:`goal_solve` call may go (``constrained_gauss_newton``'s arguments)."""

    max_iterations: int
    step_tolerance: float  #: stop when the predicted change of the rows is below this (m)
    constraint_weight: float  #: constraint units -> residual units (m), the rod length


class GoalSolved(NamedTuple):
    """What :func:`goal_solve` returns."""

    x: np.ndarray  #: the state reached
    values: np.ndarray  #: the model there (``kernel.probe`` rows)
    iterations: int
    stationary: bool  #: the predicted step fell below the tolerance
    finite: bool  #: the model was finite at the start (else nothing was tried)


@numba.njit(cache=True, nogil=True)
def _rows(model, tip_force, tip_moment, fixed, x, rows, length):
    """Residual, its Jacobian, constraint, its Jacobian and the model values at ``x``."""
    probed = probe(model, tip_force, tip_moment, fixed, x, x.shape[0])
    values, jac = probed.values, probed.jacobian
    n_x = x.shape[0]
    n = rows.limits.shape[0]
    balance = LENGTH_ROWS_AT + n
    n_goal = 3 if rows.direction.shape[0] == 0 else 6
    goal_res = np.empty(n_goal)
    goal_jac = np.empty((n_goal, n_x))
    for i in range(3):
        goal_res[i] = values[TIP_ROWS_AT + i] - rows.goal[i]
        goal_jac[i] = jac[TIP_ROWS_AT + i]
    if n_goal == 6:  # the tip axis times L
        for i in range(3):
            goal_res[3 + i] = (values[AXIS_ROWS_AT + i] - rows.direction[i]) * length
            goal_jac[3 + i] = jac[AXIS_ROWS_AT + i] * length
    n_held = rows.held.shape[0]
    limit_res = np.empty(n)
    limit_jac = np.zeros((n, n_x))
    for j in range(n):
        value = values[LENGTH_ROWS_AT + j]
        over = max(value - rows.limits[j, 1], 0.0) + min(value - rows.limits[j, 0], 0.0)
        limit_res[j] = rows.penalty * over
        if over != 0.0:
            limit_jac[j] = rows.penalty * jac[LENGTH_ROWS_AT + j]
    if rows.redundant:  # least change of the section moments, the goal a constraint
        n_res, n_con = n_x - 3 + n, 3 + n_goal + n_held
    else:
        n_res, n_con = n_goal + n, 3 + n_held
    res = np.zeros(n_res)
    res_jac = np.zeros((n_res, n_x))
    con = np.empty(n_con)
    con_jac = np.empty((n_con, n_x))
    for i in range(3):
        con[i] = values[balance + i]
        con_jac[i] = jac[balance + i]
    at = 3
    if rows.redundant:
        square = length * length
        for i in range(n_x - 3):
            res[i] = (x[3 + i] - rows.reference[3 + i]) * square
            res_jac[i, 3 + i] = square
        res[n_x - 3:] = limit_res
        res_jac[n_x - 3:] = limit_jac
        for i in range(n_goal):
            con[at + i] = goal_res[i] / length
            con_jac[at + i] = goal_jac[i] / length
        at += n_goal
    else:
        res[:n_goal] = goal_res
        res_jac[:n_goal] = goal_jac
        res[n_goal:] = limit_res
        res_jac[n_goal:] = limit_jac
    for k in range(n_held):
        row = LENGTH_ROWS_AT + rows.held[k]
        con[at + k] = (values[row] - rows.held_at[k]) * rows.held_scale
        con_jac[at + k] = jac[row] * rows.held_scale
    return res, res_jac, con, con_jac, values


@numba.njit(cache=True, nogil=True)
def goal_solve(model, tip_force, tip_moment, fixed, x0, rows, limits):
    """Solve min |res(x)|^2 s.t. con(x) = 0 from ``x0``: a :class:`GoalSolved`.

    ``model`` the robot's :class:`~continuum_statics.core.description.layout.KernelModel`,
    ``rows`` a
    :class:`GoalRows`, ``limits`` a :class:`GoalLimits`; ``fixed`` the fixed tensions (N).
    """
    length = limits.constraint_weight
    x = x0.copy()
    res, jac, con, con_jac, values = _rows(model, tip_force, tip_moment, fixed, x, rows, length)
    if not (np.all(np.isfinite(res)) and np.all(np.isfinite(jac)) and np.all(np.isfinite(con))
            and np.all(np.isfinite(con_jac))):
        return GoalSolved(x, values, 0, False, False)
    damping = 1e-6
    # constraints are physics, the residual a wish: a constraint violation costs a thousand
    # times its residual-unit equivalent in the merit function
    penalty = (1e3 * length) ** 2
    current = res @ res + penalty * (con @ con)
    tolerance = limits.step_tolerance
    no_residual = np.zeros(0)
    no_jacobian = np.zeros((0, x.shape[0]))
    for iteration in range(1, limits.max_iterations + 1):
        step, predicted = constrained_step(res, jac, con, con_jac, damping)
        small = (predicted @ predicted <= tolerance ** 2
                 and length ** 2 * (con @ con) <= tolerance ** 2)
        if small or not np.all(np.isfinite(step)):
            return GoalSolved(x, values, iteration, small, True)
        accepted = False
        for _ in range(12):
            trial = x + step
            t_res, t_jac, t_con, t_con_jac, t_values = _rows(model, tip_force, tip_moment,
                                                             fixed, trial, rows, length)
            t_merit = t_res @ t_res + penalty * (t_con @ t_con)
            if not (np.isfinite(t_merit) and t_merit < current):
                # second-order correction: back onto the curved constraint surface before the
                # trial is judged (the Maratos effect's tiny steps otherwise)
                correction, _ = constrained_step(no_residual, no_jacobian, t_con, t_con_jac,
                                                 0.0)
                if np.all(np.isfinite(correction)):
                    c_trial = trial + correction
                    c_res, c_jac, c_con, c_con_jac, c_values = _rows(
                        model, tip_force, tip_moment, fixed, c_trial, rows, length)
                    c_merit = c_res @ c_res + penalty * (c_con @ c_con)
                    if np.isfinite(c_merit) and c_merit < current:
                        trial, t_res, t_jac, t_con, t_con_jac, t_values = (
                            c_trial, c_res, c_jac, c_con, c_con_jac, c_values)
                        t_merit = c_merit
            if np.isfinite(t_merit) and t_merit < current:
                damping = max(damping / 4.0, 1e-9)
                accepted = True
                break
            damping *= 8.0
            step, predicted = constrained_step(res, jac, con, con_jac, damping)
        if not accepted:
            return GoalSolved(x, values, iteration, False, True)
        x, res, jac, con, con_jac, values = trial, t_res, t_jac, t_con, t_con_jac, t_values
        current = t_merit
    return GoalSolved(x, values, limits.max_iterations, False, True)
