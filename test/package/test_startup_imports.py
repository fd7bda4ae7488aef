"""A node starts sooner: no heavy scipy subpackage, the quick-discovery profile in every command.

``scipy.stats`` alone took 0.5-1.2 s of a node's start (the chi-square gates), ``scipy.spatial``
and ``scipy.optimize`` ~0.5 s more; the gates compute their quantiles themselves, and obstacles
and clearance goals import scipy where they use it (numba takes LAPACK from scipy.linalg).
"""
import os
import subprocess
import sys

from conftest import REPO
import pytest

HEAVY = ('scipy.stats', 'scipy.optimize', 'scipy.spatial')

SCRIPT = """
import sys
import continuum_statics.nodes.statics_node
import continuum_statics.nodes.tip_controller_node
import continuum_statics.nodes.tip_load_estimator_node
import continuum_statics.nodes.cable_driver_node
from continuum_statics import load_robot
from continuum_statics.config_paths import config_file
from continuum_statics.core.warmup import warm_up
robot = load_robot(config_file('tendon_robot_payload.yaml'))
warm_up(robot)  # the estimator's paths, gates included
estimate = robot.estimate_shape(robot.straight_cable_lengths, stamp=0.0)
print(' '.join(sorted(name for name in sys.modules if name.startswith(%r))))
""" % (HEAVY,)


@pytest.mark.ros  # a process of its own: the modules a node's start imports
def test_the_nodes_and_their_warm_up_import_no_heavy_scipy_subpackage():
    result = subprocess.run([sys.executable, '-c', SCRIPT], cwd=REPO, capture_output=True,
                            text=True, timeout=300, check=True)
    assert result.stdout.strip() == ''


def test_every_node_command_takes_the_quick_discovery_profile_unless_one_is_set(monkeypatch):
    """A node restarted alone (not by bringup) found its peers 0.9-2.0 s later without it."""
    from continuum_statics.nodes import node_runner

    class Started(Exception):
        """rclpy.init reached: where the profile must already be set."""

    def init(**_):
        raise Started(os.environ.get('FASTDDS_DEFAULT_PROFILES_FILE'))

    monkeypatch.setattr(node_runner.rclpy, 'init', init)
    monkeypatch.delenv('FASTDDS_DEFAULT_PROFILES_FILE', raising=False)
    with pytest.raises(Started) as started:
        node_runner.run_nodes([])
    profile = started.value.args[0]
    assert profile.endswith('fastdds_fast_discovery.xml') and os.path.isfile(profile)
    monkeypatch.setenv('FASTDDS_DEFAULT_PROFILES_FILE', '/a/users/own.xml')
    with pytest.raises(Started, match='/a/users/own.xml'):
        node_runner.run_nodes([])
