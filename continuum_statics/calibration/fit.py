"""The least-squares fit of a run model: a pattern-rotation scan, then trust-region steps.

``scipy.optimize.least_squares`` (trust region, bounds) minimises the model's residuals; its
Jacobian comes from the implicit-function theorem on every row's equilibrium
(:mod:`.sensitivities`), or from one replay per variable run on every core (:mod:`.pool`).
"""
import math
import time
from typing import NamedTuple

import numpy as np
from scipy.optimize import least_squares

from continuum_statics.calibration.phases import Phases
from continuum_statics.calibration.pool import default_workers, fork_pool
from continuum_statics.calibration.replay import rms
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.calibration.sensitivities import point_sensitivities

#: Angles per section and rows of the pattern-rotation scan that starts a fit.
SCAN_STEPS = 24
SCAN_ROWS = 250
#: Stick lengths (m) tried before a fit of ``stick_length`` (:func:`scan_stick_length`).
STICK_SCAN = (5e-4, 1e-3, 2e-3, 4e-3, 8e-3, 1.6e-2)
#: Capstan coefficients tried with them when friction is fitted too.
FRICTION_SCAN = (0.05, 0.1, 0.2)
#: How a fit's Jacobian is made (:func:`fit`).
JACOBIANS = ('implicit', 'differences')

_WORKER_MODEL = None  # the model a forked worker evaluates


class FitResult(NamedTuple):
    """What a fit reached: search vector, last residuals and Jacobian, and how it ended."""

    x: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray   # (residuals, variables), the last Jacobian
    evaluations: int
    success: bool
    message: str


def evaluate_all(model, xs, workers, starts=None):
    """Residuals of ``model`` at every search vector of ``xs``, on ``workers`` forked processes.

    The pool is forked now, so the workers share the model, its registration and the per-row
    warm starts ``starts`` (:func:`replay.replay_solutions`) without pickling them.
    """
    global _WORKER_MODEL
    _WORKER_MODEL = model
    model.starts = starts
    try:
        with fork_pool(workers) as pool:
            return list(pool.map(_worker_residuals, xs))
    finally:  # the starts hold a replay's solutions (and their robots): not kept past the call
        _WORKER_MODEL = None
        model.starts = None


def _worker_residuals(x):
    return _WORKER_MODEL.residuals(x, starts=_WORKER_MODEL.starts)


