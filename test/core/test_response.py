"""Settling time, overshoot and spectrum peaks against a second-order system's closed forms."""
import numpy as np

from continuum_statics.core.dynamics.response import (
    overshoot,
    settling_time,
    spectrum_peaks,
)

ZETA, FREQUENCY = 0.1, 9.3  # damping ratio, natural frequency (Hz)


def step_response(duration=3.0, dt=1e-3, size=0.02):
    """Return the unit step of a second-order system (zeta, frequency), ``size`` m along x."""
    w = 2.0 * np.pi * FREQUENCY
    wd = w * np.sqrt(1.0 - ZETA ** 2)
    t = np.arange(0.0, duration, dt)
    x = 1.0 - np.exp(-ZETA * w * t) * (np.cos(wd * t) + ZETA / np.sqrt(1.0 - ZETA ** 2)
                                        * np.sin(wd * t))
    path = np.zeros((len(t), 3))
    path[:, 0] = size * x
    return t, path, wd / (2.0 * np.pi)


def test_a_second_order_step_reads_as_its_closed_forms():
    t, path, damped = step_response()
    expected = 100.0 * np.exp(-ZETA * np.pi / np.sqrt(1.0 - ZETA ** 2))
    assert abs(overshoot(path, final=path[0] * 0 + [0.02, 0, 0]) - expected) < 0.05
    settle = settling_time(t, path, final=[0.02, 0.0, 0.0])
    # the envelope exp(-zeta w t) / sqrt(1 - zeta^2) under 2 %: a bound the last crossing meets
    envelope = np.log(0.02 * np.sqrt(1.0 - ZETA ** 2)) / (-ZETA * 2.0 * np.pi * FREQUENCY)
    assert 0.8 * envelope < settle <= envelope
    peaks = spectrum_peaks(t, path, count=1, final=[0.02, 0.0, 0.0])
    assert abs(peaks[0] - damped) < 0.01 * damped


def test_a_path_that_never_settles_says_so_and_a_still_one_has_no_peaks():
    t, path, _ = step_response(duration=0.2)
    assert settling_time(t, path, final=[0.02, 0.0, 0.0]) is None
    still = np.zeros((100, 3))
    assert settling_time(np.arange(100) * 1e-3, still) == 0.0
    assert overshoot(still) == 0.0
    assert spectrum_peaks(np.arange(100) * 1e-3, still) == []


def test_a_run_cut_short_is_not_settled_and_a_long_one_meets_the_closed_form():
    """The band is about the median of the last fifth, and the path must stay in it that long."""
    envelope = np.log(0.02 * np.sqrt(1.0 - ZETA ** 2)) / (-ZETA * 2.0 * np.pi * FREQUENCY)
    for duration in (0.2, 0.3, 0.4, 0.5):  # all end before the 0.67 s envelope
        t, path, _ = step_response(duration=duration)
        # before: 0.198, 0.298, 0.395, 0.468 s (the band centred on the last sample)
        assert settling_time(t, path) is None, duration
    for duration in (1.0, 3.0):  # no final given: estimated from the record itself
        t, path, _ = step_response(duration=duration)
        assert 0.8 * envelope < settling_time(t, path) <= envelope
