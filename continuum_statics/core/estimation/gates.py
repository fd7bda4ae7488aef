"""The chi-square gates every estimator and coverage check uses, written once.

A measurement (or a set of them) with residual r and stated covariance S is what the model
explains when r^T S^-1 r stays below the (1 - p) quantile of the chi-square distribution of its
degrees of freedom; p is the probability that a measurement whose noise is as stated is set
aside. A 95 % ellipsoid is the same quantile at 0.95.
"""
import functools

from scipy.stats import chi2 as chi2_distribution

#: The gate on one sensor reading's innovation (state estimation). Lower than the load
#: estimator's: a model whose held-out error exceeds its calibration run's must not lose its
#: tracker; 30 mm of bias against 4 mm of stated error is still chi2 ~ 60, beyond the 3-dof
#: gate of 30.7.
SENSOR_GATE_PROBABILITY = 1e-6
#: The gate on the tip-load estimator's whole measurement set (tensions, lengths, a tracker):
#: measurements whose noise is as stated are set aside once in a thousand; a faulty one (a wrong
#: unit, a tracker the tensions contradict) is off by orders of magnitude more.
LOAD_GATE_PROBABILITY = 1e-3
#: A reading at rest this unlikely under the estimate, with a tip load to estimate, is held back
#: one reading as a possible new load (the next, as far off and agreeing, decides): one honest
#: reading in a thousand waits for the next.
HOLD_PROBABILITY = 1e-3
#: The probability inside 3 sigma of a Gaussian: an estimate inside it is noise about zero.
THREE_SIGMA = 0.9973


@functools.lru_cache(maxsize=64)
def chi2_quantile(probability, dof):
    """Return the ``probability`` quantile of chi-square with ``dof`` degrees of freedom.

    Cached: scipy's ``ppf`` takes ~100 us, a gate is asked at every estimate.
    """
    return float(chi2_distribution.ppf(probability, int(dof)))


def gate(dof, probability):
    """Return the chi-square value above which a measurement of ``dof`` values is set aside."""
    return chi2_quantile(1.0 - probability, dof)


def passes(chi2, dof, probability):
    """Return True if ``chi2`` (a finite total, not per measurement) is inside the gate."""
    return dof <= 0 or chi2 <= gate(dof, probability)
