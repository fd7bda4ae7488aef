"""The nodes' obstacle decisions without DDS: merge rules, frame chains, messages, markers.

The ``obstacles`` topic adds to or replaces the robot file's obstacles by name and a message
without names clears the topic's (doc/nodes.md, "Obstacles and contacts"); frames other than
the base frame go through the newest /tf transforms; the messages convert both ways and a bad
entry is refused by name; contacts become a Contacts message (bytes from a template when
empty); statics draws obstacles and contacts and deletes what is gone.
"""
import math
from types import SimpleNamespace

from conftest import REPO
import numpy as np
import pytest

pytest.importorskip('rclpy')
from geometry_msgs.msg import Pose, TransformStamped  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from shape_msgs.msg import SolidPrimitive  # noqa: E402
from std_msgs.msg import Header  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402
from visualization_msgs.msg import Marker  # noqa: E402

from continuum_statics.control.shape_tracking import ShapeTracker, Thresholds  # noqa: E402
from continuum_statics.core.description.obstacles import Obstacle, plane  # noqa: E402
from continuum_statics.core.statics.contact import Contact  # noqa: E402
from continuum_statics.nodes.controller_obstacles import (  # noqa: E402
    ControlParameters,
    check_clearance,
    control_value,
)
from continuum_statics.nodes.obstacle_markers import ObstacleMarkers  # noqa: E402
from continuum_statics.nodes.obstacle_messages import (  # noqa: E402
    EmptyContacts,
    contacts_msg,
    obstacles_from_msg,
    obstacles_msg,
    transforms_of,
)
from continuum_statics.nodes.obstacle_set import FrameTree, ObstacleSet  # noqa: E402
from continuum_statics.tools import doctor_checks as checks  # noqa: E402
from continuum_statics.tools.view_obstacles import contact_segments, obstacle_shapes  # noqa: E402

Contacts = pytest.importorskip('continuum_statics_interfaces.msg').Contacts


def sphere(name, position, radius=0.02, frame_id=None):
    return Obstacle(name, 'sphere', (radius,), np.asarray(position, dtype=float), np.eye(3),
                    frame_id)


FILE = (sphere('ball', (0.05, 0.0, 0.2)), plane('floor', (0.0, 0.0, 1.0), -0.02))


def names(obstacles):
    return [o.name for o in obstacles]


def test_the_topic_adds_replaces_by_name_and_an_empty_message_clears_only_its_own():
    merged = ObstacleSet(FILE, 'base_link')
    tree = FrameTree()
    assert names(merged.resolve(tree)[0]) == ['ball', 'floor']
    merged.apply([sphere('post', (0.0, 0.1, 0.1))])  # adds
    merged.apply([sphere('ball', (0.0, -0.1, 0.1), frame_id='base_link')])  # replaces the file's
    obstacles, unresolved = merged.resolve(tree)
    assert names(obstacles) == ['floor', 'post', 'ball'] and unresolved == {}
    ball = obstacles[2]
    np.testing.assert_allclose(ball.position, (0.0, -0.1, 0.1))
    assert ball.frame_id is None  # the base frame named: the base frame
    merged.apply([sphere('post', (0.0, 0.2, 0.1))])  # a name given again replaces it
    np.testing.assert_allclose(merged.resolve(tree)[0][1].position, (0.0, 0.2, 0.1))
    merged.apply([])  # clears the topic's; the file's ball is back where the file says
    obstacles, _ = merged.resolve(tree)
    assert names(obstacles) == ['ball', 'floor']
    np.testing.assert_allclose(obstacles[0].position, (0.05, 0.0, 0.2))


def test_an_obstacle_in_an_unknown_frame_is_left_out_by_name_with_the_name_it_replaced():
    merged = ObstacleSet(FILE, 'base_link')
    merged.apply([sphere('ball', (0.0, 0.0, 0.5), frame_id='camera'),
                  sphere('post', (0.0, 0.0, 0.1), frame_id='/base_link')])
    assert merged.frames() == {'camera'}
    obstacles, unresolved = merged.resolve(FrameTree())
    assert names(obstacles) == ['floor', 'post'] and unresolved == {'ball': 'camera'}


def random_pose(rng):
    return Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3)


