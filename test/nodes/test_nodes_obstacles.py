"""Obstacles over DDS (in one process, private context): statics rests the rod on them.

- A sphere published on ``obstacles`` into which the straight robot then bends: ``contacts``
  names it with a force, the backbone keeps out of it (body radius, 0.1 mm), and
  ``backbone_markers`` draws the sphere and the contact.
- An obstacle in a frame /tf does not know is refused by name on /diagnostics, and taken once a
  /tf_static transform reaches the base frame.
- tip_controller hands the merged set to its run and its ``clearance`` (-1: the robot file's).
- The simulated driver's real tendons rest on its robot file's ball (``sim/tip_pose_true``):
  statics without the ball is millimetres off that true tip, with it (sent on ``obstacles``)
  within 0.1 mm.
"""
from builtin_interfaces.msg import Time
from conftest import REPO
from nodes_helpers import (
    LATCHED,
    Collector,
    diagnostic_values,
    pose_xyz,
    publish_until,
    wait_until,
)
import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
interfaces = pytest.importorskip('continuum_statics_interfaces.msg')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, TransformStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from tf2_msgs.msg import TFMessage  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.core.description.obstacles import Obstacle  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.obstacle_messages import obstacles_msg  # noqa: E402
from continuum_statics.nodes.qos import TF_STATIC_QOS  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT_FILE = str(REPO / 'config' / 'tendon_robot.yaml')
REAL_FILE = REPO / 'config' / 'tendon_robot_real_tendons.yaml'
ROBOT = load_robot(ROBOT_FILE)
NAMES = list(ROBOT.cable_names)
RADIUS = 0.02
# cable_2 (at -x) pulls 3 N: the free rod's s = 0.2 m passes 1 cm left of the axis; the ball
# sits there, 4 mm into the body's way, so the bent rod rests on it
TENSIONS = np.array([0.0, 0.0, 3.0, 0.0])
BALL = Obstacle('ball', 'sphere', (RADIUS,), np.array([-0.03937, 0.0, 0.1994]), np.eye(3))
RESTING = ROBOT.solve_tensions(TENSIONS, obstacles=(BALL,))
STRAIGHT = ROBOT.solve_tensions(np.zeros(4), obstacles=())


class Rig:
    def __init__(self, harness):
        self.node = harness.add(StaticsNode, robot_file=ROBOT_FILE, max_stamp_offset=1e12,
                                marker_rate=50.0, path_samples=60)
        client = self.client = harness.client()
        self.backbone = Collector(client, Path, 'backbone', LATCHED)
        self.contacts = Collector(client, interfaces.Contacts, 'contacts', LATCHED)
        self.markers = Collector(client, MarkerArray, 'backbone_markers', LATCHED)
        self.diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
        self.states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
        self.obstacles = client.create_publisher(interfaces.Obstacles, 'obstacles', LATCHED)
        self.stamp = 100

    def feed(self, shape, tensions):
        """Publish the lengths (and tensions) of ``shape`` until its backbone comes back."""
        self.stamp += 1
        msg = JointState(name=NAMES, position=ROBOT.cable_lengths(shape).tolist(),
                         effort=[float(t) for t in tensions])
        msg.header.stamp = Time(sec=self.stamp)
        publish_until(self.states, msg, lambda: self.backbone.last is not None
                      and self.backbone.last.header.stamp.sec == self.stamp, 15.0,
                      'the backbone of measurement %d' % self.stamp)
        return self.backbone.last

    def contacts_of(self, stamp):
        wait_until(lambda: any(m.header.stamp == stamp for m in self.contacts.messages), 5.0,
                   'contacts stamped like the backbone')
        return next(m for m in self.contacts.messages if m.header.stamp == stamp)

    def values(self):
        found = diagnostic_values(self.diagnostics, '/statics')
        return found[0] if found else {}


