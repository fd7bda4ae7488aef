"""Node-layer helpers without DDS: message <-> numpy, CDR templates, sampling, parameters."""
import math
import os
import time

from conftest import REPO
import numpy as np
import pytest

pytest.importorskip('rclpy')
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.core.rod.backbone_sampling import BackboneSampler  # noqa: E402
from continuum_statics.core.rod.rotations import (  # noqa: E402
    quaternion_to_rotation,
    rotation_to_quaternion,
)
from continuum_statics.nodes.bringup import parse_args  # noqa: E402
from continuum_statics.nodes.dedicated_intake import IntakeEntry  # noqa: E402
from continuum_statics.nodes.joint_state_parser import parse_joint_state  # noqa: E402
from continuum_statics.nodes.marker_geometry import (  # noqa: E402
    guide_and_cable_points,
    section_layout,
    section_of,
)
from continuum_statics.nodes.markers import BackboneMarkers  # noqa: E402
from continuum_statics.nodes.node_params import ParamSpec, resolve_config_path  # noqa: E402
from continuum_statics.nodes.pose_encoder import PoseSequenceEncoder  # noqa: E402
from continuum_statics.nodes.ros_conversions import (  # noqa: E402
    cable_index,
    fill_path,
    goal_position,
    set_pose,
    tip_load,
)

ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
NAMES = ('cable_0', 'cable_1', 'cable_2', 'cable_3')


@pytest.mark.parametrize('frame', ['base_link', '', 'ab', 'abc', 'frame_with_7', 'ü'])
@pytest.mark.parametrize('count', [1, 2, 3, 20])
def test_pose_encoder_bytes_decode_to_the_same_messages(frame, count):
    rng = np.random.default_rng(count)
    positions, quaternions = rng.normal(size=(count, 3)), rng.normal(size=(count, 4))
    stamp = Time(sec=-7 if count == 2 else 1_800_000_000, nanosec=999_999_999)
    expected = fill_path(Path(), Header(frame_id=frame, stamp=stamp), positions, quaternions)
    data = PoseSequenceEncoder(frame, count).encode(stamp.sec, stamp.nanosec, positions,
                                                    quaternions)
    assert len(data) == len(serialize_message(expected))
    assert deserialize_message(data, Path) == expected
    single = PoseStamped(header=Header(frame_id=frame, stamp=stamp))
    set_pose(single.pose, positions[-1].tolist(), quaternions[-1].tolist())
    data = PoseSequenceEncoder(frame).encode(stamp.sec, stamp.nanosec, positions[-1],
                                             quaternions[-1])
    assert deserialize_message(data, PoseStamped) == single


