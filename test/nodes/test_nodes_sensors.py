"""statics with sensors over DDS (issue 35): the fused shape, its covariance, the gate."""
from pathlib import Path as FilePath

from conftest import REPO
from nodes_helpers import LATCHED, Collector, diagnostic_values, publish_until, wait_until
import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402

pytestmark = pytest.mark.ros
SENSOR_ROBOT = REPO / 'config' / 'tendon_robot_sensors.yaml'


def robot_file(tmp_path, correlation_time, covariance=False, frame_id=None):
    """Write the sensor robot with another correlation time (s); return its path.

    ``covariance``: its tip tracker publishes PoseWithCovarianceStamped; ``frame_id``: in that
    frame.
    """
    with open(SENSOR_ROBOT, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    document['model_uncertainty']['correlation_time'] = correlation_time
    tracker = next(s for s in document['sensors'] if s['name'] == 'tip_tracker')
    if covariance:
        tracker['covariance'] = True
    if frame_id:
        tracker['frame_id'] = frame_id
    path = FilePath(tmp_path) / 'robot.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


class Rig:
    """statics with sensors, a client feeding cable_states and a tip tracker."""

    def __init__(self, harness, path, **params):
        self.robot = load_robot(path)
        self.node = harness.add(StaticsNode, robot_file=str(path), max_stamp_offset=1e12,
                                **params)
        client = harness.client()
        self.backbone = Collector(client, Path, 'backbone', LATCHED)
        self.tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
        self.covariance = Collector(client, PoseWithCovarianceStamped, 'tip_pose_covariance',
                                    LATCHED)
        from continuum_statics_interfaces.msg import BackboneEstimate

        self.estimate = Collector(client, BackboneEstimate, 'backbone_estimate', LATCHED)
        self.diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
        self.states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
        self.covariant = self.robot.sensors[0].covariance
        self.tracker = client.create_publisher(
            PoseWithCovarianceStamped if self.covariant else PoseStamped,
            'sensors/tip_tracker', qos_profile_sensor_data)
        self.stamp = 100
        self.lengths = np.array(self.robot.straight_cable_lengths)
        self.lengths[0] -= 0.004
        model = self.robot.without_load_model().with_model_uncertainty(None)
        shape = model.solve_lengths(self.lengths).shape
        self.model_marker = shape.tip_position + shape.tip_rotation @ self.robot.tip_marker

    def feed(self):
        """Publish one measurement until its covariance comes back; return (tip, covariance)."""
        self.stamp += 1
        msg = JointState(name=list(self.robot.cable_names), position=list(self.lengths))
        msg.header.stamp = Time(sec=self.stamp)
        stamp = self.stamp
        publish_until(self.states, msg, lambda: self.covariance.last is not None
                      and self.covariance.last.header.stamp.sec == stamp, 15.0,
                      'the covariance of measurement %d' % stamp)
        last = self.covariance.last
        position = last.pose.pose.position
        return (np.array([position.x, position.y, position.z]),
                np.array(last.pose.covariance).reshape(6, 6))

    def see(self, offset, sigma=None):
        """Send one tracker reading at the model's marker + offset (m), stamped as the next.

        ``sigma`` (m): the noise a PoseWithCovarianceStamped tracker reports with it.
        """
        pose = PoseStamped()
        pose.header.frame_id = self.robot.base_frame_id
        pose.header.stamp = Time(sec=self.stamp + 1)
        point = self.model_marker + np.asarray(offset)
        pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v)
                                                                            for v in point)
        pose.pose.orientation.w = 1.0
        msg = pose
        if self.covariant:
            msg = PoseWithCovarianceStamped(header=pose.header)
            msg.pose.pose = pose.pose
            msg.pose.covariance = (sigma ** 2 * np.eye(6)).ravel().tolist()
        received = self.node._sensors.inbox.records['tip_tracker'].received
        publish_until(self.tracker, msg, lambda: self.node._sensors.inbox.records[
            'tip_tracker'].received > received, 10.0, 'the tracker reading')

    def sensor_value(self):
        found = diagnostic_values(self.diagnostics, '/statics')
        return (found[0].get('sensor_tip_tracker', ''), found[1]) if found else ('', None)


