"""Compiled cable paths with capstan friction (the inner loop of ``length_statics``).

For each cable: its holes at the base disk and every guide up to its end disk (paper eq. 11 with
the errata), the spans between them, the wrap angle at each hole (at the base disk from the base
axis, along which the cable arrives from its motor; none at the end disk, where it ends), the
tension of each span t_i = t exp(mu_signed * sum of the wraps between span i and the end disk)
and the free length the path takes, sum_i p_i / (1 + t_i / EA).
"""
import math

import numba
import numpy as np

from continuum_statics.core.description.routing import hole_in


@numba.njit(cache=True, nogil=True)
def path_stretch(states, guide_nodes, cable_last_guide, hole_offsets, base_axis, tensions,
                 friction, compliance, consumed, motor, mean):
    """Fill, per cable: free length its path takes (m), motor-side and mean tension (N).

    :param states: (N, 21) node states of one shape (layout ``core/description/layout.py``)
    :param hole_offsets: (n, G, 3) each cable's hole at each guide, local frame, m (routing.py)
    :param tensions: (n,) end-disk tensions (N); ``friction``: (n,) mu times the sign of motion
        (+1 pulled: tension rises toward the motor); ``compliance``: (n,) 1 / EA (1/N)
    """
    n_cables = hole_offsets.shape[0]
    size = guide_nodes.shape[0]
    spans = np.empty(size)
    wraps = np.empty(size)
    hole = np.empty(3)
    previous = np.empty(3)
    direction = np.empty(3)
    for j in range(n_cables):
        last = cable_last_guide[j]
        for i in range(3):
            direction[i] = base_axis[i]
        for g in range(last + 1):
            hole[0], hole[1], hole[2] = hole_in(states[guide_nodes[g]], hole_offsets[j, g])
            if g > 0:
                d0, d1, d2 = hole[0] - previous[0], hole[1] - previous[1], hole[2] - previous[2]
                span = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                spans[g - 1] = span
                wraps[g - 1] = 0.0
                if span > 0.0:  # holes that meet (a shape folded onto itself) turn nothing
                    d0, d1, d2 = d0 / span, d1 / span, d2 / span
                    cosine = direction[0] * d0 + direction[1] * d1 + direction[2] * d2
                    wraps[g - 1] = math.acos(min(1.0, max(-1.0, cosine)))  # at hole g - 1
                    direction[0], direction[1], direction[2] = d0, d1, d2
            for i in range(3):
                previous[i] = hole[i]
        # span i runs from hole i to hole i + 1; the wraps beyond it are at holes i + 1 .. last-1
        beyond, total, weighted, length = 0.0, 0.0, 0.0, 0.0
        for i in range(last - 1, -1, -1):
            t = tensions[j] * math.exp(friction[j] * beyond)
            total += spans[i] / (1.0 + t * compliance[j])
            weighted += spans[i] * t
            length += spans[i]
            beyond += wraps[i]
        consumed[j] = total
        motor[j] = tensions[j] * math.exp(friction[j] * beyond)
        mean[j] = weighted / max(length, 1e-300)