def test_pose_encoder_refuses_non_finite_values_and_wrong_counts():
    encoder = PoseSequenceEncoder('base_link', 3)
    positions, quaternions = np.zeros((3, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (3, 1))
    good = encoder.encode(1, 2, positions, quaternions)
    positions[1, 2] = math.nan
    with pytest.raises(ValueError, match='non-finite'):
        encoder.encode(1, 2, positions, quaternions)
    with pytest.raises(ValueError, match='expected 3 poses'):
        encoder.encode(1, 2, np.zeros((2, 3)), quaternions[:2])
    assert encoder.encode(1, 2, np.zeros((3, 3)), quaternions) == good


@pytest.mark.parametrize('names, positions, frame', [
    (list(NAMES), [0.3, 0.31, 0.29, 0.3], 'base_link'),
    (['b', 'abc', 'abcd', 'x'], [1.0, 2.0, 3.0, 4.0], ''),
    ([], [], 'a'),
    (['cable_0'], [], 'abc'),
    (['cable_0'], [0.1, 0.2], 'abcd'),
])
def test_joint_state_view_matches_rclpy(names, positions, frame):
    msg = JointState(name=names, position=positions, velocity=[0.5], effort=[1.0, 2.0])
    msg.header.frame_id = frame
    msg.header.stamp = Time(sec=12, nanosec=34)
    data = serialize_message(msg)
    view = parse_joint_state(data)
    assert (view.sec, view.nanosec) == (12, 34)
    assert view.names == names
    np.testing.assert_array_equal(view.position, positions)
    again = parse_joint_state(data, view.name_bytes)
    assert again.name_bytes == view.name_bytes
    np.testing.assert_array_equal(again.position, positions)


def test_joint_state_view_rejects_malformed_data():
    data = serialize_message(JointState(name=list(NAMES), position=[0.3] * 4))
    # truncated, garbage little-endian, and garbage in another encapsulation (rclpy's path)
    for bad in (data[:10], data[:40], b'\x00\x01\x00\x00' + b'\xff' * 40,
                b'\x00\x00\x00\x00' + b'\xff' * 8):
        with pytest.raises(ValueError, match='malformed'):
            parse_joint_state(bad)


@pytest.mark.parametrize('names, require_all, message', [
    (['cable_0', 'cable_x'], False, "unknown cable name 'cable_x'"),
    (['cable_1', 'cable_1'], False, 'repeated cable names cable_1$'),
    (['cable_0', 'cable_1', 'cable_2'], True, 'missing cable.*cable_3'),
    ([], False, 'no cable names'),
])
def test_cable_index_errors_say_what_is_wrong(names, require_all, message):
    with pytest.raises(ValueError, match=message):
        cable_index(names, NAMES, require_all=require_all)


def test_cable_index_maps_any_order():
    index = cable_index(['cable_2', 'cable_0', 'cable_3', 'cable_1'], NAMES)
    values = np.empty(4)
    values[index] = [2.0, 0.0, 3.0, 1.0]
    np.testing.assert_array_equal(values, [0.0, 1.0, 2.0, 3.0])


def _goal(x=0.0, frame='base_link', w=1.0):
    goal = PoseStamped()
    goal.header.frame_id = frame
    goal.pose.position.x, goal.pose.orientation.w = x, w
    return goal


@pytest.mark.parametrize('goal, message', [
    (_goal(math.nan), 'non-finite'),
    (_goal(w=math.inf), 'non-finite'),
    (_goal(frame='map'), "frame 'map'"),
    (_goal(frame=''), "frame ''"),
])
def test_goal_validation(goal, message):
    with pytest.raises(ValueError, match=message):
        goal_position(goal, 'base_link')
    np.testing.assert_array_equal(goal_position(_goal(0.1), 'base_link'), [0.1, 0.0, 0.0])


def test_wrench_validation():
    msg = WrenchStamped()
    msg.header.frame_id = 'base_link'
    msg.wrench.force.z = -0.5
    msg.wrench.torque.x = 0.01
    np.testing.assert_array_equal(tip_load(msg, 'base_link'), [0.0, 0.0, -0.5, 0.01, 0.0, 0.0])
    msg.wrench.torque.y = math.nan
    with pytest.raises(ValueError, match='non-finite'):
        tip_load(msg, 'base_link')
    msg.wrench.torque.y = 0.0
    msg.header.frame_id = 'tool0'
    with pytest.raises(ValueError, match='tool0'):
        tip_load(msg, 'base_link')


@pytest.mark.parametrize('count', [2, 3, 20, 50])
def test_sampler_interpolates_the_backbone(count):
    robot = ROBOT
    shape = robot.solve_bvp(tip_moment=(0.0, 0.1, 0.0))
    sampler = BackboneSampler(shape.s, count)
    points, quats = sampler.sample(shape.positions, shape.rotations)
    s = np.linspace(0.0, robot.length, count)
    assert np.allclose(sampler.s, s)
    np.testing.assert_allclose(points[0], shape.positions[0], atol=1e-15)
    np.testing.assert_allclose(points[-1], shape.tip_position, atol=1e-15)
    np.testing.assert_allclose(quats[-1], rotation_to_quaternion(shape.tip_rotation), atol=1e-12)
    # every sample lies on the polyline through the nodes, at its arc length
    for axis in range(3):
        expected = np.interp(s, shape.s, shape.positions[:, axis])
        np.testing.assert_allclose(points[:, axis], expected, atol=1e-12)
    assert sampler.matches(shape.s, count) and not sampler.matches(shape.s, count + 1)


def test_quaternions_round_trip_on_every_branch():
    rng = np.random.default_rng(3)
    random = np.linalg.qr(rng.normal(size=(500, 3, 3)))[0]
    random *= np.sign(np.linalg.det(random))[:, None, None]  # proper rotations
    half_turns = np.array([np.diag(d) for d in ([1, -1, -1], [-1, 1, -1], [-1, -1, 1])],
                          dtype=float)
    rotations = np.concatenate([random, half_turns, np.eye(3)[None]])
    quaternions = rotation_to_quaternion(rotations)
    assert np.all(quaternions[:, 3] >= 0.0)
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=1), 1.0, atol=1e-14)
    back = np.array([quaternion_to_rotation(q) for q in quaternions])
    np.testing.assert_allclose(back, rotations, atol=1e-12)


