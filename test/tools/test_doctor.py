"""Issue 37: ``doctor`` names the fault of deliberately broken set-ups, and the one thing to do.

Over DDS with the real nodes (in-process, the test's private domain) and the real command line:
a healthy robot has no error; a driver not activated, a doctor in the wrong domain, a stopped
node, a silent tracker, a tracker in the wrong frame and an unhomed driver (lengths 10 mm off the
robot file's) each give an error naming it. The ``ros2doctor.checks`` entry point loads and
counts the same errors. The checks' judgement is also tested without DDS.
"""
import json
import os
import subprocess
import sys

from conftest import REPO
from nodes_helpers import LATCHED, Collector, wait_until
import pytest

from continuum_statics import load_robot
from continuum_statics.tools import doctor_checks as checks
from continuum_statics.tools.doctor import observe

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

ROBOT_FILE = str(REPO / 'config' / 'tendon_robot.yaml')
ROBOT = load_robot(ROBOT_FILE)
WATCH = 2.5  # s of graph watched per diagnosis


def errors(findings, check):
    return [f for f in findings if f.level == checks.ERROR and f.check == check]


def start(harness, *nodes, **driver):
    added = {}
    if 'statics' in nodes:
        added['statics'] = harness.add(StaticsNode, robot_file=ROBOT_FILE, marker_rate=0.0)
    if 'tip_controller' in nodes:
        added['tip_controller'] = harness.add(TipControllerNode, robot_file=ROBOT_FILE)
    if 'cable_driver' in nodes:
        added['cable_driver'] = harness.add(CableDriverNode, robot_file=ROBOT_FILE, **driver)
    return added


def wait_ready(harness):
    client = harness.client('ready_probe')
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    wait_until(lambda: len(tip) > 0, 30.0, 'tip_pose from statics')


def diagnose(harness, **options):
    return checks.diagnose(observe(harness.namespace, WATCH, **options))


@pytest.mark.ros
def test_healthy_robot_has_no_error(harness):
    start(harness, 'statics', 'tip_controller', 'cable_driver')
    wait_ready(harness)
    findings = diagnose(harness)
    assert checks.worst(findings) in (checks.OK, checks.NOTE, checks.WARN), findings
    ready = [f.message for f in findings if f.check == 'nodes' and f.level == checks.OK]
    assert len(ready) == 3, findings
    assert any(f.check == 'rates' and f.level == checks.OK for f in findings), findings
    assert any(f.check == 'tf' and f.level == checks.OK for f in findings), findings


@pytest.mark.ros
def test_driver_not_activated(harness):
    start(harness, 'statics', 'tip_controller', 'cable_driver', autostart=False)
    findings = diagnose(harness)
    driver = errors(findings, 'driver')
    assert driver and 'unconfigured' in driver[0].message, findings
    assert 'ros2 lifecycle set %s/cable_driver' % harness.namespace in driver[0].action


@pytest.mark.ros
def test_wrong_domain_from_the_command_line(harness):
    start(harness, 'statics', 'cable_driver')
    wait_ready(harness)
    env = dict(os.environ)
    here = int(env.get('ROS_DOMAIN_ID', '0'))
    env['ROS_DOMAIN_ID'] = str((here + 1) % 233)
    run = subprocess.run([sys.executable, '-m', 'continuum_statics', 'doctor', '--namespace',
                          harness.namespace, '--duration', str(WATCH), '--json'],
                         capture_output=True, text=True, env=env, timeout=120)
    assert run.returncode == 1, run.stdout + run.stderr
    report = json.loads(run.stdout)
    nodes = [f for f in report['findings'] if f['check'] == 'nodes']
    assert nodes[0]['level'] == 'error' and 'no node of the robot' in nodes[0]['message']
    assert 'ROS_DOMAIN_ID=%s' % env['ROS_DOMAIN_ID'] in nodes[0]['message']
    assert 'ROS_DOMAIN_ID' in nodes[0]['action']
    # the same doctor in the robot's domain finds them
    env['ROS_DOMAIN_ID'] = str(here)
    run = subprocess.run([sys.executable, '-m', 'continuum_statics', 'doctor', '--namespace',
                          harness.namespace, '--duration', str(WATCH)],
                         capture_output=True, text=True, env=env, timeout=120)
    assert 'statics ready' in run.stdout, run.stdout + run.stderr
    assert 'tip_controller is not running' in run.stdout


