"""Shape estimation: measured cable lengths and a tip force -> u(0) -> shape (paper sec. V.A).

Unknown: the base bending u(0). Equations: the model's cable lengths (eq. 11) match the
measurements in the least-squares sense, and the tip moment has no component the cables cannot
apply (:attr:`Robot.free_moment_basis`): no twisting moment about the backbone, and no bending
about an axis the cable holes do not span, so unobservable bending stays at the passive
equilibrium instead of being fixed by an arbitrary regulariser.
"""
from dataclasses import dataclass

import numpy as np

from continuum_statics.core import bvp
from continuum_statics.core.inputs import as_vector
from continuum_statics.core.least_squares import constrained_gauss_newton
from continuum_statics.core.shape import Shape


@dataclass(frozen=True, eq=False)
class ShapeEstimate:
    """Result of :func:`estimate_shape`.

    :ivar shape: estimated backbone
    :ivar u0: estimated base bending (1/m)
    :ivar converged: the solver reached a stationary point with the constraints satisfied
    :ivar residual: RMS difference between model and measured cable lengths (m)
    :ivar iterations: Gauss-Newton iterations used
    :ivar observable_bending: number of bending directions the cables observe (0, 1 or 2)
    :ivar message: what limited the estimate, empty when nothing did
    """

    shape: Shape
    u0: np.ndarray
    converged: bool
    residual: float
    iterations: int
    observable_bending: int
    message: str


def estimate_shape(robot, cable_lengths, tip_force=(0.0, 0.0, 0.0), u0_guess=None,
                   tip_moment=(0.0, 0.0, 0.0)):
    """Estimate the shape from measured cable lengths (m, ``robot.cable_names`` order).

    ``tip_force`` (N) and ``tip_moment`` (N m) are the external tip load in the base frame; the
    cables add to the moment. Damped Gauss-Newton from ``u0_guess`` (the previous estimate when
    tracking; default the small-deflection passive solution).
    """
    n_cables = len(robot.cable_names)
    measured = as_vector(cable_lengths, n_cables, 'cable_lengths')
    tip_force = as_vector(tip_force, 3, 'tip_force')
    tip_moment = as_vector(tip_moment, 3, 'tip_moment')
    if u0_guess is None:
        u0_guess = bvp.linear_guess(robot, tip_force, tip_moment)
    u0_guess = as_vector(u0_guess, 3, 'u0_guess')

    cables = slice(3, 3 + n_cables)
    free = slice(3 + n_cables, None)

    def evaluate(x):
        values, jac, states = robot.probe(x, tip_force, tip_moment)
        return values[cables] - measured, jac[cables], values[free], jac[free], states

    result = constrained_gauss_newton(
        evaluate, u0_guess, robot.solver.max_iterations, robot.solver.estimate_tolerance,
        constraint_weight=robot.length ** 2 / robot.c[0])
    observable = 3 - robot.free_moment_basis.shape[1]
    message = ''
    if observable < 2:
        message = ('%d cable(s) observe %d of 2 bending directions; the rest is held at the '
                   'passive equilibrium' % (n_cables, observable))
    if not result.stationary:
        message = ('not converged in %d iterations; ' % result.iterations + message).rstrip('; ')
    residual = float(np.sqrt(np.mean(result.residual ** 2))) if n_cables else 0.0
    shape = robot._shape(result.x, tip_force, result.evaluation)
    return ShapeEstimate(shape=shape, u0=result.x, converged=result.stationary,
                         residual=residual, iterations=result.iterations,
                         observable_bending=observable, message=message)
