"""Tip-goal solving: goal position -> u(0) -> cable lengths (paper sec. V.B, end-point control).

Damped least squares on the tip position with the same physical constraint as the estimator:
the tip moment has no component the cables cannot apply (no twist about the backbone). A single
section then has two bending degrees of freedom and its reachable tips form a surface; a goal off
it converges to the nearest reachable tip and reports the remaining distance as ``error``. Cable
length limits are honoured with an active set: a cable that would leave its range is held at the
limit as one more equality constraint, and the solve continues with the freedom that is left.
"""
from dataclasses import dataclass

import numpy as np

from continuum_statics.core import bvp
from continuum_statics.core.inputs import as_vector
from continuum_statics.core.least_squares import constrained_gauss_newton
from continuum_statics.core.shape import Shape


@dataclass(frozen=True, eq=False)
class TipGoalSolution:
    """Result of :func:`solve_tip_goal`.

    :ivar shape: backbone at the solution
    :ivar u0: base bending (1/m)
    :ivar cable_lengths: cable lengths to command (m), ``robot.cable_names`` order
    :ivar converged: the tip is within the tolerance of the goal
    :ivar error: distance from the reached tip to the goal (m)
    :ivar iterations: Gauss-Newton iterations used, over all active-set rounds
    :ivar limited_cables: names of cables held at a length limit
    :ivar message: why the goal was not reached, empty when it was
    """

    shape: Shape
    u0: np.ndarray
    cable_lengths: np.ndarray
    converged: bool
    error: float
    iterations: int
    limited_cables: tuple
    message: str


def solve_tip_goal(robot, goal_position, tip_force=(0.0, 0.0, 0.0), u0_guess=None,
                   tolerance=None, tip_moment=(0.0, 0.0, 0.0)):
    """Find u(0) and cable lengths that put the tip at ``goal_position`` (m, global frame).

    ``tip_force`` (N) and ``tip_moment`` (N m) are the external tip load, base frame.

    :param u0_guess: start (1/m); default the passive equilibrium's small-deflection solution
    :param tolerance: position tolerance (m); default ``robot.solver.goal_tolerance``
    """
    goal = as_vector(goal_position, 3, 'goal_position')
    tip_force = as_vector(tip_force, 3, 'tip_force')
    tip_moment = as_vector(tip_moment, 3, 'tip_moment')
    tolerance = robot.solver.goal_tolerance if tolerance is None else float(tolerance)
    if not np.isfinite(tolerance) or tolerance <= 0.0:
        raise ValueError('tolerance must be a finite number > 0 m, got %r' % tolerance)
    if u0_guess is None:
        u0_guess = bvp.linear_guess(robot, tip_force, tip_moment)
    x = as_vector(u0_guess, 3, 'u0_guess')
    limits = robot.cable_length_limits
    n_cables = len(robot.cable_names)
    cables = slice(3, 3 + n_cables)
    free = slice(3 + n_cables, None)
    # a cable held at a limit is one more constraint, scaled from m of cable to N m of tip
    # moment (E I / L^2 per m) so that all constraint rows are of one size
    held_scale = robot.c[0] / robot.length ** 2
    held, held_at = [], []
    iterations = 0

    def evaluate(x):
        values, jac, states = robot.probe(x, tip_force, tip_moment)
        rows = [3 + i for i in held]
        con = np.concatenate([values[free], (values[rows] - held_at) * held_scale])
        con_jac = np.vstack([jac[free], jac[rows] * held_scale])
        return values[0:3] - goal, jac[0:3], con, con_jac, (states, values[cables])

    while True:
        result = constrained_gauss_newton(
            evaluate, x, robot.solver.max_iterations, 0.01 * tolerance,
            constraint_weight=robot.length ** 2 / robot.c[0])
        iterations += result.iterations
        x = result.x
        states, lengths = result.evaluation
        violated = [i for i in range(n_cables) if i not in held and not (
            limits[i, 0] - 1e-9 <= lengths[i] <= limits[i, 1] + 1e-9)]
        if not violated:
            break
        for i in violated:
            held.append(i)
            held_at.append(float(np.clip(lengths[i], limits[i, 0], limits[i, 1])))

    error = float(np.linalg.norm(result.residual))
    converged = error <= tolerance
    limited = tuple(robot.cable_names[i] for i in sorted(held))
    message = ''
    if not converged:
        message = 'goal not reached: tip %.3g m from goal (tolerance %.3g m)' % (error, tolerance)
        if limited:
            message += '; cable(s) at length limit: ' + ', '.join(limited)
        elif result.stationary:
            message += '; nearest reachable tip (goal off the reachable surface)'
        else:
            message += '; not converged in %d iterations' % iterations
    shape = robot._shape(x, tip_force, states)
    return TipGoalSolution(shape=shape, u0=x, cable_lengths=lengths.copy(), converged=converged,
                           error=error, iterations=iterations, limited_cables=limited,
                           message=message)
