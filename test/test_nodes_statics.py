"""statics over DDS in one process (private context): outputs, bad input, tip load, parameters."""
import math

from conftest import REPO
from nodes_helpers import (
    LATCHED,
    Collector,
    all_finite_path,
    call,
    diagnostic_values,
    pose_xyz,
    publish_until,
    wait_until,
)
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
BENT = ROBOT.solve_ivp([2.0, 1.0, 0.0])
NAMES = list(ROBOT.cable_names)


class Rig:
    """statics plus a client that feeds cable_states/tip_wrench and collects the outputs."""

    def __init__(self, harness, **overrides):
        self.node = harness.add(StaticsNode, **overrides)
        client = self.client = harness.client()
        self.backbone = Collector(client, Path, 'backbone', LATCHED)
        self.tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
        self.markers = Collector(client, MarkerArray, 'backbone_markers', LATCHED)
        self.diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
        self.states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
        self.wrench = client.create_publisher(WrenchStamped, 'tip_wrench',
                                              qos_profile_sensor_data)
        self.stamp = 100

    def measurement(self, lengths, names=None):
        self.stamp += 1
        msg = JointState(name=NAMES if names is None else names, position=list(lengths))
        msg.header.stamp = Time(sec=self.stamp, nanosec=250)
        return msg

    def feed(self, lengths, names=None):
        """Publish one measurement until its backbone comes back; return that backbone."""
        msg = self.measurement(lengths, names)
        publish_until(self.states, msg, lambda: self.backbone.last is not None
                      and self.backbone.last.header.stamp.sec == msg.header.stamp.sec, 10.0,
                      'the backbone of measurement %d' % msg.header.stamp.sec)
        return self.backbone.last

    def values(self):
        found = diagnostic_values(self.diagnostics, '/statics')
        return found[0] if found else {}


def test_backbone_tip_pose_and_markers_from_cable_states(harness):
    rig = Rig(harness)
    backbone = rig.feed(ROBOT.cable_lengths(BENT))
    assert backbone.header.frame_id == ROBOT.base_frame_id == 'base_link'
    assert backbone.header.stamp.nanosec == 250
    assert len(backbone.poses) == 20
    assert all(p.header.frame_id == 'base_link' for p in backbone.poses)
    assert all_finite_path(backbone)
    np.testing.assert_allclose(pose_xyz(backbone.poses[0].pose), BENT.positions[0], atol=1e-9)
    np.testing.assert_allclose(pose_xyz(backbone.poses[-1].pose), BENT.tip_position, atol=1e-6)
    wait_until(lambda: rig.tip.last is not None and rig.tip.last.header.stamp.sec == rig.stamp,
               5.0, 'the tip pose of the same measurement')
    assert rig.tip.last.pose == backbone.poses[-1].pose
    assert rig.tip.last.header.frame_id == 'base_link'
    wait_until(lambda: len(rig.markers) > 0, 5.0, 'backbone markers')
    namespaces = {m.ns.split('/')[-1] for m in rig.markers.last.markers}
    assert {'backbone', 'guides', 'cables', 'tip'} <= namespaces
    wait_until(lambda: rig.values().get('converged') == 'True', 5.0, 'a converged status')


def test_late_joiner_gets_the_latched_backbone(harness):
    rig = Rig(harness)
    first = rig.feed(ROBOT.cable_lengths(BENT))
    late = Collector(rig.client, Path, 'backbone', LATCHED)
    wait_until(lambda: len(late) > 0, 5.0, 'the latched backbone')
    assert late.last.header.stamp == first.header.stamp


BAD_MEASUREMENTS = [
    (['cable_0', 'cable_1', 'cable_2', 'cable_3'], [0.3, math.nan, 0.3, 0.3], 'positive finite'),
    (['cable_0', 'cable_1', 'cable_2', 'cable_3'], [0.3, 0.0, 0.3, -0.3], 'for cable_1, cable_3'),
    # all four 5 mm too long: the rod would have to stretch, no shape explains it
    (['cable_0', 'cable_1', 'cable_2', 'cable_3'], [0.305] * 4, 'fit no shape: RMS residual 0.00'),
    (['cable_0', 'cable_1', 'cable_2', 'cable_3'], [1000.0] * 4, 'residual 1e+03'),
    (['cable_0', 'cable_1', 'cable_2', 'cable_9'], [0.3] * 4, 'unknown cable name'),
    (['cable_0', 'cable_1', 'cable_2', 'cable_3'], [0.3] * 3, '4 names but 3 positions'),
    (['cable_0', 'cable_1', 'cable_2'], [0.3] * 3, 'missing cable'),
    (['cable_0', 'cable_1', 'cable_2', 'cable_2'], [0.3] * 4, 'repeated'),
]


