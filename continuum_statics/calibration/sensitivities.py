"""Exact tip sensitivities of a replay: the implicit-function theorem on each row's equilibrium.

A row of :func:`replay.replay_solutions` solves ``solve_lengths``' equations E(z, p) = 0
(:mod:`continuum_statics.core.statics.length_statics`): the tip moment balance (3 rows) and, per
taut
cable, its gap Lf - consumed = 0; a slack cable's end tension is 0 whatever p. The
unknowns z are u(0) and the taut cables' end tensions, p the fit's variables. With E_z
invertible (the Jacobian every Newton step of the row already uses),

    dz/dp = -E_z^-1 E_p,        dP/dp = P_p + P_z dz/dp,

where P is the row's marker point (tip position + tip rotation times ``tip_marker``); a row that
did not converge is differentiated at its best state. The partial derivatives are taken at
the row's solution by central differences of the model with z held (one-sided at a bound; one
IVP each, no re-solve): they carry no solver tolerance, so the result agrees with whole
re-solved replays to their own convergence floor, and a column costs two IVPs per row where a
finite-difference replay costs a chord solve per row.

Memory: friction follows each cable's friction state, carried from row to row
(:func:`length_statics.motion_since`). It moves with the motor travel, which no parameter
changes, except through ``stick_length`` (the travel over which it turns): a variant robot
with another stick length gets its own chain of states over the whole run, so that column
carries the memory; every other column holds each row's states (a parameter step that flips a
sign is a kink no derivative describes).
"""
from types import SimpleNamespace

import numpy as np

from continuum_statics.calibration.pool import fork_pool
from continuum_statics.core.description.layout import POSITION, ROTATION
from continuum_statics.core.rod.length_tracking import TendonArgs
from continuum_statics.core.statics.length_statics import (
    motion_since,
    problem_constants,
    warm_unknowns,
)

#: Central-difference step of u(0) (times 1/L) and of an end tension (times E I / (L r)).
STATE_STEP = 1e-5
#: Step of each variable relative to its finite-difference replay step
#: (:data:`parameters.DIFFERENCE_STEPS`): z is held, so no solver tolerance limits it.
PARAMETER_STEP_FRACTION = 0.1
_NO_LOAD = np.zeros(3)

_JOB = None  # what a forked worker differentiates: (base, variants, stencils, lengths, solutions)


class RowModel:
    """One robot's model of a row at fixed z (compiled: one IVP and the cables' stretch).

    :param robot: a candidate robot
    :param rod: a robot whose rod and holes are the same (its IVP may be reused), or None
    """

    def __init__(self, robot, rod=None):
        self.robot = robot
        constants = problem_constants(robot)
        self.compliance, self.base_axis = constants.compliance, constants.base_axis
        self.radius, self.t_ref, self.kappa = constants.radius, constants.t_ref, constants.kappa
        self.moment_map, self.friction = constants.kernel_map, constants.friction
        self.marker = np.asarray(robot.tip_marker, dtype=float)
        self.same_rod = rod is not None and _same_rod(robot, rod)
        # the same rod and the same stretch of every cable at z (only zero offsets or
        # pretension differ): the base's path_stretch at z is its own, only its free lengths
        # differ
        self.free_only = self.same_rod and _same_stretch(robot, rod)
        self.motions = None  # (rows, n) friction states of its own, else the row's
        self.frees = None  # (rows, n) free lengths of a run's rows (:meth:`free_rows`)

    def free_rows(self, lengths):
        """Keep the free lengths (m) of every row of motor-side ``lengths`` (rows, n)."""
        self.frees = self.free(lengths)
        return self

    def free(self, lengths, row=None):
        """Free lengths (m) of motor-side ``lengths`` (row ``row`` of :meth:`free_rows`)."""
        if row is not None and self.frees is not None:
            return self.frees[row]
        return self.robot.tendons.free_lengths(lengths, self.robot.straight_cable_lengths)

    def at(self, z, lengths, motion, row=None):
        """Return (balance (3,), gap (n,) m, marker point (3,) m, node states) at z."""
        at = self.robot.model.evaluate_at(
            _NO_LOAD, _NO_LOAD, z, TendonArgs(self.moment_map, self.free(lengths, row),
                                              self.friction * motion, self.compliance,
                                              self.base_axis, self.kappa, self.radius))
        return at.residual[:3], at.gap, self._point(at.states), at.states

    def on(self, states, balance, z, lengths, motion, row=None):
        """:meth:`at` on another robot's IVP at z (``same_rod``): only the cables' stretch."""
        consumed = self.consumed(states, z, motion)
        return balance, self.free(lengths, row) - consumed, self._point(states), states

    def consumed(self, states, z, motion):
        """Free length (m) each cable's path and stretch consume on the IVP ``states`` at z."""
        consumed, _, _ = self.robot.model.path_stretch(
            states, self.base_axis, np.ascontiguousarray(z[3:]), self.friction * motion,
            self.compliance)
        return consumed

    def _point(self, states):
        return states[-1, POSITION] + states[-1, ROTATION].reshape(3, 3) @ self.marker


