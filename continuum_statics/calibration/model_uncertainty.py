"""The model's own error as unmodelled loads, measured on a recorded run (no ROS).

A calibrated model still misses the tracker by what it does not model (friction history,
drift, the tracker's own noise). :mod:`continuum_statics.core.estimation.state_estimation` carries
that error as unmodelled loads d with prior N(0, P0), P0 = diag(sigma_group^2). This module
measures sigma_group and the correlation time from the run's residuals:

each row's residual e_i = measured - model marker point is, to first order, H_i d + noise,
with H_i the marker rows of the load columns at that row. The residuals are cross-validated
(:func:`fold_robots`): each row's comes from a robot fitted without its motion pattern, so
their scale is a held-out run's, not the smaller one of the rows the robot was fitted to. Each
fold is replayed through the same filter as the estimator's, with the tracker seen on some rows
and occluded on others (:data:`OCCLUSION_PATTERNS`: what a lab's tracker does), and sigma per
group and tau maximise the likelihood of what the filter predicts on the occluded rows (error
and covariance both: too small a covariance is penalised as much as too large). The fit starts
from the file's prior and from the offset alone (the last-residual baseline is that model with
every other group at zero) and keeps the likelier. sigma_y, the tracker's noise, is given (the
robot file's tip sensor, else :data:`TRACKER_NOISE`). Only the calibration run is used:
held-out runs judge the result.

A second stage adds the drift (a smooth offset, :mod:`.state_estimation`'s Matern 3/2 process)
to the kept model and fits its sigma and time with the offset's sigma and tau (the two compete
for the same error), the other sigmas held: a joint fit of all seven costs several times as
long. The drift is kept when the likelihood ratio says its two parameters are needed
(:data:`DRIFT_GATE`). A third stage fits the point noise (the model's white error at the tip)
on the run with the tracker seen on every row, the rest held (:func:`_point_noise`).
"""
import math

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from continuum_statics.calibration.error_budget import folds, pattern_groups
from continuum_statics.calibration.filter_replay import replay_rows
from continuum_statics.calibration.fit import fit as fit_run
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.core.description.sensors import (
    DEFAULT_SENSOR_NOISE,
    ModelUncertainty,
    Sensor,
    default_model_uncertainty,
)
from continuum_statics.core.estimation.gates import chi2_quantile
from continuum_statics.core.estimation.state_estimation import (
    GROUPS,
    group_sigma,
    sensor_rows,
    white_sigma,
)

#: Occlusion patterns of the fit: (rows seen, rows occluded), repeated over the run.
OCCLUSION_PATTERNS = ((1, 1), (5, 5), (20, 40))
#: The tracker's noise (m) assumed when the robot file names no tip sensor: a sensor's default.
TRACKER_NOISE = DEFAULT_SENSOR_NOISE['position']
#: Folds of the cross-validation (whole motion patterns each, as :mod:`.selection`'s).
FOLDS = 3
#: Least-squares evaluations of a fold's fit (it starts at the whole run's fit).
FOLD_EVALUATIONS = 8
#: sigma (relative to the file's prior) of the groups other than the offset at the offset-only
#: start: the last-residual baseline, up to the optimiser's log scale.
SWITCHED_OFF = 1e-4
#: Where the drift's fit starts: sigma (m) as a fraction of the rod's length, and its time (s).
DRIFT_START = (0.01, 5.0)
#: The drift is kept when twice the log-likelihood it adds exceeds this: chi-square, 2 degrees
#: of freedom (its sigma and time), 95 % (Wilks' likelihood-ratio test).
DRIFT_GATE = chi2_quantile(0.95, 2)
#: The point noise (the model's white error at the tip) is searched over this range, as a
#: multiple of the tracker's noise ...
POINT_NOISE_RANGE = (0.01, 10.0)
#: ... and kept when twice the log-likelihood it adds exceeds this: chi-square, 1 degree of
#: freedom, 95 %.
POINT_NOISE_GATE = chi2_quantile(0.95, 1)


