"""Issue 37: ``robot_description`` (URDF of base and disks, links = statics' /tf frames).

The URDF is parsed with ``urdf_parser_py`` (the ROS URDF parser's Python package) on every example
robot; over DDS a late subscriber gets it latched from statics and every link but the base is a
frame statics puts on /tf; RViz's and Foxglove's configurations are read and checked against it.
"""
import json

from conftest import REPO
from nodes_helpers import LATCHED, Collector, publish_until, wait_until
import numpy as np
import pytest
import yaml

from continuum_statics import load_robot
from continuum_statics.core.rod.rotations import quaternion_to_rotation
from continuum_statics.nodes.robot_description import (
    disk_diameter,
    link_names,
    robot_urdf,
    rotation_to_rpy,
)
from continuum_statics.nodes.tf_frames import frames

URDF = pytest.importorskip('urdf_parser_py.urdf').URDF
ROBOTS = sorted(p.name for p in (REPO / 'config').glob('*.yaml')
                if 'sections' in p.read_text() or 'guides' in p.read_text())


def rpy_matrix(roll, pitch, yaw):
    def axis(k, angle):
        c, s = np.cos(angle), np.sin(angle)
        i, j = [(1, 2), (2, 0), (0, 1)][k]
        m = np.eye(3)
        m[i, i] = m[j, j] = c
        m[i, j], m[j, i] = -s, s
        return m
    return axis(2, yaw) @ axis(1, pitch) @ axis(0, roll)


def test_rpy_reproduces_the_rotation():
    rng = np.random.default_rng(37)
    for _ in range(200):
        q = rng.normal(size=4)
        rotation = quaternion_to_rotation(q / np.linalg.norm(q))
        np.testing.assert_allclose(rpy_matrix(*rotation_to_rpy(rotation)), rotation, atol=1e-9)
    half_turn = rpy_matrix(0.3, np.pi / 2, 0.0)  # gimbal lock
    np.testing.assert_allclose(rpy_matrix(*rotation_to_rpy(half_turn)), half_turn, atol=1e-9)


@pytest.mark.parametrize('disks', [False, True])
@pytest.mark.parametrize('name', ROBOTS)
def test_urdf_parses_with_links_named_as_the_tf_frames(name, disks):
    robot = load_robot(REPO / 'config' / name)
    model = URDF.from_xml_string(robot_urdf(robot, disks=disks))
    tf_children, arc_lengths = frames(robot, '', disks)
    links = [link.name for link in model.links]
    assert links[0] == robot.base_frame_id == model.get_root()
    assert set(links[1:]) <= set(tf_children)
    # each frame once: a guide disk that ends a section is drawn by its section link only
    missing = set(tf_children) - set(links)
    assert len(missing) == (len(robot.sections or [None]) if disks and len(robot.guides) else 0)
    assert all(m[len(robot.name):].startswith('_disk_') for m in missing)
    for joint in model.joints:
        assert joint.type == 'floating' and joint.parent == robot.base_frame_id
    materials = {link.name: link.visual.material.name for link in model.links}
    kind = {n: n[len(robot.name):].split('_')[1] for n in links[1:]}  # tip, section, disk
    assert kind[links[1]] == 'tip' and materials[links[1]] == 'tip'
    sections = [n for n in links if kind.get(n) == 'section']
    assert len(sections) == len(robot.sections or [None])
    assert all(materials[n] == 'end_disk' for n in sections)
    assert all(materials[n] == 'guide_disk' for n in links if kind.get(n) == 'disk')
    assert (list(kind.values()).count('disk') > 0) == (disks and len(robot.guides) > 1)
    for link in model.links[2:]:
        assert link.visual.geometry.radius == pytest.approx(disk_diameter(robot) / 2, rel=1e-8)
    # the clamp sits behind the rod's start, along the base's -z
    clamp = model.links[0].visual
    rotation = np.asarray(robot.base_rotation)
    np.testing.assert_allclose(rpy_matrix(*clamp.origin.rpy), rotation, atol=1e-7)
    behind = np.asarray(clamp.origin.xyz) - np.asarray(robot.base_position)
    assert np.dot(behind, rotation[:, 2]) == pytest.approx(-0.005, abs=1e-9)


