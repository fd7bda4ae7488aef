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
    innovations = np.zeros_like(residuals)
    spreads = np.tile(np.eye(3), (len(residuals), 1, 1))
    for i, (residual, jac) in enumerate(zip(residuals, columns)):
        if i:
            mean, covariance = decayed(mean, covariance, prior, max(times[i] - times[i - 1], 0.0),
                                       tau, drift_time)
        if not np.all(np.isfinite(residual)):
            continue
        innovations[i] = residual - jac @ mean
        spreads[i] = jac @ covariance @ jac.T + noise ** 2 * np.eye(3)
        if seen[i]:
            mean, covariance = fused(mean, covariance, jac, innovations[i], noise ** 2 * np.eye(3))
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