def scan_rotations(model, x0, log=print, steps=SCAN_STEPS, rows=SCAN_ROWS, workers=1):
    """Start each section's pattern rotation at the best of ``steps`` angles around the circle.

    A lab knows its holes' radius and spacing but not how each pattern sits: a local fit from a
    wrong quarter turn ends in a wrong basin. Sections are scanned base to tip on every
    ``len(run) // rows``-th row (the registration, solved in closed form, follows each guess).
    """
    block = next((b for b in model.blocks if b.name == 'section_rotation'), None)
    if block is None:
        return x0
    stride = max(1, len(model.run.tips) // rows)
    coarse = RunModel(model.robot, model.fit,
                      model.run.subset(np.arange(0, len(model.run.tips), stride)),
                      model.vector.shear_fixed)
    x = np.array(x0, dtype=float)
    for index in range(block.index.start, block.index.stop):
        trials = []
        for angle in x[index] + np.linspace(-math.pi, math.pi, steps, endpoint=False):
            trials.append(x.copy())
            trials[-1][index] = math.remainder(angle, 2.0 * math.pi)
        costs = [float(np.sum(r ** 2)) for r in evaluate_all(coarse, trials, workers)]
        x[index] = trials[int(np.argmin(costs))][index]
    log('  pattern rotations scanned (%d angles each, %d rows): start %s rad'
        % (steps, len(coarse.run.tips), np.round(x[block.index], 3).tolist()))
    return x


def scan_stick_length(model, x0, log=print, workers=1):
    """Start ``stick_length`` (and ``friction`` when fitted) at the best of a grid.

    A stick length under the motor travel between rows turns each friction state within a
    row, where the fit finds no gradient; and without friction no stick length changes
    anything, so a fitted friction is scanned with it (:data:`STICK_SCAN`,
    :data:`FRICTION_SCAN`, and the current values). Whole replays: a subset of rows would change
    the travel between them.
    """
    stick = next((b for b in model.blocks if b.name == 'stick_length'), None)
    if stick is None:
        return x0
    friction = next((b for b in model.blocks if b.name == 'friction'), None)
    frictions = ((x0[friction.index.start],) + FRICTION_SCAN) if friction else (None,)
    trials = []
    for mu in frictions:
        for value in (x0[stick.index.start],) + STICK_SCAN:
            trials.append(np.array(x0, dtype=float))
            trials[-1][stick.index] = min(value, stick.high[0])
            if friction is not None:
                trials[-1][friction.index] = mu
    costs = [float(np.sum(r ** 2)) for r in evaluate_all(model, trials, workers)]
    x = trials[int(np.argmin(costs))]
    log('  stick length scanned (%d trials): start %.4g m%s' % (
        len(trials), x[stick.index][0],
        ', friction %.3g' % x[friction.index][0] if friction else ''))
    return x


def fit(model, log=print, workers=None, max_evaluations=40, x0=None, jacobian='implicit',
        phases=None):
    """Fit the model's search vector; returns a :class:`FitResult`.

    ``x0``: the start (e.g. an earlier fit's values, :meth:`RunModel.start_from`); by default
    the robot file's values with the pattern rotations scanned. ``jacobian``: ``'implicit'``
    (:mod:`.sensitivities`, every variable from one pass over the rows) or ``'differences'``
    (one re-solved replay per variable, each row started from the current replay's).
    ``phases``: a :class:`phases.Phases` that gets the seconds of the scans (``scan``) and of
    the least-squares steps (``fit``).
    """
    if jacobian not in JACOBIANS:
        raise ValueError('jacobian %r: one of %s' % (jacobian, ', '.join(JACOBIANS)))
    if jacobian == 'differences' and 'stick_length' in model.fit:
        # its replays start each row from the base's, friction states held: no memory
        raise ValueError("stick_length needs jacobian='implicit' (the friction state's chain)")
    workers = workers or default_workers()
    phases = phases or Phases()
    low, high = model.bounds()
    with phases('scan'):
        if x0 is None:
            x0 = scan_rotations(model, np.clip(model.start(), low, high), log, workers=workers)
        x0 = scan_stick_length(model, np.clip(x0, low, high), log, workers)
    with phases('fit'):
        return _least_squares(model, log, workers, max_evaluations, x0, jacobian)


def _least_squares(model, log, workers, max_evaluations, x0, jacobian):
    """:func:`fit` from ``x0``: the trust-region steps."""
    low, high = model.bounds()
    model.residuals(x0, update=True)
    began = time.monotonic()
    count = [0]
    cache = {}

    def fun(x):
        res = model.residuals(x, update=True)
        cache.update(x=np.array(x), res=res, starts=model.solutions, points=model.replayed)
        count[0] += 1
        n = len(model.run.tips)
        log('  evaluation %d: RMS %.3f mm (%.0f s)' % (
            count[0], rms(res[:3 * n].reshape(-1, 3)) * 1e3, time.monotonic() - began))
        return res

    def jac(x):
        if not np.array_equal(cache.get('x'), x):
            cache.update(x=np.array(x), res=model.residuals(x), starts=model.solutions,
                         points=model.replayed)
        if jacobian == 'implicit':
            return model.jacobian(x, cache['points'], point_sensitivities(
                model, x, cache['starts'], workers))
        base = cache['res']
        steps = model.vector.steps()
        steps = np.where(x + steps > high, -steps, steps)
        trials = [x + steps[i] * np.eye(len(x))[i] for i in range(len(x))]
        # each column's rows start from the base's solutions of the same rows: a chord step
        # or two each, friction directions held
        columns = evaluate_all(model, trials, workers, cache['starts'])
        return np.stack([(c - base) / h for c, h in zip(columns, steps)], axis=1)

    if model.size == 0:  # only closed-form names (registration): nothing to search
        res = fun(x0)
        return FitResult(x0, res, np.zeros((res.size, 0)), 1, True, 'closed form only')
    # ftol 1e-3: a step that gains less than 0.1 % of the cost ends the fit (its last
    # evaluations gained micrometres at a minute each)
    result = least_squares(fun, x0, jac=jac, bounds=(low, high), x_scale='jac',
                           xtol=1e-8, ftol=1e-3, gtol=1e-8, max_nfev=max_evaluations)
    res = model.residuals(result.x, update=True)
    return FitResult(result.x, res, np.asarray(result.jac), int(result.nfev),
                     bool(result.success), str(result.message))


def standard_errors(jacobian, residuals, derivatives=None):
    """1-sigma of each variable from the Jacobian and the residual RMS (Gauss-Newton covariance).

    :param derivatives: d value / d variable per variable, to get the 1-sigma in value units
    :returns: (m,) 1-sigma, NaN where the Jacobian is singular
    """
    jacobian = np.asarray(jacobian, dtype=float)
    if jacobian.shape[1] == 0:
        return np.zeros(0)
    dof = max(jacobian.shape[0] - jacobian.shape[1], 1)
    variance = float(np.sum(np.asarray(residuals) ** 2)) / dof
    try:
        covariance = np.linalg.inv(jacobian.T @ jacobian) * variance
    except np.linalg.LinAlgError:
        return np.full(jacobian.shape[1], np.nan)
    sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    return sigma if derivatives is None else sigma * np.abs(derivatives)
