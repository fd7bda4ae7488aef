"""Issue 26: the robot's frames on /tf, as every ROS user expects.

Over DDS: the transform base -> tip equals ``tip_pose`` (same stamp), the section frames sit on the
shape of the measured lengths at the section ends (the forward tension solve that made the
lengths is the truth), /tf stays absolute in a namespace and follows a remap. Without DDS: the
CDR template deserializes to the same message as rclpy's serialization.
"""
from conftest import REPO
from nodes_helpers import LATCHED, Collector, pose_xyz, publish_until, wait_until
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.core.rod.rotations import quaternion_to_rotation
from continuum_statics.nodes.tf_frames import FramePoses, frames

rclpy = pytest.importorskip('rclpy')
TFMessage = pytest.importorskip('tf2_msgs.msg').TFMessage
from geometry_msgs.msg import PoseStamped, TransformStamped  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics.nodes.pose_encoder import TransformEncoder  # noqa: E402
from continuum_statics.nodes.qos import TF_QOS  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402

THREE_FILE = str(REPO / 'config' / 'three_section_robot.yaml')
THREE = load_robot(THREE_FILE)


def transforms_by_child(msg):
    return {t.child_frame_id: t for t in msg.transforms}


def translation(transform):
    t = transform.transform.translation
    return np.array([t.x, t.y, t.z])


def rotation(quaternion):
    return quaternion_to_rotation(np.array([quaternion.x, quaternion.y, quaternion.z,
                                            quaternion.w]))


def stamp_ns(header):
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


# -- without DDS ------------------------------------------------------------------------------
def test_the_tf_template_serializes_like_rclpy():
    encoder = TransformEncoder('base_link', ['robot_tip', 'robot_section_0'])
    translations = np.array([[0.01, -0.02, 0.3], [0.0, 0.001, 0.15]])
    quaternions = np.array([[0.0, 0.1, 0.0, np.sqrt(0.99)], [0.0, 0.0, 0.0, 1.0]])
    expected = TFMessage()
    for child, t, q in zip(encoder.children, translations, quaternions):
        transform = TransformStamped(child_frame_id=child)
        transform.header.frame_id = 'base_link'
        transform.header.stamp.sec, transform.header.stamp.nanosec = 1700000000, 123456789
        v, r = transform.transform.translation, transform.transform.rotation
        v.x, v.y, v.z = (float(x) for x in t)
        r.x, r.y, r.z, r.w = (float(x) for x in q)
        expected.transforms.append(transform)
    data = encoder.encode(1700000000, 123456789, translations, quaternions)
    # rclpy's padding bytes are not zeroed: compare the message and the size
    assert deserialize_message(data, TFMessage) == expected
    assert len(data) == len(serialize_message(expected))
    with pytest.raises(ValueError, match='non-finite'):
        encoder.encode(0, 0, translations * np.nan, quaternions)


def test_frames_are_the_tip_and_section_ends_on_the_shape():
    names, arc_lengths = frames(THREE, disks=True)
    ends = [float(section.guides[-1]) for section in THREE.sections]
    assert names[:4] == ('%s_tip' % THREE.name, '%s_section_0' % THREE.name,
                         '%s_section_1' % THREE.name, '%s_section_2' % THREE.name)
    np.testing.assert_allclose(arc_lengths[:4], [THREE.length] + ends)
    assert len(names) == 4 + len(THREE.guides)
    shape = THREE.solve_tensions(np.linspace(0.0, 2.0, len(THREE.cable_names)))
    positions, quaternions = FramePoses(arc_lengths).of(shape)
    np.testing.assert_allclose(positions[0], shape.tip_position, atol=1e-12)
    for k, end in enumerate(ends):  # the guide disks are nodes of the integration grid
        node = int(np.argmin(np.abs(shape.s - end)))
        assert abs(shape.s[node] - end) < 1e-12
        np.testing.assert_allclose(positions[1 + k], shape.positions[node], atol=1e-12)
        np.testing.assert_allclose(quaternion_to_rotation(quaternions[1 + k]),
                                   shape.rotations[node], atol=1e-12)