def test_frame_chains_compose_up_to_the_common_ancestor():
    rng = np.random.default_rng(4)
    # world -> base_link -> (robot); world -> rack -> camera: camera to base_link goes through
    # world, up from camera and down to base_link
    poses = {('world', 'base_link'): random_pose(rng), ('world', 'rack'): random_pose(rng),
             ('rack', 'camera'): random_pose(rng), ('base_link', 'tip'): random_pose(rng)}
    tree = FrameTree()
    for (parent, child), (rotation, translation) in poses.items():
        assert tree.set('/' + parent, child, rotation, translation)
    assert not tree.set('world', 'rack', *poses[('world', 'rack')])  # the same again: no news

    def world_from(frame):
        chain = {'base_link': ['base_link'], 'camera': ['camera', 'rack'], 'tip': [
            'tip', 'base_link'], 'world': []}[frame]
        matrix = np.eye(4)
        for child in chain:
            parent = next(p for p, c in poses if c == child)
            step = np.eye(4)
            step[:3, :3], step[:3, 3] = poses[(parent, child)]
            matrix = step @ matrix
        return matrix

    for frame, target in (('camera', 'base_link'), ('base_link', 'camera'), ('tip', 'camera'),
                          ('world', 'tip'), ('camera', 'world'), ('tip', 'tip')):
        rotation, translation = tree.lookup(frame, target)
        expected = np.linalg.inv(world_from(target)) @ world_from(frame)
        np.testing.assert_allclose(rotation, expected[:3, :3], atol=1e-12)
        np.testing.assert_allclose(translation, expected[:3, 3], atol=1e-12)
    assert tree.lookup('lidar', 'base_link') is None
    # an obstacle in the camera frame lands where the chain puts it
    merged = ObstacleSet((), 'base_link')
    merged.apply([sphere('ball', (0.1, 0.2, 0.3), frame_id='camera')])
    (ball,), unresolved = merged.resolve(tree)
    expected = np.linalg.inv(world_from('base_link')) @ world_from('camera') @ [0.1, 0.2, 0.3, 1]
    np.testing.assert_allclose(ball.position, expected[:3], atol=1e-12)
    assert ball.frame_id is None and unresolved == {}


def test_a_loop_in_the_transforms_and_bad_transforms_end_the_chain():
    tree = FrameTree()
    tree.set('a', 'b', np.eye(3), np.zeros(3))
    tree.set('b', 'a', np.eye(3), np.zeros(3))  # a loop: lookups end, nothing hangs
    assert tree.lookup('a', 'base_link') is None
    assert not tree.set('c', 'c', np.eye(3), np.zeros(3))
    assert not tree.set('', 'c', np.eye(3), np.zeros(3))
    assert not tree.set('base_link', 'c', np.eye(3), [math.nan, 0.0, 0.0])
    assert tree.lookup('c', 'base_link') is None


def test_tf_messages_give_their_finite_transforms():
    good = TransformStamped(child_frame_id='camera')
    good.header.frame_id = 'base_link'
    good.transform.translation.x = 0.5
    good.transform.rotation.z, good.transform.rotation.w = math.sin(0.25), math.cos(0.25)
    bad = TransformStamped(child_frame_id='lidar')
    bad.header.frame_id = 'base_link'
    bad.transform.rotation.w = 0.0  # not a rotation
    ((parent, child, rotation, translation),) = transforms_of(TFMessage(transforms=[good, bad]))
    assert (parent, child) == ('base_link', 'camera')
    np.testing.assert_allclose(rotation, Rotation.from_euler('z', 0.5).as_matrix(), atol=1e-12)
    np.testing.assert_allclose(translation, (0.5, 0.0, 0.0))


def test_obstacles_convert_to_the_message_and_back():
    rotation = Rotation.from_euler('xyz', (0.3, -0.2, 1.0)).as_matrix()
    obstacles = [sphere('ball', (0.05, 0.0, 0.2)),
                 Obstacle('post', 'capsule', (0.01, 0.3), np.array([0.08, 0.05, 0.15]),
                          rotation),
                 Obstacle('shelf', 'box', (0.2, 0.3, 0.01), np.array([0.1, 0.0, 0.25]),
                          rotation)]
    msg = obstacles_msg(obstacles, 'camera')
    # a capsule is a CYLINDER [height, radius]; a sphere [radius]; a box its three edges
    assert [p.type for p in msg.primitives] == [SolidPrimitive.SPHERE, SolidPrimitive.CYLINDER,
                                                SolidPrimitive.BOX]
    assert list(msg.primitives[1].dimensions) == [0.3, 0.01]
    back, refused = obstacles_from_msg(msg)
    assert refused == {}
    for got, want in zip(back, obstacles):
        assert (got.name, got.kind, got.size, got.frame_id) == (want.name, want.kind, want.size,
                                                                'camera')
        np.testing.assert_allclose(got.position, want.position)
        np.testing.assert_allclose(got.rotation, want.rotation, atol=1e-12)
    with pytest.raises(ValueError, match='plane'):
        obstacles_msg([FILE[1]], 'base_link')


