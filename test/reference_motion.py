"""Inputs like a real robot's and a plain SciPy fit, shared by tests and benchmarks.

- :func:`motion`: motor lengths moving linearly between far-apart equilibria (real cable lengths
  never fit a shape exactly between the end points);
- :func:`scipy_estimate`: the shape fitted by ``scipy.optimize.least_squares`` (LM) on the model's
  own residual, the baseline of another solver (``test/core/test_noisy_estimation.py``,
  ``benchmarks/bench_noisy.py`` through ``benchmarks/shared.py``).
"""
import dataclasses

import numpy as np
from scipy.optimize import least_squares

from continuum_statics.core.description.layout import ProbeRows
from continuum_statics.core.robot import Robot

#: Cable speed (m/s) and sample rate (Hz) of the motion: 20 um between samples at most.
SPEED, RATE = 0.02, 1000.0


def motion(robot, samples, seed=0, speed=SPEED, rate=RATE):
    """Return (samples, n) motor lengths moving linearly between far-apart equilibria.

    ``speed`` m/s, sampled at ``rate`` Hz; the equilibria are the ideal cables' under random
    tensions.
    """
    rng = np.random.default_rng(seed)
    n = len(robot.cable_names)
    ideal = Robot(dataclasses.replace(robot.description, tendons=dataclasses.replace(
        robot.tendons, stiffness=np.full(n, np.inf), pretension=np.zeros(n),
        friction=np.zeros(n), zero_offset=np.zeros(n))))
    limits = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)
    rows, here, warm = [], None, None
    while len(rows) < samples:
        tensions = rng.uniform(0.0, 1.0, n) * rng.uniform(0.2, 2.0)
        warm = ideal.solve_tensions(tensions, warm_start=warm)
        there = ideal.cable_lengths(warm)
        if np.any(there < limits[:, 0] + 1e-3) or np.any(there > limits[:, 1] - 1e-3):
            continue
        if here is not None:
            steps = max(1, int(np.ceil(np.max(np.abs(there - here)) / (speed / rate))))
            rows.extend(here + (there - here) * k / steps for k in range(1, steps + 1))
        here = there
    return np.array(rows[:samples])


def scipy_estimate(robot, lengths, start):
    """Fit by scipy.optimize.least_squares (LM): the lengths and the weighted tip balance."""
    rows = ProbeRows(len(robot.cable_names))
    zero = np.zeros(3)

    def residual(x):
        values = robot.probe(x, 0, zero, zero).values
        return np.concatenate([values[rows.lengths] - lengths,
                               1e3 * robot.length * values[rows.balance]])

    return least_squares(residual, start, method='lm', xtol=1e-12)
