"""Issue 38 items 6-8 over DDS: honest stamps, a frame prefix per arm, a passive rod's /tf.

(and a tracker stamped 1970: used by the controller without a word before)

Each failed on main: a cable_states stamp of 1970 was copied onto backbone and /tf; /tf went
backwards when two stamp sources mixed; two arms from one robot file published the same frames;
a passive rod's /tf was published once, so a listener started later never saw it; the
controller used a tracker stamped 1970 without a word.
"""
import time

from conftest import REPO
from nodes_helpers import LATCHED, Collector, diagnostic_values, publish_until, wait_until
import numpy as np
import pytest

from continuum_statics import load_robot

rclpy = pytest.importorskip('rclpy')
TFMessage = pytest.importorskip('tf2_msgs.msg').TFMessage
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics.nodes.qos import TF_QOS  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

pytestmark = pytest.mark.ros  # starts DDS or a process

THREE_FILE = str(REPO / 'config' / 'three_section_robot.yaml')
THREE = load_robot(THREE_FILE)
ROD_FILE = str(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
NS = 1_000_000_000


def seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def straight_state(sec=0, nanosec=0):
    msg = JointState(name=list(THREE.cable_names),
                     position=[float(v) for v in THREE.straight_cable_lengths])
    msg.header.stamp = Time(sec=sec, nanosec=nanosec)
    return msg


def test_a_stamp_of_1970_is_replaced_by_arrival_and_counted(harness):
    node = harness.add(StaticsNode, robot_file=THREE_FILE, marker_rate=0.0)
    client = harness.client()
    backbone = Collector(client, Path, 'backbone', LATCHED)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)

    def replaced():
        found = diagnostic_values(diagnostics, '/statics')
        return int(found[0].get('stamps_replaced_cable_states', 0)) if found else 0

    publish_until(states, straight_state(sec=1), lambda: backbone.last is not None
                  and replaced() >= 1, 10.0, 'the backbone and the replaced stamp counted')
    now = node.get_clock().now().nanoseconds / NS
    assert abs(seconds(backbone.last.header.stamp) - now) < 10.0  # arrival, not 1970


def test_tf_never_goes_backwards_when_two_stamp_sources_mix(harness):
    harness.add(StaticsNode, robot_file=THREE_FILE, marker_rate=0.0)
    client = harness.client()
    tf = Collector(client, TFMessage, '/tf', TF_QOS)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    wait_until(lambda: states.get_subscription_count() > 0, 10.0, 'statics subscribed')
    deadline = time.monotonic() + 20.0
    while len(tf) < 40:
        assert time.monotonic() < deadline, 'only %d /tf messages' % len(tf)
        now = time.time_ns()
        for sec in (now // NS, 1):  # the driver's clock, then an unsynchronised bridge's
            states.publish(straight_state(sec, now % NS))
            time.sleep(0.005)
    stamps = [seconds(m.transforms[0].header.stamp) for m in list(tf.messages)]
    assert all(b >= a for a, b in zip(stamps, stamps[1:])), np.diff(stamps).min()
    assert min(stamps) > 1e9  # never 1970


def test_two_arms_from_one_robot_file_publish_frames_of_their_own(harness):
    for arm in ('arm1', 'arm2'):
        node = StaticsNode(namespace=harness.namespace + '/' + arm, context=harness.context,
                           parameter_overrides=[
                               rclpy.parameter.Parameter('robot_file', value=THREE_FILE),
                               rclpy.parameter.Parameter('marker_rate', value=0.0),
                               rclpy.parameter.Parameter('frame_prefix', value=arm + '/')])
        harness.nodes.append(node)
        harness._spin(node, 'single')
    client = harness.client()
    tf = Collector(client, TFMessage, '/tf', TF_QOS)
    publishers = [client.create_publisher(JointState, '%s/%s/cable_states'
                                          % (harness.namespace, arm), qos_profile_sensor_data)
                  for arm in ('arm1', 'arm2')]

    def children():
        return {t.child_frame_id for m in list(tf.messages) for t in m.transforms}

    def both():
        for publisher in publishers:
            publisher.publish(straight_state())
        tip = '%s_tip' % THREE.name
        return {'arm1/' + tip, 'arm2/' + tip} <= children()

    wait_until(both, 15.0, 'the tips of both arms on /tf')
    assert all(name.startswith(('arm1/', 'arm2/')) for name in children()), children()


def test_a_passive_rods_frames_reach_a_listener_started_later(harness):
    harness.add(StaticsNode, robot_file=ROD_FILE, marker_rate=0.0, diagnostics_rate=2.0)
    client = harness.client()
    backbone = Collector(client, Path, 'backbone', LATCHED)
    wait_until(lambda: backbone.last is not None, 10.0, 'the passive backbone')
    time.sleep(0.5)  # the start-up /tf is long gone (volatile): this listener comes later
    late = Collector(harness.client('late_listener'), TFMessage, '/tf', TF_QOS)
    wait_until(lambda: any(t.child_frame_id == 'jones2009_nitinol_rod_tip'
                           for m in list(late.messages) for t in m.transforms), 10.0,
               "the rod's tip on /tf for a late listener")


def test_a_tracker_stamped_1970_is_stamped_on_arrival_warned_and_counted(harness):
    harness.add(TipControllerNode, robot_file=THREE_FILE)
    client = harness.client()
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    tracker = client.create_publisher(PoseStamped, 'tip_pose_measured', 10)
    pose = PoseStamped()
    pose.header.frame_id = 'base_link'
    pose.header.stamp = Time(sec=1)
    pose.pose.position.z = 0.3
    pose.pose.orientation.w = 1.0

    def counted():
        found = diagnostic_values(diagnostics, '/tip_controller')
        return found and int(found[0].get('rejected_stamp', 0)) >= 1

    publish_until(tracker, pose, counted, 15.0, 'the 1970 stamp counted on /diagnostics')
    values = diagnostic_values(diagnostics, '/tip_controller')[0]
    assert 'tip_pose_measured stamped' in values['last_rejection']
