"""Validation of arguments at the boundary of the core (numbers, and robot file mappings)."""
import math

import numpy as np

_FLOAT = np.dtype(np.float64)  # a singleton: compared by identity in the per-cycle path


def as_vector(value, size, name, finite=True):
    """Float array of ``size`` finite numbers (a copy), or ``ValueError`` saying what was wrong.

    ``finite=False``: a float64 array of that size is copied unchecked, for a caller whose
    compiled code checks its inputs itself (and then calls this again to say what was wrong).
    """
    if type(value) is np.ndarray and value.dtype is _FLOAT and value.shape == (size,):
        array = value.copy()  # fast path for the per-cycle calls
        if not finite:
            return array
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


def mapping(value, field, allowed):
    """Return ``value`` if it is a mapping with only ``allowed`` keys, else ``ValueError``."""
    if not isinstance(value, dict):
        raise ValueError('%s must be a mapping, got %r' % (field, value))
    unknown = sorted(set(value) - set(allowed))
    if unknown:
        raise ValueError('%s has unknown keys %s (allowed: %s)'
                         % (field, unknown, ', '.join(sorted(allowed))))
    return value
