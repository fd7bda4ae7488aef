"""The compiled filter replay of ``calibrate --model-uncertainty`` is the estimator's filter.

The reference is the estimator's own ``decayed`` and ``fused`` (what a node runs), called row by
row in Python as ``model_uncertainty.replay_filter`` did before it was compiled.
"""
import math

import numpy as np
import pytest

from continuum_statics.calibration.model_uncertainty import replay_filter, seen_mask, with_drift
from continuum_statics.core.estimation.state_estimation import decayed, fused


def reference(times, residuals, columns, sigma, tau, noise, seen, drift=None):
    """Replay with the estimator's functions, one row at a time (slow)."""
    sigma, columns, drift_time = with_drift(sigma, columns, drift)
    prior = np.diag(sigma ** 2)
    mean, covariance = np.zeros(len(sigma)), prior
    m = residuals.shape[1]
    noise = np.broadcast_to(noise, (m,))
    innovations = np.zeros_like(residuals)
    spreads = np.tile(np.eye(m), (len(residuals), 1, 1))
    for i, (residual, jac) in enumerate(zip(residuals, columns)):
        if i:
            mean, covariance = decayed(mean, covariance, prior, max(times[i] - times[i - 1], 0.0),
                                       tau, drift_time)
        given = np.isfinite(residual)
        if not np.any(given):
            continue
        jac, variance = jac[given], np.diag(noise[given] ** 2)
        innovation = residual[given] - jac @ mean
        innovations[i, given] = innovation
        spreads[i][np.ix_(given, given)] = jac @ covariance @ jac.T + variance
        if seen[i]:
            mean, covariance = fused(mean, covariance, jac, innovation, variance)
    return innovations, spreads


@pytest.mark.parametrize('drift', [None, (2e-3, 3.0)])
@pytest.mark.parametrize('pattern', [(1, 1), (5, 5), (20, 40)])
def test_the_compiled_replay_equals_the_estimators_filter(drift, pattern):
    rng = np.random.default_rng(3)
    rows, k = 150, 13
    times = np.cumsum(rng.uniform(0.0, 0.8, rows))
    times[7] = times[6]  # two rows at one stamp, and one out of order: no step back in time
    times[20] = times[19] - 0.1
    residuals = rng.normal(0.0, 3e-3, (rows, 3))
    residuals[11] = np.nan  # a row the tracker lost: its time still counts
    columns = rng.normal(0.0, 1.0, (rows, 3, k)) * np.geomspace(1e-3, 1.0, k)
    sigma = np.geomspace(1e-3, 1.0, k)[::-1] * 1e-3
    seen = seen_mask(rows, *pattern)
    args = (times, residuals, columns, sigma, 8.0, 5e-4, seen)
    innovations, spreads = replay_filter(*args, drift=drift)
    expected_innovations, expected_spreads = reference(*args, drift=drift)
    # to rounding: the estimator rounds elapsed time to 1 ns to cache its drift's transitions
    # (seen: 2e-12 m on residuals of 3 mm)
    np.testing.assert_allclose(innovations, expected_innovations, rtol=0.0, atol=1e-10)
    np.testing.assert_allclose(spreads, expected_spreads, rtol=1e-7, atol=0.0)
    assert np.all(np.isfinite(spreads)) and spreads[11, 0, 0] == 1.0
    # the state did change what was predicted: the occluded rows are not the raw residuals
    hidden = ~seen & np.all(np.isfinite(residuals), axis=1)
    assert not np.allclose(innovations[hidden], residuals[hidden])
    assert math.isfinite(float(np.sum(np.linalg.slogdet(spreads[hidden])[1])))


@pytest.mark.parametrize('drift', [None, (2e-3, 3.0)])
def test_two_sensors_with_their_own_noise_and_rows_one_of_them_lacks(drift):
    """A tip tracker and a mid-body sensor (6 entries a row): the coil reads every third row."""
    rng = np.random.default_rng(5)
    rows, k = 120, 13
    times = np.cumsum(rng.uniform(0.0, 0.8, rows))
    residuals = rng.normal(0.0, 3e-3, (rows, 6))
    residuals[np.arange(rows) % 3 != 0, 3:] = np.nan  # the coil at a third of the rate
    residuals[12, :3] = np.nan  # a row only the coil saw
    residuals[13] = np.nan      # and one neither did
    columns = rng.normal(0.0, 1.0, (rows, 6, k)) * np.geomspace(1e-3, 1.0, k)
    sigma = np.geomspace(1e-3, 1.0, k)[::-1] * 1e-3
    noise = np.repeat([5e-4, 7e-4], 3)
    seen = seen_mask(rows, 5, 5)
    args = (times, residuals, columns, sigma, 8.0, noise, seen)
    innovations, spreads = replay_filter(*args, drift=drift)
    expected_innovations, expected_spreads = reference(*args, drift=drift)
    np.testing.assert_allclose(innovations, expected_innovations, rtol=0.0, atol=1e-10)
    np.testing.assert_allclose(spreads, expected_spreads, rtol=1e-7, atol=1e-20)
    # an entry a row lacks takes no part in the likelihood: innovation 0, spread 1 and 0
    np.testing.assert_array_equal(spreads[1, 3:, 3:], np.eye(3))
    np.testing.assert_array_equal(spreads[1, :3, 3:], 0.0)
    assert np.all(innovations[1, 3:] == 0.0) and np.all(innovations[12, 3:] != 0.0)
    # the coil's rows moved the state: without them the tracker's predictions differ
    alone = replay_filter(times, residuals[:, :3], columns[:, :3], sigma, 8.0, 5e-4, seen,
                          drift=drift)[0]
    hidden = ~seen & np.isfinite(residuals[:, 0])
    assert np.max(np.abs(alone[hidden] - innovations[hidden, :3])) > 1e-8  # rounding: 1e-16