def test_marker_geometry_of_the_straight_rod():
    shape = ROBOT.solve_ivp([0.0, 0.0, 0.0])
    guides, rotations, cables = guide_and_cable_points(
        shape.s, shape.positions, shape.rotations, ROBOT.guides, ROBOT.cable_offsets)
    np.testing.assert_allclose(guides[:, 2], ROBOT.guides, atol=1e-6)  # own weight shortens it
    np.testing.assert_allclose(guides[:, :2], 0.0, atol=1e-12)
    assert cables.shape == (4, len(ROBOT.guides) + 1, 3)
    np.testing.assert_allclose(cables[0, :, 0], ROBOT.cable_offsets[0][0], atol=1e-12)
    np.testing.assert_allclose(rotations, np.tile(np.eye(3), (len(ROBOT.guides), 1, 1)),
                               atol=1e-12)


def test_markers_are_reused_and_refuse_nan():
    shape = ROBOT.solve_ivp([1.0, 0.0, 0.0])
    guides, rotations, cables = guide_and_cable_points(
        shape.s, shape.positions, shape.rotations, ROBOT.guides, ROBOT.cable_offsets)
    _, positions, quaternions = shape.sample(20)
    markers = BackboneMarkers('robot')
    args = (Header(frame_id='base_link'), positions, quaternions, guides,
            rotation_to_quaternion(rotations), cables)
    first = list(markers.update(*args).markers)
    second = list(markers.update(*args).markers)
    assert [id(m) for m in first] == [id(m) for m in second]
    assert len(first) == 1 + len(ROBOT.guides) + 4 + 1
    assert len({(m.ns, m.id) for m in first}) == len(first)
    bad = positions.copy()
    bad[3, 1] = math.nan
    with pytest.raises(ValueError, match='non-finite'):
        markers.update(args[0], bad, *args[2:])


def test_serialized_markers_are_rclpys_serialization_of_the_same_markers():
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    cable_ends, section_ends = section_layout(robot)
    encoder, reference = BackboneMarkers('robot'), BackboneMarkers('robot')
    for k, (tensions, samples) in enumerate([([0.0, 0.6, 0.0, 0.0, 0.0, 0.4], 9),
                                             ([0.5, 0.0, 0.1, 0.3, 0.0, 0.0], 9),
                                             ([0.2, 0.2, 0.0, 0.0, 0.7, 0.0], 14)]):
        shape = robot.solve_tensions(tensions)
        guides, rotations, cables = guide_and_cable_points(
            shape.s, shape.positions, shape.rotations, robot.guides, robot.hole_offsets,
            cable_ends)
        s, positions, quaternions = shape.sample(samples)
        args = (positions, quaternions, guides, rotation_to_quaternion(rotations), cables,
                section_of(s, section_ends), section_of(cable_ends, section_ends))
        stamp = (1700000000 + k, 123456789 * k)
        encoded = encoder.encode('base_link', *stamp, *args)
        assert encoder._template is not None  # filled in place, not rclpy's serialization
        expected = serialize_message(reference.update(
            Header(frame_id='base_link', stamp=Time(sec=stamp[0], nanosec=stamp[1])), *args))
        # rclpy leaves CDR padding bytes unset: the messages are compared, not the bytes
        decoded = deserialize_message(encoded, MarkerArray)
        assert decoded == deserialize_message(expected, MarkerArray)  # 9 -> 14: a new layout
        assert decoded.markers[-1].header.stamp == Time(sec=stamp[0], nanosec=stamp[1])
    bad = [np.array(c) for c in cables]
    bad[2][1, 0] = math.inf
    with pytest.raises(ValueError, match='non-finite'):
        encoder.encode('base_link', 1, 2, *args[:4], bad, *args[5:])