def test_passive_rod_is_base_tip_and_one_end_disk():
    robot = load_robot(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    assert link_names(robot) == ('base_link', '%s_tip' % robot.name,
                                 '%s_section_0' % robot.name)


def test_links_follow_the_frame_prefix_of_two_arms_from_one_file():
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    for disks in (False, True):
        plain = link_names(robot, disks=disks)
        arm = link_names(robot, disks=disks, prefix='arm1/')
        assert arm[0] == plain[0] == robot.base_frame_id  # the base frame is not prefixed
        assert arm[1:] == tuple('arm1/' + name for name in plain[1:])
        assert set(arm[1:]) <= set(frames(robot, '', disks, 'arm1/')[0])
        urdf = URDF.from_xml_string(robot_urdf(robot, disks=disks, prefix='arm1/'))
        materials = {link.name: link.visual.material.name for link in urdf.links}
        assert materials['arm1/%s_section_1' % robot.name] == 'end_disk'


def test_rviz_config_shows_the_description_from_the_latched_topic():
    config = yaml.safe_load((REPO / 'config' / 'continuum_robot.rviz').read_text())
    displays = {d['Class']: d for d in config['Visualization Manager']['Displays']}
    model = displays['rviz_default_plugins/RobotModel']
    assert model['Enabled'] and model['Visual Enabled']
    assert model['Description Source'] == 'Topic'
    topic = model['Description Topic']
    assert topic['Value'] == 'robot_description'  # relative: the robot's namespace
    assert topic['Durability Policy'] == 'Transient Local'
    assert topic['Reliability Policy'] == 'Reliable'
    assert model['TF Prefix'] == ''  # links are the /tf frames as statics names them


def test_foxglove_layout_shows_backbone_markers_description_and_plots():
    layout = json.loads((REPO / 'config' / 'continuum_robot.foxglove.json').read_text())
    panels = layout['configById']
    three_d = next(v for k, v in panels.items() if k.startswith('3D!'))
    urdf_layers = [layer for layer in three_d['layers'].values()
                   if layer['layerId'] == 'foxglove.Urdf']
    assert urdf_layers == [dict(urdf_layers[0], sourceType='topic',
                                topic='/continuum/robot_description')]
    assert three_d['topics']['/continuum/backbone']['visible']
    assert three_d['topics']['/continuum/backbone_markers']['visible']
    assert three_d['followTf'] == 'base_link'
    plots = [v for k, v in panels.items() if k.startswith('Plot!')]
    paths = [p['value'] for plot in plots for p in plot['paths']]
    assert any(p.startswith('/continuum/cable_states.position[') for p in paths)
    assert any(p.startswith('/continuum/cable_commands.position[') for p in paths)
    assert '/continuum/move_tip/_action/feedback.feedback.distance' in paths
    # every panel of the config is placed in the layout tree
    def leaves(node):
        return [node] if isinstance(node, str) else leaves(node['first']) + leaves(node['second'])
    assert sorted(leaves(layout['layout'])) == sorted(panels)
    assert "glob('config/*.json')" in (REPO / 'setup.py').read_text()


@pytest.mark.ros
def test_statics_publishes_the_description_latched_and_its_links_are_on_tf(harness):
    pytest.importorskip('rclpy')
    TFMessage = pytest.importorskip('tf2_msgs.msg').TFMessage
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String

    from continuum_statics.nodes.qos import TF_QOS
    from continuum_statics.nodes.statics_node import StaticsNode

    robot_file = str(REPO / 'config' / 'two_section_robot.yaml')
    robot = load_robot(robot_file)
    statics = harness.add(StaticsNode, robot_file=robot_file, marker_rate=0.0, tf_disks=True)
    client = harness.client()
    # a late joiner: subscribed after statics published its one message
    wait_until(lambda: statics.count_publishers(statics.get_namespace() + '/robot_description')
               >= 1, 10.0, 'the robot_description publisher')
    description = Collector(client, String, 'robot_description', LATCHED)
    wait_until(lambda: len(description) > 0, 10.0, 'the latched robot_description')
    model = URDF.from_xml_string(description.last.data)
    assert model.name == robot.name
    tf = Collector(client, TFMessage, '/tf', TF_QOS)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    state = JointState(name=list(robot.cable_names),
                       position=[float(v) for v in robot.straight_cable_lengths])
    publish_until(states, state, lambda: len(tf) > 0, 10.0, '/tf')
    on_tf = {t.child_frame_id for t in tf.last.transforms}
    parents = {t.header.frame_id for t in tf.last.transforms}
    links = {link.name for link in model.links}
    assert parents == {model.get_root()}
    assert links - {model.get_root()} <= on_tf
    assert len(links) == len(on_tf) + 1 - len(robot.sections)  # end disks drawn once
    assert len(description) == 1