# -- over DDS ---------------------------------------------------------------------------------
def bent_lengths():
    """Cable lengths of a bent equilibrium (forward tension solve) and that shape."""
    tensions = np.zeros(len(THREE.cable_names))
    tensions[[0, 4, 7]] = (3.0, 1.5, 0.8)
    shape = THREE.solve_tensions(tensions)
    return THREE.cable_lengths(shape), shape


@pytest.mark.ros
def test_tf_tip_equals_tip_pose_and_section_frames_sit_on_the_shape(harness):
    harness.add(StaticsNode, robot_file=THREE_FILE, marker_rate=0.0)
    client = harness.client()
    tf = Collector(client, TFMessage, '/tf', TF_QOS)
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    lengths, truth = bent_lengths()
    state = JointState(name=list(THREE.cable_names), position=[float(v) for v in lengths])
    state.header.stamp.sec, state.header.stamp.nanosec = 1700000000, 5000
    publish_until(states, state, lambda: len(tip) > 0 and len(tf) > 0, 10.0,
                  'tip_pose and /tf')
    wanted = stamp_ns(tip.last.header)
    wait_until(lambda: any(stamp_ns(m.transforms[0].header) == wanted for m in tf.messages),
               5.0, '/tf of the same stamp')
    msg = next(m for m in tf.messages if stamp_ns(m.transforms[0].header) == wanted)
    children = transforms_by_child(msg)
    assert set(children) == {'%s_tip' % THREE.name} | {
        '%s_section_%d' % (THREE.name, k) for k in range(3)}
    assert all(t.header.frame_id == 'base_link' for t in msg.transforms)
    tip_transform = children['%s_tip' % THREE.name]
    assert np.linalg.norm(translation(tip_transform) - pose_xyz(tip.last.pose)) <= 1e-9
    np.testing.assert_allclose(rotation(tip_transform.transform.rotation),
                               rotation(tip.last.pose.orientation), atol=1e-9)
    # the estimate of the lengths is the forward solve's shape (to the estimate's tolerance)
    for k, section in enumerate(THREE.sections):
        node = int(np.argmin(np.abs(truth.s - section.guides[-1])))
        frame = children['%s_section_%d' % (THREE.name, k)]
        assert np.linalg.norm(translation(frame) - truth.positions[node]) <= 1e-5
        np.testing.assert_allclose(rotation(frame.transform.rotation), truth.rotations[node],
                                   atol=1e-3)


@pytest.mark.ros
def test_tf_is_absolute_in_a_namespace_and_follows_a_remap(harness):
    node = StaticsNode(namespace=harness.namespace + '/arm', context=harness.context,
                       cli_args=['--ros-args', '-r', '/tf:=/arm_tf'],
                       parameter_overrides=[Parameter('robot_file', value=THREE_FILE),
                                            Parameter('marker_rate', value=0.0),
                                            Parameter('tip_frame_id', value='arm_tip')])
    harness.nodes.append(node)
    harness._spin(node, 'single')
    client = harness.client()
    remapped = Collector(client, TFMessage, '/arm_tf', TF_QOS)
    plain = Collector(client, TFMessage, '/tf', TF_QOS)
    states = client.create_publisher(JointState, '%s/arm/cable_states' % harness.namespace,
                                     qos_profile_sensor_data)
    lengths, _ = bent_lengths()
    state = JointState(name=list(THREE.cable_names), position=[float(v) for v in lengths])
    publish_until(states, state, lambda: len(remapped) > 3, 10.0, '/tf remapped to /arm_tf')
    assert 'arm_tip' in transforms_by_child(remapped.last)
    assert not any('arm_tip' in transforms_by_child(m) for m in plain.messages)