@pytest.mark.ros
def test_stopped_node(harness):
    start(harness, 'statics', 'cable_driver')
    wait_ready(harness)
    findings = diagnose(harness)
    nodes = errors(findings, 'nodes')
    assert [f.message for f in nodes] == ['tip_controller is not running in %s'
                                          % harness.namespace], findings
    assert 'start it' in nodes[0].action


@pytest.mark.ros
def test_silent_sensor(harness):
    start(harness, 'statics', 'tip_controller', 'cable_driver')
    client = harness.client('tracker')
    client.create_publisher(PoseStamped, 'tip_pose_measured', qos_profile_sensor_data)
    wait_ready(harness)
    sensors = errors(diagnose(harness), 'sensors')
    assert len(sensors) == 1 and 'tip_pose_measured' in sensors[0].message
    assert 'silent' in sensors[0].message and 'driver' in sensors[0].action


@pytest.mark.ros
def test_tracker_in_the_wrong_frame(harness):
    client = harness.client('tracker')
    publisher = client.create_publisher(PoseStamped, 'tip_pose_measured',
                                        qos_profile_sensor_data)

    def send():
        msg = PoseStamped()
        msg.header.frame_id = 'mocap_world'
        msg.header.stamp = client.get_clock().now().to_msg()
        publisher.publish(msg)

    client.create_timer(0.02, send)
    sensors = errors(diagnose(harness, robot_file=ROBOT_FILE), 'sensors')
    assert len(sensors) == 1 and "'mocap_world'" in sensors[0].message, sensors
    assert ROBOT.base_frame_id in sensors[0].message


@pytest.mark.parametrize('offset', [-0.010, -0.040])
@pytest.mark.ros
def test_unhomed_driver(harness, offset):
    """One cable's zero off: 10 mm fits no shape, 40 mm is outside the file's length limits."""
    start(harness, 'statics', 'tip_controller')
    client = harness.client('unhomed_driver')
    publisher = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    lengths = [float(v) for v in ROBOT.straight_cable_lengths]
    lengths[0] += offset

    def send():
        msg = JointState(name=list(ROBOT.cable_names), position=lengths)
        msg.header.stamp = client.get_clock().now().to_msg()
        publisher.publish(msg)

    client.create_timer(0.01, send)
    driver = errors(diagnose(harness), 'driver')
    assert len(driver) == 1 and 'not homed' in driver[0].message, driver
    assert ('outside' in driver[0].message) == (offset < -0.02)
    assert 'set_home' in driver[0].action


@pytest.mark.ros
def test_ros2doctor_entry_point_counts_the_errors(harness, monkeypatch):
    from importlib.metadata import entry_points

    start(harness, 'statics', 'cable_driver')
    wait_ready(harness)
    (entry,) = [e for e in entry_points(group='ros2doctor.checks')
                if e.value.startswith('continuum_statics.')]
    check = entry.load()()
    monkeypatch.setenv('CONTINUUM_STATICS_NAMESPACE', harness.namespace)
    assert check.category() == 'continuum_statics'
    result = check.check()
    assert result.error >= 1  # tip_controller is not running
    (report_entry,) = [e for e in entry_points(group='ros2doctor.report')
                       if e.value.startswith('continuum_statics.')]
    report = report_entry.load()().report()
    assert any('tip_controller is not running' in info for _, info in report.items)


def test_checks_without_dds(tmp_path):
    bad = checks.Observation(environment={'ROS_DOMAIN_ID': '300'}, graph_seen=False,
                             kernels_cached=(3, 13), robot_error='rod.length: missing',
                             robot_file='x.yaml')
    findings = checks.diagnose(bad)
    assert errors(findings, 'environment') and errors(findings, 'robot_file')
    assert [f.level for f in findings if f.check == 'kernels'] == [checks.WARN]
    calibrated = tmp_path / 'robot.yaml'
    calibrated.write_text('# Calibrated by `python -m continuum_statics calibrate` on '
                          '2020-01-02 03:04 UTC\n' + open(ROBOT_FILE).read())
    good = checks.Observation(robot=ROBOT, robot_file=str(calibrated), graph_seen=False,
                              kernels_cached=(13, 13))
    calibration = [f for f in checks.diagnose(good) if f.check == 'calibration']
    # written today, calibrated in 2020: edited after calibration, and an old calibration
    assert [f.level for f in calibration] == [checks.WARN, checks.WARN]
    assert 'changed' in calibration[0].message and '2020-01-02 03:04' in calibration[1].message
