"""Test-session ROS settings: loopback-only discovery, a domain per run, quick discovery.

Set before any test imports rclpy, and inherited by every subprocess the tests start, so a run
never hears another run (or a demo) on the same machine.
"""
import os
from pathlib import Path
import random

import pytest

REPO = Path(__file__).resolve().parents[1]

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(10, 99)))
os.environ.setdefault(
    'FASTDDS_DEFAULT_PROFILES_FILE', str(REPO / 'config' / 'fastdds_fast_discovery.xml'))


def pytest_sessionstart(session):
    """Compile and cache the numba kernels once, before any test starts a node subprocess.

    In a fresh clone the first solve compiles for ~20 s; doing it here keeps that out of the
    deadlines of the cross-process tests, whose subprocesses then load the on-disk cache.
    """
    from continuum_statics import load_robot

    robot = load_robot(REPO / 'config' / 'tendon_robot.yaml')
    shape = robot.solve_ivp([1.0, 0.5, 0.0])
    robot.cable_lengths(shape)
    robot.estimate_shape(robot.cable_lengths(shape), u0_guess=shape.u0)
    robot.solve_tip_goal(shape.tip_position)
    robot.jacobian(shape.u0)
    robot.solve_bvp(tip_force=(0.0, 0.0, -0.1))


@pytest.fixture
def harness():
    """Yield a private rclpy context with its own executors for in-process node tests."""
    from nodes_helpers import Harness

    harness = Harness()
    try:
        yield harness
    finally:
        harness.close()