def test_bad_measurements_are_rejected_and_the_last_good_state_stays(harness):
    rig = Rig(harness)
    good = rig.feed(ROBOT.cable_lengths(BENT))
    for count, (names, lengths, reason) in enumerate(BAD_MEASUREMENTS, 1):
        msg = rig.measurement(lengths, names)
        publish_until(rig.states, msg, lambda: reason in rig.values().get('last_rejection', ''),
                      5.0, 'rejection %d (%s)' % (count, reason))
        assert int(rig.values()['rejected_cable_states']) >= count
    assert rig.backbone.last.header.stamp == good.header.stamp, 'a bad input was published'
    assert rig.values()['tip_position_m'] == '%.5f %.5f %.5f' % tuple(
        pose_xyz(good.poses[-1].pose))
    # The node is still alive and takes the next good measurement (in a new name order).
    order = [3, 1, 0, 2]
    again = rig.feed(np.asarray(ROBOT.cable_lengths(BENT))[order], [NAMES[i] for i in order])
    np.testing.assert_allclose(pose_xyz(again.poses[-1].pose), BENT.tip_position, atol=1e-6)
    assert all(all_finite_path(path) for path in rig.backbone.messages)


def test_tip_wrench_bends_the_backbone_and_expires(harness):
    rig = Rig(harness, tip_wrench_timeout=0.5)
    straight = ROBOT.straight_cable_lengths
    unloaded = pose_xyz(rig.feed(straight).poses[-1].pose)
    for bad, reason in [((math.nan, 0.0, 0.0), 'non-finite'), ((0.1, 0.0, 0.0), 'frame')]:
        msg = WrenchStamped()
        msg.header.frame_id = 'base_link' if reason == 'non-finite' else 'tool0'
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = bad
        publish_until(rig.wrench, msg, lambda: reason in rig.values().get('last_rejection', ''),
                      5.0, 'the tip_wrench rejection (%s)' % reason)
    load = WrenchStamped()
    load.header.frame_id = 'base_link'
    load.wrench.force.x = 0.2
    publish_until(rig.wrench, load, lambda: rig.values().get('tip_force_n', '').startswith('0.2'),
                  5.0, 'the tip load to be used')
    loaded = pose_xyz(rig.feed(straight).poses[-1].pose)
    expected = ROBOT.estimate_shape(straight, tip_force=(0.2, 0.0, 0.0)).shape.tip_position
    np.testing.assert_allclose(loaded, expected, atol=1e-6)
    assert loaded[0] - unloaded[0] > 1e-3, 'a 0.2 N side load moves the tip'
    wait_until(lambda: rig.values().get('tip_wrench_expired') == 'True', 5.0,
               'the tip load estimate to expire')
    np.testing.assert_allclose(pose_xyz(rig.feed(straight).poses[-1].pose), unloaded, atol=1e-6)


INVALID_PARAMETERS = [
    ('path_samples', 1, 'path_samples'),
    ('path_samples', 0, 'path_samples'),
    ('marker_rate', -1.0, 'marker_rate'),
    ('max_residual', math.nan, 'max_residual'),
    ('tip_wrench_timeout', math.inf, 'tip_wrench_timeout'),
    ('robot_file', str(REPO / 'config' / 'jones2009_nitinol_rod.yaml'), 'read-only'),
    ('input_queue_depth', 3, 'read-only'),
    ('path_samples', 'many', 'type'),
]


def test_parameters_are_validated_over_the_parameter_service(harness):
    rig = Rig(harness)
    rig.feed(ROBOT.cable_lengths(BENT))
    client = rig.client.create_client(SetParameters, 'statics/set_parameters')
    assert client.wait_for_service(timeout_sec=10.0)
    for name, value, reason in INVALID_PARAMETERS:
        parameter = Parameter(name, value=value).to_parameter_msg()
        request = SetParameters.Request(parameters=[parameter])
        result = call(client, request, 5.0).results[0]
        assert not result.successful, (name, value)
        assert reason.lower() in result.reason.lower(), (name, value, result.reason)
    assert rig.node.get_parameter('path_samples').value == 20
    request = SetParameters.Request(parameters=[Parameter('path_samples', value=7)
                                                .to_parameter_msg()])
    assert call(client, request, 5.0).results[0].successful
    backbone = rig.feed(ROBOT.cable_lengths(BENT))
    assert len(backbone.poses) == 7
    np.testing.assert_allclose(pose_xyz(backbone.poses[-1].pose), BENT.tip_position, atol=1e-6)