def entry(msg, name, kind, dimensions, w=1.0, x=0.0):
    msg.names.append(name)
    msg.primitives.append(SolidPrimitive(type=kind, dimensions=dimensions))
    pose = Pose()
    pose.position.x, pose.orientation.w = x, w
    msg.poses.append(pose)


def test_bad_entries_are_refused_by_name_and_the_others_taken():
    msg = obstacles_msg([], 'base_link')
    entry(msg, 'ok', SolidPrimitive.SPHERE, [0.02])
    entry(msg, 'cone', SolidPrimitive.CONE, [0.1, 0.02])
    entry(msg, 'short', SolidPrimitive.BOX, [0.1, 0.1])
    entry(msg, 'flat', SolidPrimitive.CYLINDER, [0.1, 0.0])
    entry(msg, 'huge', SolidPrimitive.SPHERE, [200.0])
    entry(msg, 'turned', SolidPrimitive.SPHERE, [0.02], w=0.5)
    entry(msg, 'lost', SolidPrimitive.SPHERE, [0.02], x=math.inf)
    entry(msg, '', SolidPrimitive.SPHERE, [0.02])
    entry(msg, 'ok', SolidPrimitive.SPHERE, [0.03])
    taken, refused = obstacles_from_msg(msg)
    assert names(taken) == ['ok'] and taken[0].size == (0.02,)
    assert sorted(refused) == ['#7', 'cone', 'flat', 'huge', 'lost', 'ok', 'short', 'turned']
    assert 'primitive type 4' in refused['cone'] and 'needs 3 dimensions' in refused['short']
    assert 'unit quaternion' in refused['turned'] and 'twice' in refused['ok']
    msg.poses.pop()
    with pytest.raises(ValueError, match='differ in length'):
        obstacles_from_msg(msg)


CONTACT = Contact('ball', 0.2031, np.array([-0.0194, 0.0, 0.2003]), np.array([1.0, 0.0, 0.0]),
                  0.0684)


def test_contacts_become_a_message_and_the_empty_one_comes_from_a_template():
    msg = contacts_msg((CONTACT,), 'base_link', 12, 345)
    assert msg.header.frame_id == 'base_link' and (msg.header.stamp.sec,
                                                   msg.header.stamp.nanosec) == (12, 345)
    assert msg.obstacles == ['ball'] and list(msg.s) == [0.2031]
    assert (msg.points[0].x, msg.points[0].z) == (-0.0194, 0.2003)
    assert (msg.normals[0].x, msg.normals[0].y) == (1.0, 0.0)
    assert list(msg.forces) == [0.0684]
    empty = EmptyContacts('base_link')
    for sec, nanosec in ((1, 2), (1_700_000_000, 999_999_999), (-5, 0)):
        got = deserialize_message(empty.encode(sec, nanosec), Contacts)
        assert got == contacts_msg((), 'base_link', sec, nanosec)
    with pytest.raises(ValueError, match='ball'):
        contacts_msg((Contact('ball', math.nan, CONTACT.point, CONTACT.normal, 1.0),),
                     'base_link', 0, 0)


def test_obstacle_and_contact_markers_and_the_deletion_of_what_is_gone():
    drawing = ObstacleMarkers('statics', 0.3, 0.5)  # 0.5 N draws 0.15 m
    header = Header(frame_id='base_link')
    capsule = Obstacle('post', 'capsule', (0.01, 0.3), np.array([0.08, 0.05, 0.15]), np.eye(3))
    markers = drawing.markers(header, FILE + (capsule,), (CONTACT,))
    kinds = [(m.ns, m.type) for m in markers]
    assert kinds == [('statics/obstacles', Marker.SPHERE), ('statics/obstacles', Marker.CUBE)] + [
        ('statics/obstacles', t) for t in (Marker.CYLINDER, Marker.SPHERE, Marker.SPHERE)] + [
        ('statics/contacts', Marker.ARROW)]
    assert all(m.action == Marker.ADD and m.color.a < 1.0 for m in markers[:5])
    assert markers[0].scale.x == 0.04 and markers[2].scale.z == 0.3
    np.testing.assert_allclose([markers[3].pose.position.z, markers[4].pose.position.z],
                               [0.3, 0.0])
    arrow = markers[-1]
    start, end = [np.array([p.x, p.y, p.z]) for p in arrow.points]
    np.testing.assert_allclose(start, CONTACT.point)
    np.testing.assert_allclose(end - start, CONTACT.normal * 0.3 * CONTACT.force)
    # the view reads the same markers back
    shapes = obstacle_shapes(markers)
    assert [s[0] for s in shapes] == [Marker.SPHERE, Marker.CUBE, Marker.CYLINDER,
                                      Marker.SPHERE, Marker.SPHERE]
    np.testing.assert_allclose(contact_segments(markers), [[start, end]])
    # the capsule cleared and the contact let go: their markers are deleted, once
    later = drawing.markers(header, FILE, ())
    assert [(m.ns, m.id, m.action) for m in later[2:]] == [
        ('statics/contacts', 0, Marker.DELETE)] + [
        ('statics/obstacles', k, Marker.DELETE) for k in (2, 3, 4)]
    assert len(drawing.markers(header, FILE, ())) == 2
    drawing.markers(header, (), ())
    assert drawing.markers(header, (), ()) == []  # nothing drawn, nothing to delete


