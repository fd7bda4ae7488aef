"""The model's own error as unmodelled loads, measured on a recorded run (no ROS).

A calibrated model still misses the tracker by what it does not model (friction history,
drift, the tracker's own noise). :mod:`continuum_statics.core.state_estimation` carries that
error as unmodelled loads d with prior N(0, P0), P0 = diag(sigma_group^2). This module measures
sigma_group and the correlation time from the run's residuals:

- sigma (type-II maximum likelihood): each row's residual e_i = measured - model marker point
  is, to first order, H_i d + noise with H_i the marker rows of the load columns at that row,
  so e_i ~ N(0, H_i P0 H_i^T + sigma_y^2 I). The log likelihood summed over rows is maximised
  over log sigma of each group (tip force, tip moment, cable length); sigma_y is the tracker's
  noise, given.
- correlation time tau: the residuals' autocorrelation rho(dt) over pairs of rows dt apart,
  fitted by exp(-dt / tau) (least squares on the pairs within the first lags).
"""
import math

import numpy as np
from scipy.optimize import minimize

from continuum_statics.core.sensors import ModelUncertainty, default_model_uncertainty
from continuum_statics.core.state_estimation import GROUPS

#: Row pairs up to this many rows apart measure the residuals' correlation in time.
CORRELATION_LAGS = 10
#: The tracker's noise (m) assumed when the robot file names no tip sensor.
TRACKER_NOISE = 5e-4
#: Where each group's sigma starts, as a fraction of the stand-in the robot gives.
_START = 1.0


def residual_rows(robot, run):
    """Replay a run through the estimator; return (residuals (n, 3) m, marker columns (n, 3, k)).

    Each row is estimated to the end, warm-started from the previous (friction follows each
    cable's motion); its load columns are the estimator's (refreshed as the tip moves).
    """
    residuals = np.full((len(run), 3), np.nan)
    columns = None
    previous = None
    for i, lengths in enumerate(run.lengths):
        estimate = robot.estimate_shape(lengths, warm_start=previous, exact=True,
                                        stamp=float(run.times[i]))
        previous = estimate
        shape = estimate.shape
        arm = shape.tip_rotation @ robot.tip_marker
        residuals[i] = run.tips[i] - (shape.tip_position + arm)
        sens = estimate.sensitivity
        if columns is None:
            columns = np.zeros((len(run), 3, sens.positions.shape[2]))
        columns[i] = sens.positions[-1] - _skew(arm) @ sens.angles[-1]
    return residuals, columns


def _skew(v):
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def fit_sigmas(robot, residuals, columns, tracker_noise):
    """Return {group: sigma} maximising the residuals' likelihood (see the module)."""
    groups = _group_index(robot)
    valid = np.all(np.isfinite(residuals), axis=1)
    residuals, columns = residuals[valid], columns[valid]
    start = np.array([math.log(_START * getattr(robot.model_uncertainty, name))
                      for name, _ in groups])

    def negative_log_likelihood(log_sigma):
        sigma = np.concatenate([np.full(len(index), math.exp(value))
                                for (_, index), value in zip(groups, log_sigma)])
        scaled = columns * sigma
        spread = scaled @ scaled.transpose(0, 2, 1) + tracker_noise ** 2 * np.eye(3)
        sign, logdet = np.linalg.slogdet(spread)
        solved = np.linalg.solve(spread, residuals[:, :, None])[:, :, 0]
        return 0.5 * float(np.sum(logdet) + np.sum(residuals * solved))

    result = minimize(negative_log_likelihood, start, method='Nelder-Mead',
                      options={'xatol': 1e-3, 'fatol': 1e-3, 'maxiter': 400})
    return {name: math.exp(value) for (name, _), value in zip(groups, result.x)}


def _group_index(robot):
    """Return [(group, column indices)] of the robot's unmodelled loads with a prior."""
    groups, at = [], 0
    for name, size, _ in GROUPS:
        size = len(robot.cable_names) if size is None else size
        if getattr(robot.model_uncertainty, name) > 0.0:
            groups.append((name, np.arange(at, at + size)))
            at += size
    return groups


def correlation_time(times, residuals, lags=CORRELATION_LAGS):
    """Return tau (s) of the residuals' autocorrelation exp(-dt / tau) over nearby rows."""
    valid = np.all(np.isfinite(residuals), axis=1)
    times, residuals = times[valid], residuals[valid] - residuals[valid].mean(axis=0)
    power = float(np.mean(np.sum(residuals ** 2, axis=1)))
    gaps, logs = [], []
    for lag in range(1, lags + 1):
        products = np.sum(residuals[lag:] * residuals[:-lag], axis=1) / power
        rho = float(np.mean(products))
        if rho <= 0.05:  # at the noise floor: further lags say nothing
            break
        gaps.append(float(np.mean(times[lag:] - times[:-lag])))
        logs.append(math.log(rho))
    if not gaps:
        return float(np.median(np.diff(times)))  # uncorrelated from one row to the next
    gaps, logs = np.array(gaps), np.array(logs)
    # log rho = -dt / tau through the origin (rho(0) = 1), least squares
    return float(-np.sum(gaps * gaps) / np.sum(gaps * logs))


def measure(robot, run, tracker_noise=None):
    """Return (:class:`ModelUncertainty`, report dict) of a calibrated robot on a run."""
    if robot.model_uncertainty is None:
        robot = robot.with_model_uncertainty(default_model_uncertainty(robot.c[0], robot.length))
    if tracker_noise is None:
        tips = [sensor for sensor in robot.sensors if sensor.at_tip]
        tracker_noise = tips[0].position_sigma if tips else TRACKER_NOISE
    residuals, columns = residual_rows(robot, run)
    sigmas = fit_sigmas(robot, residuals, columns, tracker_noise)
    tau = correlation_time(run.times, residuals)
    values = {name: 0.0 for name, _, _ in GROUPS}
    values.update(sigmas)
    uncertainty = ModelUncertainty(correlation_time=tau, **values)
    return uncertainty, {'tracker_noise': tracker_noise, 'correlation_time': tau, **sigmas}