def test_the_rod_bent_into_a_published_sphere_rests_on_it(harness):
    rig = Rig(harness)
    straight = rig.feed(STRAIGHT, np.zeros(4))
    empty = rig.contacts_of(straight.header.stamp)
    assert empty.header.frame_id == 'base_link' and list(empty.obstacles) == []
    assert list(empty.forces) == [] and list(empty.points) == []
    rig.obstacles.publish(obstacles_msg([BALL], 'base_link'))
    wait_until(lambda: rig.values().get('obstacles') == 'ball', 10.0,
               'statics to take the ball')
    backbone = rig.feed(RESTING, TENSIONS)
    contacts = rig.contacts_of(backbone.header.stamp)
    assert list(contacts.obstacles) == ['ball'], contacts
    assert contacts.forces[0] > 0.0 and 0.15 < contacts.s[0] < 0.25
    normal = contacts.normals[0]
    assert normal.x > 0.9  # from the ball (at -x) towards the body
    points = np.array([(p.pose.position.x, p.pose.position.y, p.pose.position.z)
                       for p in backbone.poses])
    gaps = np.linalg.norm(points - BALL.position, axis=1) - RADIUS - ROBOT.body_radius
    assert gaps.min() > -1e-4, gaps.min()
    assert gaps.min() < 1e-3  # it does touch
    wait_until(lambda: rig.markers.last is not None and {'obstacles', 'contacts'} <= {
        m.ns.split('/')[-1] for m in rig.markers.last.markers}, 5.0,
        'the ball and the contact drawn')
    wait_until(lambda: rig.values().get('contacts', '').startswith('ball@'), 5.0,
               'the contact on /diagnostics')
    assert float(rig.values()['contact_force_max_n']) > 0.0


def test_an_obstacle_in_an_unknown_frame_is_refused_by_name_until_tf_reaches_it(harness):
    rig = Rig(harness)
    far = Obstacle('far_ball', 'sphere', (0.01,), np.array([0.0, 0.0, 0.5]), np.eye(3))
    rig.obstacles.publish(obstacles_msg([far], 'camera_mount'))
    wait_until(lambda: 'far_ball' in rig.values().get('obstacles_refused', ''), 10.0,
               'far_ball refused on /diagnostics')
    values = rig.values()
    assert "frame 'camera_mount'" in values['obstacles_refused']
    assert values['obstacles'] == 'none'
    _, status = diagnostic_values(rig.diagnostics, '/statics')
    assert 'far_ball' in status.message
    # the camera's mount on the base arrives: the obstacle is taken, 1 m further along x
    mount = TransformStamped(child_frame_id='camera_mount')
    mount.header.frame_id = 'base_link'
    mount.transform.translation.x = 1.0
    mount.transform.rotation.w = 1.0
    static = rig.client.create_publisher(TFMessage, '/tf_static', TF_STATIC_QOS)
    static.publish(TFMessage(transforms=[mount]))
    wait_until(lambda: rig.values().get('obstacles') == 'far_ball'
               and 'obstacles_refused' not in rig.values(), 10.0, 'far_ball taken')
    (taken,) = rig.node._obstacles.topic.current
    np.testing.assert_allclose(taken.position, (1.0, 0.0, 0.5))
    # cleared by a message without names: no more /tf subscriptions
    rig.obstacles.publish(interfaces.Obstacles())
    wait_until(lambda: rig.values().get('obstacles') == 'none', 10.0, 'the topic cleared')
    assert not rig.node._obstacles.topic.follows_tf


def test_tip_controller_hands_the_obstacles_and_clearance_to_its_run(harness):
    node = harness.add(TipControllerNode, robot_file=ROBOT_FILE)
    client = harness.client()
    publisher = client.create_publisher(interfaces.Obstacles, 'obstacles', LATCHED)
    assert node.control.run.settings.clearance is None  # -1: the robot file's
    publish_until(publisher, obstacles_msg([BALL], 'base_link'),
                  lambda: node.control.run.obstacles is not None, 10.0, 'the run to get the ball')
    (ball,) = node.control.run.obstacles
    assert ball.name == 'ball' and ball.frame_id is None
    np.testing.assert_allclose(ball.position, BALL.position)
    (result,) = node.set_parameters([Parameter('clearance', value=0.004)])
    assert result.successful and node.control.run.settings.clearance == 0.004
    (result,) = node.set_parameters([Parameter('clearance', value=-0.5)])
    assert not result.successful and 'must be -1' in result.reason
    (result,) = node.set_parameters([Parameter('clearance', value=-1.0)])
    assert result.successful and node.control.run.settings.clearance is None