def fold_robots(robot, run, fit_names, model, x, workers=None, shear_fixed=False,
                count=FOLDS):
    """Return [(a robot fitted without a fold's motion patterns, the fold's rows as a run)].

    ``model`` and ``x``: the whole run's fit (:class:`RunModel` and its search vector), each
    fold's fit starts there. The robots are in the tracker frame (their registration is the
    fold's own).
    """
    fold = folds(pattern_groups(run.labels), count)
    pairs = []
    for f in range(count):
        test = fold == f
        if not np.any(test) or np.all(test):
            continue
        part = RunModel(robot, fit_names, run.subset(~test), shear_fixed)
        result = fit_run(part, log=lambda line: None, workers=workers,
                         max_evaluations=FOLD_EVALUATIONS, x0=part.start_from(model, x))
        pairs.append((part.robot_for(result.x, frame='tracker'), run.subset(test)))
    return pairs


def run_sensors(robot, run, tracker_noise=None):
    """Return the [Sensor] a run measures: the tip tracker, then each other sensor it holds.

    The tip tracker (``run.tips``, at the robot's ``tip_marker``) has ``tracker_noise`` (None:
    the robot file's tip sensor's, else :data:`TRACKER_NOISE`); a sensor of the robot file whose
    points the run holds (``run.points``, the same frame as the tips) has its own noise. A
    pose sensor's orientation is not used here.
    """
    tips = [sensor for sensor in robot.sensors if sensor.at_tip]
    if tracker_noise is None:
        tracker_noise = tips[0].position_sigma if tips else TRACKER_NOISE
    tip = Sensor('tip', robot.length, robot.tip_marker, position_sigma=float(tracker_noise),
                 at_tip=True)
    return [tip] + [sensor for sensor in robot.sensors
                    if not sensor.at_tip and sensor.name in run.points]


def residual_rows(robot, run, sensors):
    """Replay a run through the estimator; return (residuals (n, m) m, point columns (n, m, k)).

    ``sensors``: the [Sensor] of :func:`run_sensors`, m = 3 per sensor, in that order (a row a
    sensor lacks: NaN; the first is the tip tracker, ``run.tips``). Each row is estimated to
    the end, warm-started from the previous (friction follows each cable's motion); its load
    columns are the estimator's (refreshed as the tip moves), at each sensor's point
    (:func:`sensor_rows`).
    """
    robot = robot.without_load_model()  # the model's own error: a load held is not one
    residuals = np.hstack([run.tips] + [run.points[sensor.name] for sensor in sensors[1:]])
    columns = None
    previous = None
    for i, lengths in enumerate(run.lengths):
        estimate = robot.estimate_shape(lengths, warm_start=previous, exact=True,
                                        stamp=float(run.times[i]))
        previous = estimate
        if columns is None:
            columns = np.zeros(residuals.shape + (estimate.sensitivity.positions.shape[2],))
        for j, sensor in enumerate(sensors):
            point, jac, _ = sensor_rows(estimate.shape, estimate.sensitivity, sensor)
            residuals[i, 3 * j:3 * j + 3] -= point
            columns[i, 3 * j:3 * j + 3] = jac[:3]
    return residuals, columns