def test_the_fused_tip_follows_the_tracker_and_its_covariance_shrinks(harness, tmp_path):
    rig = Rig(harness, robot_file(tmp_path, 10.0))
    tip, covariance = rig.feed()
    assert np.all(np.isfinite(covariance)) and np.trace(covariance[:3, :3]) > 0.0
    wait_until(lambda: rig.estimate.last is not None, 5.0, 'backbone_estimate')
    estimate = rig.estimate.last
    assert len(estimate.s) == len(estimate.poses) == len(rig.backbone.last.poses)
    assert len(estimate.position_covariance) == 9 * len(estimate.poses)
    assert np.allclose(estimate.position_covariance[:9],  # the base: the offset's alone
                       (5e-4 ** 2 * np.eye(3)).ravel(), rtol=1e-3)
    rig.see([0.002, 0.0, 0.0])
    fused, fused_covariance = rig.feed()
    assert fused[0] - tip[0] > 1e-3  # moved most of the 2 mm towards the tracker
    assert np.trace(fused_covariance[:3, :3]) < 0.3 * np.trace(covariance[:3, :3])
    wait_until(lambda: 'used 1' in rig.sensor_value()[0], 5.0, 'the verdict on diagnostics')


def test_a_biased_tracker_is_set_aside_and_named(harness, tmp_path):
    rig = Rig(harness, robot_file(tmp_path, 10.0))
    tip, _ = rig.feed()
    rig.see([0.03, 0.0, 0.0])
    after, _ = rig.feed()
    assert np.allclose(after, tip, atol=1e-6)  # the shape does not move towards it
    wait_until(lambda: 'set aside 1' in rig.sensor_value()[0], 5.0, 'the set-aside count')
    value, status = rig.sensor_value()
    assert 'chi2' in value and '30.0 mm from the estimate' in value
    assert status.level == b'\x01' and 'tip_tracker set aside' in status.message


def test_a_correction_fades_when_the_tracker_stops(harness, tmp_path):
    rig = Rig(harness, robot_file(tmp_path, 0.5))  # each measurement is 1 s later: 2 tau
    tip, covariance = rig.feed()
    rig.see([0.002, 0.0, 0.0])
    fused, small = rig.feed()
    assert fused[0] - tip[0] > 1e-3
    later = [rig.feed() for _ in range(6)]
    assert np.trace(later[0][1][:3, :3]) > np.trace(small[:3, :3])
    assert np.allclose(later[-1][0], tip, atol=2e-5)  # faded back to the model's
    np.testing.assert_allclose(later[-1][1], covariance, rtol=1e-3, atol=1e-12)


def test_other_nodes_read_only_the_readings_statics_accepted(harness, tmp_path):
    """One judgement: sensors/tip_tracker/accepted carries the used readings, not the biased."""
    from continuum_statics.nodes.sensor_topics import tracker_topic

    rig = Rig(harness, robot_file(tmp_path, 10.0))
    assert tracker_topic(rig.robot) == 'sensors/tip_tracker/accepted'
    client = harness.client('listener')
    accepted = Collector(client, PoseStamped, 'sensors/tip_tracker/accepted',
                         qos_profile_sensor_data)
    rig.feed()
    rig.see([0.002, 0.0, 0.0])
    rig.feed()
    wait_until(lambda: len(accepted) >= 1, 5.0, 'the accepted reading')
    first = len(accepted)
    rig.see([0.03, 0.0, 0.0])
    rig.feed()
    wait_until(lambda: 'set aside 1' in rig.sensor_value()[0], 5.0, 'the biased one set aside')
    assert len(accepted) == first