class RecordingRobot:
    """The little a ShapeTracker reads of a robot, recording what estimate_shape is given."""

    sensors = ()
    cable_length_limits = [(0.2, 0.4)] * 4
    solver = SimpleNamespace(max_iterations=50)

    def __init__(self):
        self.calls = []

    def with_solver(self, **_):
        return self

    def estimate_shape(self, lengths, **kwargs):
        self.calls.append(kwargs.get('obstacles'))
        return SimpleNamespace(residual=0.0, converged=True, capped=False, message='',
                               sensors={})


def test_the_tracker_solves_with_the_obstacles_it_is_given():
    robot = RecordingRobot()
    tracker = ShapeTracker(robot, ('a', 'b', 'c', 'd'), 3)
    thresholds = Thresholds.with_noise(1e-4, 2e-3, 1e-3, 0.0)
    tracker.update(np.full(4, 0.3), None, np.zeros(6), thresholds, 10.0)
    tracker.obstacles = FILE[:1]
    tracker.update(np.full(4, 0.3), None, np.zeros(6), thresholds, 10.0)
    assert robot.calls == [None, FILE[:1]]  # None: the robot file's


def test_the_clearance_parameter_reaches_the_run_as_metres_or_none():
    assert check_clearance(-1.0) is None and check_clearance(0.0) is None
    assert 'must be -1' in check_clearance(-0.5)
    assert control_value('clearance', -1.0) is None
    assert control_value('clearance', 0.004) == 0.004
    assert control_value('goal_timeout', -1.0) == -1.0
    params = ControlParameters({'clearance': -1.0, 'max_cable_speed': 0.02})
    assert params['clearance'] is None and params['max_cable_speed'] == 0.02


def test_doctor_names_refused_obstacles_and_an_obstacle_frame_in_the_robot_file(tmp_path):
    status = (checks.WARN, 'obstacle(s) refused: ball',
              {'obstacles_refused': "ball: frame 'camera' has no transform chain to the base "
                                    "frame 'base_link' on /tf or /tf_static"})
    seen = checks.Observation(nodes=('statics',), statuses={'continuum/statics': status})
    (finding,) = checks.check_obstacles(seen)
    assert finding.level == checks.WARN and "ball: frame 'camera'" in finding.message
    assert '/tf_static' in finding.action
    text = (REPO / 'config' / 'tendon_robot.yaml').read_text().replace('solver:', (
        'obstacles:\n  - {name: ball, sphere: {radius: 0.02}, position: [0.05, 0.0, 0.2], '
        'frame_id: camera}\nsolver:'))
    robot_file = tmp_path / 'framed.yaml'
    robot_file.write_text(text)
    from continuum_statics.tools.doctor import observe
    (finding,) = checks.check_robot_file(observe(robot_file=str(robot_file), graph=False))
    assert finding.level == checks.ERROR
    assert "obstacle 'ball' is in frame 'camera'" in finding.message
    assert "give obstacle 'ball' in the base frame 'base_link'" in finding.action
    assert "header.frame_id 'camera'" in finding.action


class RecordingScene:
    """The viser scene calls the view's obstacle drawing makes, recorded."""

    def __init__(self):
        self.calls = []

    def __getattr__(self, method):
        return lambda name, *args, **kwargs: self.calls.append((method, name))


def test_the_view_draws_the_markers_obstacles_and_removes_those_gone():
    from continuum_statics.tools.view_obstacles import ObstacleDrawing

    markers = ObstacleMarkers('statics', 0.3, 0.5).markers(Header(frame_id='base_link'), FILE, (
        CONTACT,))
    scene, drawing = RecordingScene(), ObstacleDrawing()
    drawing.draw(scene, obstacle_shapes(markers), contact_segments(markers))
    assert scene.calls == [('add_icosphere', '/obstacles/0'), ('add_box', '/obstacles/1'),
                           ('add_line_segments', '/contacts')]
    scene.calls.clear()
    drawing.draw(scene, obstacle_shapes(markers[:1]), contact_segments([]))
    assert scene.calls == [('add_icosphere', '/obstacles/0'), ('remove_by_name', '/contacts'),
                           ('remove_by_name', '/obstacles/1')]