def fit(robot, sequences, sensors, patterns=None):
    """Return ({group: sigma}, tau) maximising the predictive likelihood of occluded rows.

    ``sequences``: [(times (n,) s, residuals (n, m) m, point columns (n, m, k))] of
    :func:`residual_rows`, each replayed on its own; ``sensors``: the [Sensor] of their entries,
    three each (the tip tracker first). The replay of :func:`replay_filter` under each
    occlusion pattern of ``patterns`` (default :data:`OCCLUSION_PATTERNS`; every sensor seen or
    occluded together): the sum over the rows the sensors do not see of
    log N(e_i; H_i mean_i, H_i P_i H_i^T + R), R the sensors' noise, maximised (Nelder-Mead)
    over log sigma per group and log tau, and over the offset's sigma and tau alone (the other
    groups at :data:`SWITCHED_OFF` of their prior: the last-residual baseline's model); the
    likelier is kept. The rows it sees update the unmodelled loads, as on the robot.
    """
    groups = _group_index(robot)
    if robot.model_uncertainty.drift > 0.0:
        raise ValueError('fit starts from a model uncertainty without a drift: it adds its own')
    prior = np.array([math.log(getattr(robot.model_uncertainty, name)) for name, _ in groups]
                     + [math.log(robot.model_uncertainty.correlation_time)])
    offset = np.array([name == 'base_position' for name, _ in groups] + [True])

    def offset_only(y):  # log sigma of the offset and log tau; the other groups switched off
        x = prior + math.log(SWITCHED_OFF)
        x[offset] = y
        return x

    occluded = [(times, residuals, columns, [seen_mask(len(times), seen, hidden)
                                             for seen, hidden in patterns or OCCLUSION_PATTERNS])
                for times, residuals, columns in sequences]

    spread = np.repeat([sensor.position_sigma for sensor in sensors], 3)
    reach = np.repeat([white_sigma(1.0, sensor.s, robot.length) for sensor in sensors], 3)

    def negative_log_likelihood(x, drift=None, replays=occluded, point_noise=0.0):
        sigma = _sigma_vector(groups, np.exp(x[:-1]))
        noise = np.hypot(spread, point_noise * reach)  # the white error grows as s / L
        total = 0.0
        for times, residuals, columns, masks in replays:
            for seen in masks:
                innovations, spreads = replay_filter(times, residuals, columns, sigma,
                                                     math.exp(x[-1]), noise, seen, drift)
                # the rows scored: the occluded ones (all of them when every row is seen)
                scored = (~seen if not np.all(seen) else seen) & np.any(np.isfinite(residuals),
                                                                        axis=1)
                solved = np.linalg.solve(spreads[scored], innovations[scored][:, :, None])
                total += 0.5 * float(np.sum(np.linalg.slogdet(spreads[scored])[1])
                                     + np.sum(innovations[scored] * solved[:, :, 0]))
        return total

    options = {'xatol': 1e-3, 'fatol': 1e-2, 'maxiter': 120 * len(prior)}
    every = minimize(negative_log_likelihood, prior, method='Nelder-Mead', options=options)
    alone = minimize(lambda y: negative_log_likelihood(offset_only(y)), prior[offset],
                     method='Nelder-Mead', options=options)
    best = every.x if every.fun <= alone.fun else offset_only(alone.x)
    found = min(every.fun, alone.fun)

    def with_drift(y):  # the offset's sigma and tau refitted beside the drift: they compete
        x = best.copy()
        x[offset] = y[:2]
        return x, np.exp(y[2:])

    kept = False
    if np.any(offset[:-1]):  # the drift is fitted beside an offset
        drift = minimize(lambda y: negative_log_likelihood(*with_drift(y)),
                         np.concatenate([best[offset], np.log([DRIFT_START[0] * robot.length,
                                                               DRIFT_START[1]])]),
                         method='Nelder-Mead', options=options)
        kept = 2.0 * (found - drift.fun) > DRIFT_GATE
        if kept:
            best, (sigma, time) = with_drift(drift.x)
    sigmas = {name: math.exp(value) for (name, _), value in zip(groups, best[:-1])}
    if kept:
        sigmas.update(drift=float(sigma), drift_time=float(time))
    sigmas['point_noise'] = _point_noise(
        negative_log_likelihood, best, (sigma, time) if kept else None,
        [(t, r, c, [np.ones(len(t), bool)]) for t, r, c in sequences], sensors[0].position_sigma)
    return sigmas, math.exp(best[-1])


def _point_noise(negative_log_likelihood, x, drift, every_row, tracker_noise):
    """Return the point noise (m) the rows a tracker sees on every row need, 0 if none.

    The model's error that no load explains and that changes from one configuration to the
    next is white: a tracker seen on every row shows it (each reading predicted from the ones
    before: the filter's own likelihood), occluded rows hardly (the state's growing variance
    hides it). Fitted on the run with every row seen, the rest held; kept when the likelihood
    ratio against none says it is needed (:data:`POINT_NOISE_GATE`). On simulated truth with
    physics the file lacks, the tip's 95 % ellipsoid held 74.7 % of a tracked run without it
    and 89.3 % with it (``benchmarks/bench_mismatch.py``). Fitted beside the loads instead
    (one search), it set their sigmas free (a tip force of 1.7 kN there): not kept.
    """
    def score(log_sigma):
        return negative_log_likelihood(x, drift, every_row, math.exp(log_sigma))

    found = minimize_scalar(score, bounds=tuple(np.log(POINT_NOISE_RANGE) + math.log(
        tracker_noise)), method='bounded', options={'xatol': 1e-2})
    without = negative_log_likelihood(x, drift, every_row, 0.0)
    return math.exp(found.x) if 2.0 * (without - found.fun) > POINT_NOISE_GATE else 0.0