def test_a_tracker_that_reports_its_covariance_is_weighed_by_it(harness, tmp_path):
    """A PoseWithCovarianceStamped tracker (covariance: true): its own sigma, not the file's."""
    rig = Rig(harness, robot_file(tmp_path, 10.0, covariance=True))
    client = harness.client('listener')
    accepted = Collector(client, PoseStamped, 'sensors/tip_tracker/accepted',
                         qos_profile_sensor_data)
    tip, _ = rig.feed()
    # 30 mm off: set aside at the file's 0.5 mm (test_a_biased_tracker_is_set_aside_and_named),
    # a plausible reading from a device that says it is 30 mm uncertain
    rig.see([0.03, 0.0, 0.0], sigma=0.03)
    after, _ = rig.feed()
    wait_until(lambda: 'used 1' in rig.sensor_value()[0], 5.0, 'the verdict on diagnostics')
    assert 1e-4 < after[0] - tip[0] < 0.03
    wait_until(lambda: len(accepted) >= 1, 5.0, 'the accepted reading, as a PoseStamped')
    assert abs(accepted.last.pose.position.x - (rig.model_marker[0] + 0.03)) < 1e-9


def test_a_second_stream_of_one_sensor_is_named(harness, tmp_path):
    """Issue 43 item 5: two publishers of one sensor were merged reading by reading, unnamed."""
    rig = Rig(harness, robot_file(tmp_path, 10.0))
    rig.feed()
    rig.see([0.0, 0.0, 0.0])
    wait_until(lambda: rig.sensor_value()[1] is not None, 5.0, 'statics diagnostics')
    assert 'publishers' not in rig.sensor_value()[1].message  # one stream: nothing said
    second = harness.client().create_publisher(PoseStamped, 'tip_pose_measured',
                                               qos_profile_sensor_data)

    def named():
        status = rig.sensor_value()[1]
        return status is not None and "sensor 'tip_tracker' has 2 publishers" in status.message

    wait_until(named, 10.0, 'the second stream named on /diagnostics')
    status = rig.sensor_value()[1]
    assert status.level == b'\x01'
    assert 'sensors/tip_tracker: 1, tip_pose_measured: 1' in status.message, status.message
    second.destroy()


def test_a_tracker_in_its_own_frame_is_read_through_tf(harness, tmp_path):
    """Issue 43 item 5: a sensor's frame_id is resolved through /tf.

    Before: a sensor with ``frame_id: mocap`` was refused reading by reading and called silent.
    Now: refused by name until /tf_static connects mocap, then mapped into the base frame,
    fused, and passed on in the base frame.
    """
    from geometry_msgs.msg import TransformStamped
    from tf2_msgs.msg import TFMessage

    from continuum_statics.nodes.qos import TF_STATIC_QOS

    rig = Rig(harness, robot_file(tmp_path, 10.0, frame_id='mocap'))
    client = harness.client('mocap')
    accepted = Collector(client, PoseStamped, 'sensors/tip_tracker/accepted',
                         qos_profile_sensor_data)
    tip, _ = rig.feed()
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    shift = np.array([0.1, -0.2, 0.05])  # mocap's origin in the base frame, m
    seen = rig.model_marker + np.array([0.002, 0.0, 0.0])  # base frame
    reading = PoseStamped()
    reading.header.frame_id = 'mocap'
    p = reading.pose.position
    p.x, p.y, p.z = (float(v) for v in turn.T @ (seen - shift))
    reading.pose.orientation.w = 1.0
    record = rig.node._sensors.inbox.records['tip_tracker']

    def send(until, what):
        reading.header.stamp = Time(sec=rig.stamp + 1)
        publish_until(rig.tracker, reading, until, 10.0, what)

    refused = record.rejected
    send(lambda: record.rejected > refused, 'the reading refused')

    def status():
        found = rig.sensor_value()[1]
        return '' if found is None else found.message

    wait_until(lambda: 'no transform chain' in status(), 5.0, 'the refusal on /diagnostics')
    assert 'silent' not in status()
    static = client.create_publisher(TFMessage, '/tf_static', TF_STATIC_QOS)
    transform = TransformStamped()
    transform.header.frame_id = rig.robot.base_frame_id
    transform.child_frame_id = 'mocap'
    transform.transform.translation.x, transform.transform.translation.y, \
        transform.transform.translation.z = (float(v) for v in shift)
    transform.transform.rotation.z = transform.transform.rotation.w = float(np.sqrt(0.5))
    static.publish(TFMessage(transforms=[transform]))
    received = record.received
    send(lambda: record.received > received, 'the reading taken')
    fused, _ = rig.feed()
    assert fused[0] - tip[0] > 1e-3  # moved most of the 2 mm towards the tracker, along base x
    assert abs(fused[1] - tip[1]) < 2e-4
    wait_until(lambda: len(accepted) >= 1, 5.0, 'the accepted reading')
    passed = accepted.last
    assert passed.header.frame_id == rig.robot.base_frame_id
    position = passed.pose.position
    np.testing.assert_allclose([position.x, position.y, position.z], seen, atol=1e-9)


