"""The one cable_states rule every node applies (CableStatesReader), and one-place helpers.

The helpers replaced per-node copies: header stamps, stamps <-> ns, quaternion -> direction.
"""
import math

import numpy as np
import pytest

pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics.core.rod.rotations import quaternion_direction  # noqa: E402
from continuum_statics.nodes.joint_state_parser import (  # noqa: E402
    CableStatesReader,
    header_stamp_ns,
)
from continuum_statics.nodes.ros_conversions import (  # noqa: E402
    goal_direction,
    ns_to_stamp,
    stamp_ns,
)

NAMES = ('c0', 'c1', 'c2')


def states(names, positions, effort=(), sec=3, nanosec=5):
    msg = JointState(name=list(names), position=list(positions), effort=list(effort))
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
    return serialize_message(msg)


def test_lengths_come_in_robot_order_into_the_given_array():
    reader, out = CableStatesReader(NAMES), np.zeros(3)
    view, lengths = reader.read(states(['c2', 'c0', 'c1'], [0.33, 0.31, 0.32]), out)
    assert lengths is out
    np.testing.assert_array_equal(out, [0.31, 0.32, 0.33])
    assert stamp_ns(view) == 3_000_000_005


@pytest.mark.parametrize('names, positions, reason', [
    (['c0', 'c1'], [0.3, 0.3], 'missing cable'),
    (['c0', 'c1', 'c1'], [0.3, 0.3, 0.3], 'repeated cable names'),
    (['c0', 'c1', 'x'], [0.3, 0.3, 0.3], 'unknown cable name'),
    (['c0', 'c1', 'c2'], [0.3, math.nan, 0.3], 'not a positive finite number for c1'),
    (['c0', 'c1', 'c2'], [0.3, -0.1, 0.3], 'not a positive finite number for c1'),
    (['c0', 'c1', 'c2'], [0.3, 0.3], 'has 3 names but 2 positions'),
])
def test_every_node_refuses_the_same_bad_cable_states(names, positions, reason):
    reader = CableStatesReader(NAMES)
    reader.read(states(NAMES, [0.3, 0.3, 0.3]))  # a good one first: its name index is kept
    with pytest.raises(ValueError, match=reason):
        reader.read(states(names, positions))


def test_effort_is_a_tension_only_when_finite_and_not_negative_for_every_cable():
    reader = CableStatesReader(NAMES)
    view, _ = reader.read(states(['c1', 'c0', 'c2'], [0.3] * 3, [2.0, 1.0, 3.0]))
    tensions, problem = reader.tensions(view)
    np.testing.assert_array_equal(tensions, [1.0, 2.0, 3.0])
    assert problem == ''
    view, _ = reader.read(states(NAMES, [0.3] * 3, [1.0, -0.5, 3.0]))  # a signed current
    tensions, problem = reader.tensions(view)
    assert tensions is None and 'not finite and >= -0.15 N' in problem
    view, _ = reader.read(states(NAMES, [0.3] * 3))
    assert reader.tensions(view) == (None, '')


def test_a_slack_cable_read_a_hair_below_zero_is_a_zero_tension():
    # before: [6.89, 6.55, -1e-12, 0.04] (the simulated driver's slack cable) was a bad message,
    # so tip_load_estimator's estimate went stale and statics flipped to zero load (issue 43)
    reader = CableStatesReader(NAMES)
    view, _ = reader.read(states(NAMES, [0.3] * 3, [6.89, -1e-12, -0.1]))
    tensions, problem = reader.tensions(view)
    assert problem == '' and tensions.tolist() == [6.89, 0.0, 0.0]
    view, _ = reader.read(states(NAMES, [0.3] * 3, [6.89, 0.0, -0.1]))
    assert reader.tensions(view, zero_band=0.05)[0] is None  # beyond a tighter noise's band


def test_the_header_stamp_is_read_from_the_bytes_of_any_stamped_message():
    path = Path()
    path.header.stamp.sec, path.header.stamp.nanosec = 12, 345
    assert header_stamp_ns(serialize_message(path)) == 12_000_000_345
    pose = PoseStamped()
    ns_to_stamp(7_000_000_001, pose.header.stamp)
    assert (pose.header.stamp.sec, pose.header.stamp.nanosec) == (7, 1)
    assert header_stamp_ns(serialize_message(pose)) == 7_000_000_001
    with pytest.raises(ValueError, match='malformed'):
        header_stamp_ns(b'\x00\x01\x00\x00\x01')


def test_a_goal_direction_is_the_z_axis_of_its_orientation():
    half = math.sqrt(0.5)
    np.testing.assert_allclose(quaternion_direction([0.0, half, 0.0, half]), [1.0, 0.0, 0.0],
                               atol=1e-12)  # 90 degrees about y: z turns onto x
    pose = PoseStamped()
    pose.pose.orientation.x, pose.pose.orientation.w = half, half  # about x: z onto -y
    np.testing.assert_allclose(goal_direction(pose, 'test'), [0.0, -1.0, 0.0], atol=1e-12)