def seen_mask(rows, seen, hidden):
    """Return (rows,) bool: blocks of ``seen`` rows the tracker sees, then ``hidden`` not."""
    return (np.arange(rows) % (seen + hidden)) < seen


def replay_filter(times, residuals, columns, sigma, tau, noise, seen, drift=None):
    """Replay the unmodelled loads' filter in the sensors' coordinates (no solves).

    ``residuals`` (n, m): measured minus the model's points (NaN: not measured); ``columns``
    (n, m, k): the points' rows of the load columns; ``sigma`` (k,) the prior; ``noise`` (m,)
    or one value, m; ``seen`` (n,) rows the sensors are used on; ``drift``: (sigma m, time s)
    of the drift, or None. Returns each row's innovation (n, m) before its update and its
    covariance (n, m, m) (the prediction error of an occluded row and what the estimate says
    of it). The arithmetic of
    :func:`state_estimation.decayed` / :func:`state_estimation.fused`, the estimator's, compiled
    (:mod:`.filter_replay`).
    """
    sigma, columns, drift_time = with_drift(sigma, columns, drift)
    return replay_rows(np.asarray(times, dtype=float), np.ascontiguousarray(residuals, float),
                       np.ascontiguousarray(columns, float), np.ascontiguousarray(sigma, float),
                       float(tau), float(drift_time or 0.0),
                       np.broadcast_to(np.asarray(noise, dtype=float), residuals.shape[1:]).copy(),
                       np.asarray(seen, dtype=bool))


def with_drift(sigma, columns, drift):
    """Return (sigma, columns, drift time s or None) with the drift's six entries appended.

    ``drift``: (sigma m, time s), or None (``sigma`` and ``columns`` as they are).
    """
    if drift is None:
        return sigma, columns, None
    rate = group_sigma(ModelUncertainty(drift=drift[0], drift_time=drift[1]), 'drift_rate')
    sigma = np.concatenate([sigma, [drift[0]] * 3, [rate] * 3])
    # the drift moves every point as an offset; its rate moves nothing now
    rows = columns.shape[1]
    columns = np.concatenate([columns, np.broadcast_to(np.tile(np.eye(3), (rows // 3, 1)),
                                                       (len(columns), rows, 3)),
                              np.zeros((len(columns), rows, 3))], axis=2)
    return sigma, columns, drift[1]


def _sigma_vector(groups, sigmas):
    return np.concatenate([np.full(len(index), value) for (_, index), value in zip(groups,
                                                                                   sigmas)])


def _group_index(robot):
    """Return [(group, column indices)] of the robot's unmodelled loads with a prior."""
    groups, at = [], 0
    for name, size, _ in GROUPS[:4]:  # the drift is fitted on its own (:func:`fit`)
        size = len(robot.cable_names) if size is None else size
        if getattr(robot.model_uncertainty, name) > 0.0:
            groups.append((name, np.arange(at, at + size)))
            at += size
    return groups


def measure(robot, run, tracker_noise=None, folds=None):
    """Return (:class:`ModelUncertainty`, report dict) of a calibrated robot on a run.

    ``folds``: [(robot, rows)] of :func:`fold_robots`, each robot's residuals taken on rows it
    was not fitted to; without them the residuals are ``robot``'s on the whole ``run`` (rows
    it may have been fitted to: a smaller scale than a held-out run's).
    """
    sensors = run_sensors(robot, run, tracker_noise)
    prior = default_model_uncertainty(robot.c[0], robot.length)
    sequences = []
    for fold_robot, rows in folds or [(robot, run)]:
        # each fold's own tip marker and length (fit names): its residuals are its robot's
        residuals, columns = residual_rows(fold_robot.with_model_uncertainty(prior), rows,
                                           run_sensors(fold_robot, rows, tracker_noise))
        sequences.append((rows.times, residuals, columns))
    robot = robot.with_model_uncertainty(prior)
    sigmas, tau = fit(robot, sequences, sensors)
    uncertainty = ModelUncertainty(correlation_time=tau, **sigmas)
    rms = math.sqrt(np.nanmean(np.concatenate([np.sum(r[:, :3] ** 2, axis=1)
                                               for _, r, _ in sequences])))
    return uncertainty, {'tracker_noise': sensors[0].position_sigma,
                         'sensors': [sensor.name for sensor in sensors[1:]],
                         'correlation_time': tau, 'residual_rms': rms,
                         'cross_validated': folds is not None, **sigmas}
