"""Test-session ROS settings: loopback-only discovery, a domain per run, quick discovery.

Set before any test imports rclpy, and inherited by every subprocess the tests start, so a run
never hears another run (or a demo) on the same machine.
"""
import os
from pathlib import Path
import random
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
# A few test modules reuse another layer's fixtures (``from test_run_calibration import V6``):
# every layer folder is importable, so one folder runs alone (``pytest test/core``) as well.
sys.path[:0] = [str(folder) for folder in sorted(Path(__file__).parent.iterdir())
                if folder.is_dir() and folder.name.isidentifier() and folder.name[0] != '_'
                and not (folder / '__init__.py').exists()]

os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(10, 99)))
# pytest-xdist workers (gw0, gw1, ...) run side by side: each a domain of its own, 100 apart (the
# doctor's test uses the next domain up as a foreign one).
_worker = os.environ.get('PYTEST_XDIST_WORKER', 'gw0')
_domain = int(os.environ['ROS_DOMAIN_ID']) + 100 * int(_worker[2:])
os.environ['ROS_DOMAIN_ID'] = str(_domain % 233)
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


@pytest.fixture(autouse=True)
def _only_ros_tests_start_dds_or_a_process(request, monkeypatch):
    """Fail a test that starts DDS or a process without the ``ros`` marker.

    ``make test-core`` runs ``-m "not ros"``, the fast tier of everything that starts neither;
    this keeps the marker true: an unmarked test that starts a subprocess or an rclpy context
    fails with the reason (compute pools of ``multiprocessing`` are not processes a user sees).
    """
    if request.node.get_closest_marker('ros') is not None:
        return
    import subprocess

    def refuse(what):
        def refused(*args, **kwargs):
            pytest.fail('%s starts %s without the ros marker (pytestmark = pytest.mark.ros)'
                        % (request.node.nodeid, what), pytrace=False)
        return refused

    monkeypatch.setattr(subprocess.Popen, '__init__', refuse('a process'))
    try:
        import rclpy.context
    except ImportError:  # no ROS here: nothing can start DDS either
        return
    monkeypatch.setattr(rclpy.context.Context, 'init', refuse('DDS (an rclpy context)'))


@pytest.fixture
def harness():
    """Yield a private rclpy context with its own executors for in-process node tests."""
    from nodes_helpers import Harness

    harness = Harness()
    try:
        yield harness
    finally:
        harness.close()