def _same_rod(a, b):
    """Whether robots a and b integrate the same IVP at every z (only tendons or marker differ)."""
    return all(np.array_equal(p, q) for p, q in zip(a.model.record, b.model.record))


def _same_stretch(a, b):
    """Whether robots a and b stretch cables alike (friction too) and track one tip point."""
    ta, tb = a.tendons, b.tendons
    return np.array_equal(a.tip_marker, b.tip_marker) and all(
        np.array_equal(getattr(ta, name), getattr(tb, name))
        for name in ('stiffness', 'friction', 'stick_length'))


def stencil(x, step, low, high):
    """Points and weights of a second-order first derivative of variable x within its bounds.

    Central where x +- step stays inside [low, high], else one-sided (three points).
    :returns: (offsets, weights): d f / dx ~ sum(w f(x + o)) / step
    """
    if x - step >= low and x + step <= high:
        return (-step, step), (-0.5, 0.5)
    sign = 1.0 if x + 2.0 * step <= high else -1.0
    return (0.0, sign * step, 2.0 * sign * step), (-1.5 * sign, 2.0 * sign, -0.5 * sign)


def friction_states(robot, lengths, solved):
    """Return the friction state of every row (rows, n) of a replay by ``robot``.

    The chain of :func:`replay.replay_solutions`: each row's from the last solved row's
    (``solved``: (rows,) bool, False where the solve raised).
    """
    states, warm = np.zeros((len(lengths), len(robot.cable_names))), None
    for i, row in enumerate(lengths):
        free = robot.tendons.free_lengths(row, robot.straight_cable_lengths)
        motion, reference = motion_since(robot, free, warm)
        states[i] = motion
        if solved[i]:
            warm = SimpleNamespace(motion=motion, motion_reference=reference, free_lengths=free)
    return states