def test_the_files_load_model_is_estimated_with_the_shape_and_published(harness, tmp_path):
    """Issue 43 item 1: statics publishes tip_wrench_estimate and tip_contact from its state.

    A push of 0.3 N along x (load_model 'direction') moves the tracked tip 19 mm: the first
    reading gives the push, and contact; the push gone, the first reading is held (the load is
    known now), the second that agrees takes it back.
    """
    from geometry_msgs.msg import WrenchStamped
    from std_msgs.msg import Bool

    document = yaml.safe_load(SENSOR_ROBOT.read_text())
    document.update(load_model='direction', load_direction=[1.0, 0.0, 0.0],
                    model_uncertainty={'tip_force': 1e-3, 'base_position': 1e-5,
                                       'correlation_time': 10.0})
    path = FilePath(tmp_path) / 'robot.yaml'
    path.write_text(yaml.safe_dump(document))
    rig = Rig(harness, path, contact_threshold=0.05, contact_min_time=0.0)
    client = harness.client('load_listener')
    wrench = Collector(client, WrenchStamped, 'tip_wrench_estimate', 10)
    contact = Collector(client, Bool, 'tip_contact', LATCHED)
    model = rig.robot.without_load_model().with_model_uncertainty(None)
    pushed = model.solve_lengths(rig.lengths, tip_force=(0.3, 0.0, 0.0)).shape
    push = pushed.tip_position + pushed.tip_rotation @ rig.robot.tip_marker - rig.model_marker
    assert np.linalg.norm(push) > 0.015
    rig.feed()
    wait_until(lambda: wrench.last is not None, 5.0, 'tip_wrench_estimate')
    assert abs(wrench.last.wrench.force.x) < 0.01 and wrench.last.header.frame_id == 'base_link'
    wait_until(lambda: contact.last is not None and not contact.last.data, 5.0, 'no contact')
    rig.see(push)  # the load still at its prior (nothing seen yet): one reading finds it
    rig.feed()
    wait_until(lambda: wrench.last.header.stamp.sec == rig.stamp, 5.0, 'the pushed estimate')
    assert abs(wrench.last.wrench.force.x - 0.3) < 0.01
    assert wrench.last.wrench.force.y == wrench.last.wrench.force.z == 0.0
    wait_until(lambda: contact.last.data, 5.0, 'tip_contact true')
    wait_until(lambda: diagnostic_values(rig.diagnostics, '/statics') is not None and
               'in_contact' in diagnostic_values(rig.diagnostics, '/statics')[0], 5.0,
               'the load on diagnostics')
    rig.see([0.0, 0.0, 0.0])  # a load known to 8 mN: a new one is held for one reading
    rig.feed()
    wait_until(lambda: 'a new tip load if the next reading agrees' in rig.sensor_value()[0],
               5.0, 'the first reading held')
    assert contact.last.data
    rig.see([0.0, 0.0, 0.0])
    rig.feed()
    wait_until(lambda: wrench.last.header.stamp.sec == rig.stamp, 5.0, 'the released estimate')
    assert abs(wrench.last.wrench.force.x) < 0.01
    wait_until(lambda: not contact.last.data, 5.0, 'tip_contact false')
