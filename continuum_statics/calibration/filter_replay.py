"""The unmodelled loads' filter replayed over a run's rows, compiled (no ROS).

:func:`.model_uncertainty.fit` replays the estimator's filter a thousand times and more (a
Nelder-Mead search over the prior's sigmas and times, three occlusion patterns per step). Each
row is :func:`~continuum_statics.core.estimation.state_estimation.decayed` then
:func:`~continuum_statics.core.estimation.state_estimation.fused` on a state of 13-25 entries,
with the readings of every sensor the run holds (3 entries a point):
in Python, numpy calls on small matrices cost ~125 us a row, 50 ms a 400-row replay and 150 s a
fit; compiled, the same arithmetic (``test/calibration/test_filter_replay.py`` holds it equal
to those two functions) takes microseconds a row. Not part of the nodes' warm-up: ``calibrate``
compiles it on first use (seconds, once per kernel cache).
"""
import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def replay_rows(times, residuals, columns, sigma, tau, drift_time, noise, seen):
    """Return (innovations (n, m), spreads (n, m, m)) of the filter replayed over the rows.

    :param times: (n,) s
    :param residuals: (n, m) m, measured minus the model's points (3 entries a sensor's point,
        the tip tracker's first); a non-finite entry: that sensor gave nothing on that row (a
        row with none: unseen, not scored; its time still counts)
    :param columns: (n, m, k) the points' rows of the state's columns
    :param sigma: (k,) the state's prior standard deviations, N(0, diag(sigma^2)) at the start
    :param tau: s, the Ornstein-Uhlenbeck correlation time of every entry but the drift's
    :param drift_time: s, the Matern 3/2 length scale of the last six entries (the drift and
        its rate, x y z each); 0: no drift
    :param noise: (m,) m, each entry's standard deviation (its sensor's, independent)
    :param seen: (n,) bool, the rows whose residuals update the state
    :returns: an entry a row lacks has innovation 0 and spread 1 on the diagonal, 0 off it
        (no part in a Gaussian likelihood of the rows)
    """
    n, m, k = residuals.shape[0], residuals.shape[1], sigma.shape[0]
    prior = np.diag(sigma * sigma)
    mean = np.zeros(k)
    covariance = prior.copy()
    innovations = np.zeros((n, m))
    spreads = np.zeros((n, m, m))
    transition = np.eye(k)
    identity = np.eye(k)
    for i in range(n):
        for a in range(m):
            spreads[i, a, a] = 1.0
        if i > 0:
            _transition(transition, max(times[i] - times[i - 1], 0.0), tau, drift_time)
            mean = transition @ mean
            covariance = transition @ (covariance - prior) @ transition.T + prior
        given = np.nonzero(np.isfinite(residuals[i]))[0]
        if given.size == 0:
            continue
        jac = np.ascontiguousarray(columns[i][given])
        variance = noise[given] * noise[given]
        innovation = residuals[i][given] - jac @ mean
        spread_columns = covariance @ jac.T  # P H^T (k, g)
        spread = jac @ spread_columns
        for a in range(given.size):
            spread[a, a] += variance[a]
            innovations[i, given[a]] = innovation[a]
            for b in range(given.size):
                spreads[i, given[a], given[b]] = spread[a, b]
        if seen[i]:
            # state_estimation.fused: K = P H^T S^-1, Joseph form, symmetrised
            gain = np.linalg.solve(spread, np.ascontiguousarray(spread_columns.T)).T.copy()
            keep = identity - gain @ jac
            covariance = keep @ covariance @ keep.T + (gain * variance) @ gain.T
            covariance = 0.5 * (covariance + covariance.T)
            mean = mean + gain @ innovation
    return innovations, spreads


@numba.njit(cache=True, nogil=True)
def _transition(out, elapsed, tau, drift_time):
    """Write into ``out`` the transition of ``elapsed`` s (state_estimation._transition)."""
    k = out.shape[0]
    out[:, :] = 0.0
    a = np.exp(-elapsed / tau)
    for i in range(k):
        out[i, i] = a
    if drift_time > 0.0:
        lam = np.sqrt(3.0) / drift_time
        e = np.exp(-lam * elapsed)
        for o in range(k - 6, k - 3):
            out[o, o] = e * (1.0 + lam * elapsed)
            out[o, o + 3] = e * elapsed
            out[o + 3, o] = -e * lam * lam * elapsed
            out[o + 3, o + 3] = e * (1.0 - lam * elapsed)