def test_bringup_splits_its_options_from_the_ros_arguments():
    options, ros_args = parse_args(['--namespace', 'arm', '--ros-args', '-p', 'x:=1'])
    assert options.namespace == 'arm' and options.robot is None and options.driver is None
    assert ros_args == ['--ros-args', '-p', 'x:=1']
    options, ros_args = parse_args([])
    assert options.namespace == 'continuum' and ros_args == []


def test_bringup_leaves_the_load_to_statics_when_the_robot_file_names_a_load_model(
        tmp_path, capsys):
    import yaml

    from continuum_statics.nodes.bringup import wants_load_estimator

    real = REPO / 'config' / 'tendon_robot_real_tendons.yaml'
    assert wants_load_estimator('auto', str(real))  # a tendon model: the estimator node
    document = yaml.safe_load(real.read_text())
    document['load_model'] = 'force'
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(document))
    assert not wants_load_estimator('auto', str(path))  # statics estimates that load
    assert not wants_load_estimator('on', str(path))  # two estimates of one load: refused
    assert 'statics publishes tip_wrench_estimate' in capsys.readouterr().err
    assert not wants_load_estimator('off', str(real))


@pytest.mark.parametrize('spec, value, message', [
    (ParamSpec('rate', 1.0, 'Hz', 0.5, 2.0), 0.1, 'rate must be >= 0.5'),
    (ParamSpec('rate', 1.0, 'Hz', 0.5, 2.0), 3.0, 'rate must be <= 2'),
    (ParamSpec('rate', 1.0, 'Hz', 0.5, 2.0), math.nan, 'finite'),
    (ParamSpec('count', 3, '', 1, 5), 0, 'count must be >= 1'),
    (ParamSpec('name', 'a', '', check=lambda v: None if v else 'empty'), '', 'empty'),
])
def test_parameter_specs_give_reasons(spec, value, message):
    assert message in spec.reason(value)
    assert spec.reason(spec.default) is None


def test_parameter_descriptors_carry_ranges():
    descriptor = ParamSpec('rate', 1.0, 'rate, Hz', 0.5, 2.0, read_only=True).descriptor()
    assert descriptor.read_only and descriptor.description == 'rate, Hz'
    assert descriptor.floating_point_range[0].from_value == 0.5
    assert ParamSpec('n', 3, '', 1, 5).descriptor().integer_range[0].to_value == 5


def test_relative_config_paths_resolve_from_any_directory(tmp_path):
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        assert os.path.samefile(resolve_config_path('config/tendon_robot.yaml'),
                                REPO / 'config' / 'tendon_robot.yaml')
    finally:
        os.chdir(cwd)


def test_intake_counts_lost_and_stale_messages():
    entry = IntakeEntry(subscription=None, callback=None, max_lag=0.01)
    gid = {'data': b'writer-1'}
    for sequence in (1, 2, 5, 6, 9):
        entry.count({'publication_sequence_number': sequence, 'publisher_gid': gid})
    assert (entry.taken, entry.lost) == (5, 4)
    entry.count({'publication_sequence_number': 1, 'publisher_gid': {'data': b'writer-2'}})
    assert entry.lost == 4
    now = time.time_ns()
    assert entry.stale({'received_timestamp': now - 50_000_000})
    assert not entry.stale({'received_timestamp': now})
    assert not IntakeEntry(None, None).stale({'received_timestamp': 1})


