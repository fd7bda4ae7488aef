"""Issue 37: ``doctor`` names the fault of deliberately broken set-ups, and the one thing to do.

Over DDS with the real nodes (in-process, the test's private domain) and the real command line:
a healthy robot has no error; a driver not activated, a doctor in the wrong domain, a stopped
node, a silent tracker, a tracker in the wrong frame and an unhomed driver (lengths 10 mm off the
robot file's) each give an error naming it. The ``ros2doctor.checks`` entry point loads and
counts the same errors. The checks' judgement is also tested without DDS.
"""
import json
import os
import re
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
    # 100 Hz: at the default 200 Hz the three nodes as threads of one process reached 154 Hz
    # of cable_states (statics 108 Hz) on a 2-GHz Zen 1, which the doctor rightly warns of
    start(harness, 'statics', 'tip_controller', 'cable_driver', publish_rate=100.0)
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


# -- issue 44 item 5: the doctor sees what the user sees --------------------------------------
SENSORS_FILE = str(REPO / 'config' / 'tendon_robot_sensors.yaml')
TENDONS_FILE = str(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
SENSORS = load_robot(SENSORS_FILE)
TENDONS = load_robot(TENDONS_FILE)


def sensors_seen(findings):
    return [f for f in findings if f.check == 'sensors' and f.level == checks.ERROR]


def test_robot_file_sensors_silent_foreign_or_1970():
    ns = '/continuum'
    topics = {'sensors/tip_tracker': checks.TopicSample(publishers=1),
              'sensors/em_coil': checks.TopicSample(1, 40, 40.0, 'mocap_world', 0.01)}
    seen = checks.Observation(robot=SENSORS, robot_file=SENSORS_FILE, namespace=ns,
                              nodes=('statics',), topics=topics)
    findings = checks.diagnose(seen)
    # before: only tip_pose_measured and tip_wrench were looked at: no sensors finding, rc 0
    errors_ = sensors_seen(findings)
    assert [f.message.split(':')[0] for f in errors_] == ['sensor tip_tracker',
                                                          'sensor em_coil'], findings
    assert 'silent' in errors_[0].message
    assert 'check the sensor tip_tracker is publishing on /continuum/sensors/tip_tracker' \
        in errors_[0].action
    assert "'mocap_world'" in errors_[1].message
    # stamped 1970 (sec 1): before 'note' at worst; nobody publishing a declared sensor: error
    topics['sensors/em_coil'] = checks.TopicSample(1, 40, 40.0, 'base_link', 1.75e9)
    del topics['sensors/tip_tracker']
    errors_ = sensors_seen(checks.diagnose(seen))
    assert 'nobody publishes' in errors_[0].message and '1970' in errors_[1].message, errors_
    # the tip tracker on tip_pose_measured counts for the robot file's tip sensor
    topics['sensors/em_coil'] = checks.TopicSample(1, 40, 40.0, 'base_link', 0.01)
    topics['tip_pose_measured'] = checks.TopicSample(1, 100, 100.0, 'base_link', 0.01)
    assert not sensors_seen(checks.diagnose(seen))


def test_statics_status_naming_a_silent_sensor_is_an_error():
    status = (checks.WARN, 'sensor tip_tracker silent for 55.1 s',
              {'tip_sigma_mm': '3.2'})
    seen = checks.Observation(robot=SENSORS, robot_file=SENSORS_FILE, nodes=('statics',),
                              statuses={'continuum/statics': status},
                              topics={'tip_pose_measured': checks.TopicSample(
                                  1, 100, 100.0, 'base_link', 0.01),
                                  'sensors/em_coil': checks.TopicSample(
                                      1, 40, 40.0, 'base_link', 0.01)})
    findings = checks.diagnose(seen)
    # before: [ok] statics ready: sensor tip_tracker silent for 55.1 s (and rc 0)
    assert [f.level for f in findings if f.check == 'nodes' and 'statics' in f.message] == [
        checks.WARN]
    (silent,) = sensors_seen(findings)
    assert 'sensor tip_tracker silent for 55.1 s' in silent.message
    assert '/continuum/sensors/tip_tracker' in silent.action


def test_sensors_without_model_uncertainty_run_on_a_stand_in_prior(tmp_path):
    text = open(SENSORS_FILE).read()
    bare = tmp_path / 'no_prior.yaml'
    bare.write_text(text[:text.index('model_uncertainty:')])
    robot = load_robot(str(bare))
    seen = checks.Observation(robot=robot, robot_file=str(bare), graph_seen=False)
    prior = [f for f in checks.diagnose(seen) if 'stand-in' in f.message]
    # before: no word (the stand-in prior was silent)
    assert [f.level for f in prior] == [checks.WARN]
    assert 'calibrate --model-uncertainty' in prior[0].action
    # a file with its own model_uncertainty: nothing to say
    seen = checks.Observation(robot=SENSORS, robot_file=SENSORS_FILE, graph_seen=False)
    assert not [f for f in checks.diagnose(seen) if 'stand-in' in f.message]


def true_tensions(lengths):
    """Tensions of the real robot at these true lengths, the cables last pulled (N)."""
    warm = TENDONS.solve_lengths(lengths + 1e-4)
    return TENDONS.solve_lengths(lengths, warm_start=warm).tensions


@pytest.mark.parametrize('pose', [(0.0, 0.0, 0.0, 0.0), (-0.004, 0.001, 0.004, -0.001)])
def test_tension_mismatch_names_the_cable_homed_10_mm_off(pose):
    import numpy as np

    truth = np.asarray(TENDONS.straight_cable_lengths) + pose
    tensions = true_tensions(truth) + np.random.default_rng(4).normal(0.0, 0.05, 4)
    std = np.full(4, 0.05)
    homed = checks.Observation(robot=TENDONS, robot_file=TENDONS_FILE, graph_seen=False,
                               cables=checks.CableSample(truth, tensions, std, 100))
    (ok,) = [f for f in checks.diagnose(homed) if f.check == 'tensions']
    assert ok.level == checks.OK, ok  # a correct home is not named
    reads = truth.copy()
    reads[2] -= 0.010  # cable_2's zero 10 mm off: it reads 10 mm short
    off = checks.Observation(robot=TENDONS, robot_file=TENDONS_FILE, graph_seen=False,
                             cables=checks.CableSample(reads, tensions, std, 100))
    findings = checks.diagnose(off)
    # before: no tensions check: status OK, nothing named (a shape bent ~68 mm, 39 N modelled)
    (named,) = [f for f in findings if f.check == 'tensions']
    assert named.level == checks.ERROR and checks.worst(findings) == checks.ERROR
    assert re.search(r'cable_2 reads (9\.[5-9]|10\.[0-5]) mm less than its tension says',
                     named.message), named.message
    assert 'cable_0 reads' not in named.message
    assert 're-home cable_2' in named.action and 'set_home' in named.action


def test_tension_tolerance_is_noise_friction_and_sensor_error():
    import numpy as np

    truth = np.asarray(TENDONS.straight_cable_lengths) + (-0.004, 0.001, 0.004, -0.001)
    for warm in (1e-4, -1e-4):  # friction either way: inside the band
        tensions = TENDONS.solve_lengths(truth, warm_start=TENDONS.solve_lengths(
            truth + warm)).tensions
        result = checks.compare_tensions(TENDONS, truth, tensions)
        assert not np.any(result.mismatch) and result.named == ()
        assert np.all(result.low <= tensions + 1e-9) and np.all(tensions <= result.high + 1e-9)
    # noisier readings widen it: 3 sigma of their scatter
    wide = checks.compare_tensions(TENDONS, truth, tensions, np.full(4, 1.0))
    assert np.allclose(wide.tolerance - result.tolerance, 3.0)


def test_failed_lifecycle_transition_names_its_cause():
    failure = 'configure failed: sim.dynamics needs real tendons (a tendons block)'
    status = (checks.ERROR, failure, {'lifecycle': 'unconfigured',
                                      'transition_failure': failure})
    seen = checks.Observation(robot=ROBOT, robot_file=ROBOT_FILE, nodes=('cable_driver',),
                              statuses={'continuum/cable_driver': status})
    (driver,) = errors(checks.diagnose(seen), 'driver')
    # before: "cable_driver is unconfigured" -> configure, then activate (which fails the same)
    assert 'sim.dynamics needs real tendons' in driver.message
    assert driver.action.startswith('fix that cause')


def test_transition_failures_keep_the_reason_until_a_transition_succeeds():
    from rclpy.lifecycle import TransitionCallbackReturn

    from continuum_statics.control.health import ERROR as ERROR_LEVEL
    from continuum_statics.nodes.transition_failures import TransitionFailures

    class Logger:
        def __init__(self):
            self.lines = []

        def error(self, text):
            self.lines.append(text)

        info = warning = error

    class Node(TransitionFailures):
        logger = Logger()

        def get_logger(self):
            return self.logger

    node = Node()
    health = (0, 'unconfigured (lifecycle)', {'lifecycle': 'unconfigured'})
    assert node._with_transition_failure(health)[0] == 0
    assert node._transition_failed('configure failed: no tendons') == \
        TransitionCallbackReturn.FAILURE
    level, message, values = node._with_transition_failure(health)
    # before: the reason was in the log only; /diagnostics said "unconfigured", level OK
    assert level == ERROR_LEVEL and node.logger.lines == ['configure failed: no tendons']
    assert values['transition_failure'] == 'configure failed: no tendons'
    node._transition_failed('activate failed: torque refused')  # Actuators.failure
    assert node._with_transition_failure(health)[2]['transition_failure'] == \
        'activate failed: torque refused'
    node._transition_done()
    assert 'transition_failure' not in node._with_transition_failure(
        (0, 'ok', {'lifecycle': 'active'}))[2]


@pytest.mark.ros
def test_robot_file_sensors_over_dds(harness):
    """A silent tip_tracker and an em_coil stamped 1970, as the robot file declares them."""
    client = harness.client('sensors')
    client.create_publisher(PoseStamped, 'sensors/tip_tracker', qos_profile_sensor_data)
    coil = client.create_publisher(PoseStamped, 'sensors/em_coil', qos_profile_sensor_data)

    def send():
        msg = PoseStamped()
        msg.header.frame_id = SENSORS.base_frame_id
        msg.header.stamp.sec = 1  # an unset clock
        coil.publish(msg)

    client.create_timer(0.02, send)
    found = sensors_seen(diagnose(harness, robot_file=SENSORS_FILE))
    # before: neither topic was sampled: worst 'note', rc 0
    assert [f.message.split(':')[0] for f in found] == ['sensor tip_tracker',
                                                        'sensor em_coil'], found
    assert 'silent' in found[0].message and '1970' in found[1].message
    assert '%s/sensors/tip_tracker' % harness.namespace in found[0].action


@pytest.mark.ros
def test_refused_configure_is_named(harness):
    """sim.dynamics on a robot file without real tendons: the driver says why, doctor too."""
    start(harness, 'cable_driver', **{'sim.dynamics': True})
    (driver,) = errors(diagnose(harness), 'driver')
    # before: 'cable_driver is unconfigured' -> 'configure, then activate' (failing the same way)
    assert 'configure failed' in driver.message and 'real tendons' in driver.message, driver
    assert driver.action.startswith('fix that cause')


@pytest.mark.ros
def test_cable_homed_10_mm_off_on_real_tendons(harness):
    """The driver reports cable_1 10 mm short at the straight pose, its load cell 2 N."""
    client = harness.client('homed_off')
    publisher = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    lengths = [float(v) for v in TENDONS.straight_cable_lengths]
    lengths[1] -= 0.010

    def send():
        msg = JointState(name=list(TENDONS.cable_names), position=lengths, effort=[2.0] * 4)
        msg.header.stamp = client.get_clock().now().to_msg()
        publisher.publish(msg)

    client.create_timer(0.01, send)
    run = subprocess.run([sys.executable, '-m', 'continuum_statics', 'doctor', '--namespace',
                          harness.namespace, '--duration', str(WATCH), '--robot', TENDONS_FILE],
                         capture_output=True, text=True, timeout=120)
    # before: no tension check, nothing named (statics would show a shape bent ~68 mm)
    assert run.returncode == 1, run.stdout + run.stderr
    assert re.search(r'cable_1 reads (9\.\d|10\.\d) mm less', run.stdout), run.stdout
    assert 're-home cable_1' in run.stdout and 'set_home' in run.stdout
