"""Validation of numeric arguments at the boundary of the core."""
import math

import numpy as np


def as_vector(value, size, name):
    """Float array of ``size`` finite numbers (a copy), or ``ValueError`` saying what was wrong."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (size,):
        array = value.copy()  # fast path for the per-cycle calls
    else:
        try:
            array = np.array(value, dtype=float).reshape(-1)
        except (TypeError, ValueError) as error:
            raise ValueError('%s must be %d numbers, got %r' % (name, size, value)) from error
        if array.size != size:
            raise ValueError('%s must have %d elements, got %d' % (name, size, array.size))
    if not math.isfinite(array.dot(array)):  # NaN and inf both propagate into the dot product
        raise ValueError('%s must be finite, got %s' % (name, array.tolist()))
    return array
