"""Issue 44 item 7: a ``tip_frame_id`` naming another of statics' frames is refused at start.

``tip_frame_id:=base_link`` made the tip a second ``base_link``: a URDF with two ``base_link``
links (no root, urdf_parser_py refuses it) and a /tf transform from base_link to itself.
"""
from conftest import REPO
import pytest

from continuum_statics import load_robot
from continuum_statics.nodes.robot_description import link_names, robot_urdf
from continuum_statics.nodes.tf_frames import frames

ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


def test_tip_frame_id_equal_to_the_base_frame_is_refused_naming_both():
    assert ROBOT.base_frame_id == 'base_link'
    with pytest.raises(ValueError) as refused:
        robot_urdf(ROBOT, 'base_link')
    # before: a URDF with two <link name="base_link"> (urdf_parser_py: "No roots detected")
    text = str(refused.value)
    assert "tip_frame_id 'base_link'" in text and 'base.frame_id' in text
    assert "'%s_tip'" % ROBOT.name in text  # what to use instead


@pytest.mark.parametrize('clash, disks, role', [
    ('_section_0', False, "section 0's end-disk frame"),
    ('_disk_2', True, "guide disk 2's frame (tf_disks)"),
])
def test_tip_frame_id_equal_to_a_disk_frame_is_refused(clash, disks, role):
    with pytest.raises(ValueError, match="tip_frame_id '%s%s'.*%s" % (
            ROBOT.name, clash, role.replace('(', r'\(').replace(')', r'\)'))):
        frames(ROBOT, ROBOT.name + clash, disks)
    # before: frames() returned ('..._section_0', '..._section_0'): one child published twice


def test_the_default_and_distinct_tip_frames_still_work():
    names, _ = frames(ROBOT)
    assert names[0] == '%s_tip' % ROBOT.name
    assert link_names(ROBOT, 'arm_tip')[:2] == ('base_link', 'arm_tip')
    # a disk frame not published (tf_disks off) is free, and a prefix separates the base's name
    assert frames(ROBOT, ROBOT.name + '_disk_2')[0][0] == ROBOT.name + '_disk_2'
    assert frames(ROBOT, 'base_link', prefix='arm1/')[0][0] == 'arm1/base_link'


@pytest.mark.ros
def test_statics_with_tip_frame_id_base_link_does_not_start(harness):
    from continuum_statics.nodes.statics_node import StaticsNode

    with pytest.raises(ValueError, match="both the base frame .* and the tip frame "
                       r"\(tip_frame_id 'base_link'\)"):
        harness.add(StaticsNode, tip_frame_id='base_link')
    # before: statics started and published the invalid URDF on robot_description
    harness.add(StaticsNode)  # the default still starts
