"""Samples of the reachable tip positions of a robot (goals, RViz click targets, soak tests)."""
import numpy as np


def reachable_tips(robot, count, seed):
    """Tip positions of random shapes whose cable lengths are inside the limits (reachable)."""
    rng = np.random.default_rng(seed)
    limits = np.asarray(robot.cable_length_limits, dtype=float)
    goals = []
    for _ in range(100 * count):  # bounded: a robot whose limits admit almost no shape
        if len(goals) == count:
            break
        shape = robot.solve_ivp([*rng.uniform(-3.5, 3.5, 2), 0.0])
        lengths = robot.cable_lengths(shape)
        if np.all(lengths >= limits[:, 0] + 1e-4) and np.all(lengths <= limits[:, 1] - 1e-4):
            goals.append(shape.tip_position.copy())
    return goals