def row_sensitivities(base, variants, stencils, lengths, solution, row=None):
    """Return d marker point / d variable (3, m) of one row at its solution (no tip load).

    :param base: the :class:`RowModel` of the robot the row was solved with
    :param variants: per variable, the :class:`RowModel` of each of its stencil's offsets
    :param stencils: per variable, (offsets, weights, step) of :func:`stencil`
    :param row: the row's index (the variants' own friction states)
    """
    robot = base.robot
    z = warm_unknowns(robot, solution)
    if solution.model_at is not None and solution.model_at.z.shape == z.shape:
        z = solution.model_at.z.copy()  # the z the model was integrated at
    motion = solution.motion
    taut = np.flatnonzero(~solution.slack)
    free_z = np.concatenate([np.arange(3), 3 + taut])
    n_eq = free_z.size
    balance, _, _, states = base.at(z, lengths, motion, row)
    e_z, p_z = np.empty((n_eq, n_eq)), np.empty((3, n_eq))
    units = np.where(free_z < 3, 1.0 / robot.length, base.t_ref)  # z's scales (u(0) L, t)
    for k, index in enumerate(free_z):
        step = STATE_STEP * units[k]
        sides = []
        for sign in (1.0, -1.0):
            trial = z.copy()
            trial[index] += sign * step
            b, gap, point, _ = base.at(trial, lengths, motion, row)
            sides.append((np.concatenate([b, gap[taut]]), point))
        e_z[:, k] = (sides[0][0] - sides[1][0]) / (2.0 * step)
        p_z[:, k] = (sides[0][1] - sides[1][1]) / (2.0 * step)
    m = len(variants)
    e_p, p_p = np.zeros((n_eq, m)), np.zeros((3, m))
    stretched = None  # (consumed, point) of the base's cables at z, as on() has them
    for j, (models, (_, weights, step)) in enumerate(zip(variants, stencils)):
        for model, weight in zip(models, weights):
            if model.free_only:  # on() with the base's stretch: one path_stretch a row
                if stretched is None:
                    stretched = (base.consumed(states, z, motion), base._point(states))
                gap = model.free(lengths, row) - stretched[0]
                e_p[:, j] += weight / step * np.concatenate([balance, gap[taut]])
                p_p[:, j] += weight / step * stretched[1]
                continue
            own = motion if model.motions is None else model.motions[row]
            b, gap, point, _ = (model.on(states, balance, z, lengths, own, row)
                                if model.same_rod else model.at(z, lengths, own, row))
            e_p[:, j] += weight / step * np.concatenate([b, gap[taut]])
            p_p[:, j] += weight / step * point
    # solved in scaled z, as Newton's steps are: the columns O(1)
    dz = -np.linalg.lstsq(e_z * units, e_p, rcond=1e-12)[0] * units[:, None]
    return p_p + p_z @ dz


def point_sensitivities(model, x, solutions, workers=1):
    """Return d marker point / d variable (rows, 3, m), base frame, of ``model`` at ``x``.

    :param model: a :class:`run_model.RunModel`
    :param solutions: its replay's row solutions at ``x`` (:attr:`RunModel.solutions`); rows
        without one (the solve raised) get zeros
    :param workers: forked processes sharing the rows
    """
    global _JOB
    low, high = model.bounds()
    steps = model.vector.steps() * PARAMETER_STEP_FRACTION
    robot = model.robot_for(x)
    base = RowModel(robot).free_rows(model.run.lengths)
    stencils, variants = [], []
    for j in range(model.size):
        offsets, weights = stencil(x[j], steps[j], low[j], high[j])
        stencils.append((offsets, weights, steps[j]))
        models = []
        for offset in offsets:
            trial = np.array(x, dtype=float)
            trial[j] += offset
            models.append(RowModel(model.robot_for(trial), robot).free_rows(
                model.run.lengths))
        variants.append(models)
    solved = np.array([solution is not None for solution in solutions])
    for models in variants:
        for variant in models:
            if not np.array_equal(variant.robot.tendons.stick_length,
                                  robot.tendons.stick_length):
                variant.motions = friction_states(variant.robot, model.run.lengths, solved)
    rows = list(np.flatnonzero(solved))
    _JOB = (base, variants, stencils, model.run.lengths, solutions)
    try:
        with fork_pool(workers) as pool:
            parts = list(pool.map(_rows, np.array_split(rows, max(1, min(workers, len(rows))))))
    finally:
        _JOB = None
    out = np.zeros((len(solutions), 3, model.size))
    if rows:
        out[rows] = np.concatenate(parts)
    return out


def _rows(indices):
    base, variants, stencils, lengths, solutions = _JOB
    return np.array([row_sensitivities(base, variants, stencils, lengths[i], solutions[i], i)
                     for i in indices]).reshape(len(indices), 3, len(variants))