def test_a_passive_rod_sags_onto_a_sphere_published_under_its_tip(harness):
    rod_file = str(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    rod = load_robot(rod_file)
    sagging = rod.solve_bvp()
    under = Obstacle('stone', 'sphere', (RADIUS,), sagging.tip_position - np.array(
        [0.0, 0.0, RADIUS + rod.body_radius - 0.003]), np.eye(3))
    harness.add(StaticsNode, robot_file=rod_file, publish_tf=False)
    client = harness.client()
    contacts = Collector(client, interfaces.Contacts, 'contacts', LATCHED)
    backbone = Collector(client, Path, 'backbone', LATCHED)
    wait_until(lambda: contacts.last is not None, 10.0, 'the free rod and its (no) contacts')
    assert list(contacts.last.obstacles) == []
    publisher = client.create_publisher(interfaces.Obstacles, 'obstacles', LATCHED)
    publisher.publish(obstacles_msg([under], 'base_link'))
    wait_until(lambda: list(contacts.last.obstacles) == ['stone'], 10.0,
               'the rod resting on the stone')
    assert contacts.last.forces[0] > 0.0 and contacts.last.normals[0].z > 0.5
    tip = backbone.last.poses[-1].pose.position
    assert tip.z > sagging.tip_position[2] + 1e-3  # held up by the stone


def test_statics_finds_the_simulated_robot_resting_on_the_drivers_obstacle(harness, tmp_path):
    """The driver's real tendons rest on a ball statics first does not know, then is sent."""
    data = yaml.safe_load(REAL_FILE.read_text())
    data['obstacles'] = [{'name': 'ball', 'sphere': {'radius': RADIUS},
                          'position': BALL.position.tolist()}]
    (tmp_path / 'ball.yaml').write_text(yaml.safe_dump(data))
    real = load_robot(REAL_FILE)
    lengths = real.cable_lengths(real.solve_tensions(TENSIONS))  # s = 0.2 m 4 mm into the ball
    harness.add(StaticsNode, robot_file=str(REAL_FILE), marker_rate=0.0)
    harness.add(CableDriverNode, robot_file=str(tmp_path / 'ball.yaml'))
    client = harness.client()
    truth = Collector(client, PoseStamped, 'sim/tip_pose_true', qos_profile_sensor_data)
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    contacts = Collector(client, interfaces.Contacts, 'contacts', LATCHED)
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    commands = client.create_publisher(JointState, 'cable_commands', 10)
    command = JointState(name=NAMES, position=[float(v) for v in lengths])

    def gap():  # statics' tip from the true one, m, once both have settled on the lengths
        return np.linalg.norm(pose_xyz(tip.last.pose) - pose_xyz(truth.last.pose))

    publish_until(commands, command, lambda: None not in (truth.last, tip.last, states.last)
                  and np.abs(np.subtract(states.last.position, lengths)).max() < 1e-7, 20.0,
                  'the simulated cables at the commanded lengths')
    wait_until(lambda: 2e-3 < gap() < 5e-3, 10.0, 'statics without the ball 2-5 mm off')
    publish_until(client.create_publisher(interfaces.Obstacles, 'obstacles', LATCHED),
                  obstacles_msg([BALL], 'base_link'), lambda: list(contacts.last.obstacles)
                  == ['ball'], 10.0, 'statics to rest the rod on the ball')
    wait_until(lambda: gap() < 1e-4, 10.0, 'statics on the true tip')
    assert contacts.last.forces[0] > 0.0
