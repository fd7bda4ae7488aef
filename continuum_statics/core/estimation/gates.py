"""The chi-square gates every estimator and coverage check uses, written once.

A measurement (or a set of them) with residual r and stated covariance S is what the model
explains when r^T S^-1 r stays below the (1 - p) quantile of the chi-square distribution of its
degrees of freedom; p is the probability that a measurement whose noise is as stated is set
aside. A 95 % ellipsoid is the same quantile at 0.95.
"""
import functools
import math

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

    Without scipy (its import took 0.5-1.2 s of a node's start): the root x of
    P(dof / 2, x / 2) = probability, P the regularised lower incomplete gamma function
    (:func:`_gamma_p`), by Newton's method on log P or log Q (whichever is the smaller tail:
    the gates' quantiles lie at 1 - 1e-6), safeguarded by bisection; to 1e-12 relative.
    Cached: a gate is asked at every estimate.
    """
    a, probability = 0.5 * int(dof), float(probability)
    if not 1e-12 <= probability <= 1.0 - 1e-12 or a <= 0.0:
        raise ValueError('chi2_quantile needs 1e-12 <= probability <= 1 - 1e-12 and dof >= 1, '
                         'got %r, %r' % (probability, dof))
    upper = probability > 0.5  # solve on the smaller tail: log Q(a, y) = log(1 - p)
    target = math.log1p(-probability) if upper else math.log(probability)
    low, high = 0.0, max(2.0 * a, 1.0)
    # below the root, log Q lies above its target and log P below
    while (_log_tail(a, high, upper) > target) == upper:
        low, high = high, 2.0 * high
    y = 0.5 * (low + high)
    for _ in range(200):
        log_tail = _log_tail(a, y, upper)
        value = log_tail - target
        if (value > 0.0) == upper:
            low = y
        else:
            high = y
        step = math.nan
        if math.isfinite(log_tail):  # d log P / dy = density / P; d log Q / dy = -density / Q
            slope = math.exp((a - 1.0) * math.log(y) - y - math.lgamma(a) - log_tail)
            step = y + value / slope if upper else y - value / slope
        y_next = step if low < step < high else 0.5 * (low + high)
        if abs(y_next - y) <= 1e-13 * y:
            return 2.0 * y_next
        y = y_next
    return 2.0 * y


def _log_tail(a, y, upper):
    """Return log Q(a, y) (``upper``) or log P(a, y) of the regularised incomplete gamma."""
    p, q = _gamma_p(a, y)
    tail = q if upper else p
    return math.log(tail) if tail > 0.0 else -math.inf  # far beyond the root: underflow


def _gamma_p(a, y):
    """Return (P(a, y), Q(a, y)), each to full relative precision on its own (a > 0, y > 0).

    The series for y < a + 1, Lentz's continued fraction otherwise (Press et al., Numerical
    Recipes, 3rd ed., 6.2.5 and 6.2.7).
    """
    front = math.exp(a * math.log(y) - y - math.lgamma(a))
    if y < a + 1.0:
        term = total = 1.0 / a
        n = a
        while abs(term) > abs(total) * 1e-17:
            n += 1.0
            term *= y / n
            total += term
        p = total * front
        return p, 1.0 - p
    tiny = 1e-300
    b = y + 1.0 - a
    c, d = 1.0 / tiny, 1.0 / b
    h = d
    for i in range(1, 1000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = tiny if abs(d) < tiny else d
        c = b + an / c
        c = tiny if abs(c) < tiny else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-16:
            break
    q = front * h
    return 1.0 - q, q


def gate(dof, probability):
    """Return the chi-square value above which a measurement of ``dof`` values is set aside."""
    return chi2_quantile(1.0 - probability, dof)


def passes(chi2, dof, probability):
    """Return True if ``chi2`` (a finite total, not per measurement) is inside the gate."""
    return dof <= 0 or chi2 <= gate(dof, probability)