def test_each_cable_is_drawn_to_its_end_disk_and_the_tube_coloured_by_section():
    from continuum_statics.nodes.markers import SECTION_COLORS

    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    cable_ends, section_ends = section_layout(robot)
    np.testing.assert_allclose(cable_ends, [0.15] * 3 + [0.30] * 3)
    np.testing.assert_allclose(section_ends, [0.15, 0.30])
    shape = robot.solve_tensions([0.5, 0.0, 0.0, 0.0, 0.3, 0.0])
    guides, rotations, cables = guide_and_cable_points(
        shape.s, shape.positions, shape.rotations, robot.guides, robot.cable_offsets,
        cable_ends)
    assert [len(c) for c in cables] == [7] * 3 + [13] * 3  # base exit + 6 or 12 guides
    # the proximal cables end in the hole of the proximal end disk
    end_disk = list(robot.guides).index(0.15)
    hole = guides[end_disk] + rotations[end_disk] @ robot.cable_offsets[0]
    np.testing.assert_allclose(cables[0][-1], hole, atol=1e-12)
    s = np.linspace(0.0, 0.3, 7)
    np.testing.assert_array_equal(section_of(s, section_ends), [0, 0, 0, 0, 1, 1, 1])
    _, positions, quaternions = shape.sample(7)
    markers = BackboneMarkers('robot').update(
        Header(frame_id='base_link'), positions, quaternions, guides,
        rotation_to_quaternion(rotations), cables, section_of(s, section_ends),
        section_of(cable_ends, section_ends))
    tube = markers.markers[0]
    assert [(c.r, c.g, c.b) for c in tube.colors] == [
        tuple(np.float32(SECTION_COLORS[k][:3])) for k in [0, 0, 0, 0, 1, 1, 1]]
    cable_markers = [m for m in markers.markers if m.ns.endswith('cables')]
    assert cable_markers[0].color != cable_markers[3].color
    assert len(cable_markers[0].points) == 7 and len(cable_markers[3].points) == 13
    passive = load_robot(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    assert section_layout(passive)[0].shape == (0,)


def test_a_tracked_pose_is_read_alike_from_either_message_with_the_devices_sigma():
    from geometry_msgs.msg import PoseWithCovarianceStamped

    from continuum_statics.nodes.ros_conversions import tracked_pose

    plain = PoseStamped()
    plain.header.frame_id = ''  # an empty frame id is the base frame
    plain.header.stamp.sec, plain.header.stamp.nanosec = 3, 5
    plain.pose.position.x, plain.pose.position.y, plain.pose.position.z = 0.01, 0.02, 0.3
    plain.pose.orientation.w = 1.0
    position, rotation, stamp, sigma = tracked_pose(plain, 'base_link', use_rotation=True)
    assert position.tolist() == [0.01, 0.02, 0.3] and stamp == 3_000_000_005 and sigma is None
    assert np.array_equal(rotation, np.eye(3))
    covariant = PoseWithCovarianceStamped(header=plain.header)
    covariant.pose.pose = plain.pose
    covariance = np.zeros(36)
    covariance[[0, 7, 14]] = 1e-6, 4e-6, 2.5e-7  # m^2: the largest sigma is 2 mm
    covariant.pose.covariance = covariance.tolist()
    again = tracked_pose(covariant, 'base_link')
    assert again[0].tolist() == position.tolist() and again[2] == stamp
    assert again[3] == pytest.approx(2e-3)
    covariance[7] = 0.0  # a device that sends no covariance: the configured noise
    covariant.pose.covariance = covariance.tolist()
    assert tracked_pose(covariant, 'base_link')[3] is None
    plain.header.frame_id = 'tracker'
    with pytest.raises(ValueError, match="frame 'tracker' is not the base frame 'base_link'"):
        tracked_pose(plain, 'base_link')
