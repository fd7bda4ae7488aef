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

    The same warm-up every node runs at start-up; done here it keeps the compile out of the
    deadlines of the cross-process tests, whose subprocesses then load the on-disk cache
    (``test_cold_start.py`` starts its subprocesses with an empty cache on purpose).
    """
    from continuum_statics import load_robot
    from continuum_statics.core.warmup import warm_up

    warm_up(load_robot(REPO / 'config' / 'tendon_robot.yaml'))


@pytest.fixture
def harness():
    """Yield a private rclpy context with its own executors for in-process node tests."""
    from nodes_helpers import Harness

    harness = Harness()
    try:
        yield harness
    finally:
        harness.close()
