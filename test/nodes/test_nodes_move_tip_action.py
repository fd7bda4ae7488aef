"""The move_tip action (continuum_statics_interfaces/action/MoveTip) over DDS.

Reached with feedback; cancelled mid-ramp (the cables stop where they are); pre-empted by a newer
goal; a goal out of reach answered with the reason; stopped by an obstacle published in its
way. The interfaces package is built into the venv by scripts/build_interfaces.sh (Kilted and
Jazzy alike).
"""
import time

from conftest import REPO
from nodes_helpers import LATCHED, RELIABLE, Collector, pose_xyz, wait_until
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.core.description.obstacles import Obstacle  # noqa: E402
from continuum_statics.nodes.action_client import HandoverActionClient  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.obstacle_messages import obstacles_msg  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

MoveTip = pytest.importorskip('continuum_statics_interfaces.action').MoveTip
interfaces = pytest.importorskip('continuum_statics_interfaces.msg')
pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


class Client:
    def __init__(self, harness, **controller):
        harness.add(StaticsNode, marker_rate=0.0)
        harness.add(CableDriverNode)
        harness.add(TipControllerNode, **controller)
        self.node = harness.client()
        self.tip = Collector(self.node, PoseStamped, 'tip_pose', LATCHED)
        self.commands = Collector(self.node, JointState, 'cable_commands', RELIABLE)
        self.action = HandoverActionClient(self.node, MoveTip, 'move_tip')
        assert self.action.wait_for_server(timeout_sec=10.0)
        wait_until(lambda: self.tip.last is not None, 10.0, 'the first tip pose')
        self.feedback = []

    def send(self, position, tolerance=1e-3):
        goal = MoveTip.Goal(tolerance=float(tolerance))
        goal.target.header.frame_id = 'base_link'
        p = goal.target.pose.position
        p.x, p.y, p.z = (float(v) for v in position)
        goal.target.pose.orientation.w = 1.0
        future = self.action.send_goal_async(goal, feedback_callback=self.feedback.append)
        wait_until(future.done, 10.0, 'the goal accepted')
        handle = future.result()
        assert handle.accepted
        return handle

    @staticmethod
    def result(handle, timeout=30.0):
        future = handle.get_result_async()
        wait_until(future.done, timeout, 'the result')
        return future.result()


def test_a_goal_is_reached_with_feedback_and_answered_with_the_backbone(harness):
    client = Client(harness)
    goal = ROBOT.solve_ivp([2.0, -1.0, 0.0]).tip_position
    answer = Client.result(client.send(goal))
    assert answer.status == 4, answer  # SUCCEEDED
    result = answer.result
    assert result.reached and result.error <= 1e-3, result.message
    assert np.linalg.norm(pose_xyz(result.backbone.poses[-1].pose) - goal) <= 1e-3
    phases = {f.feedback.phase for f in client.feedback}
    assert 'ramp' in phases, phases
    distances = [f.feedback.distance for f in client.feedback if f.feedback.distance >= 0]
    assert distances and distances[0] > distances[-1]


def test_a_cancelled_goal_stops_the_cables_where_they_are(harness):
    client = Client(harness, max_cable_speed=0.005)  # a slow ramp, to cancel in the middle
    goal = ROBOT.solve_ivp([3.0, 0.0, 0.0]).tip_position
    handle = client.send(goal)
    wait_until(lambda: len(client.commands) >= 10, 10.0, 'the ramp under way')
    cancel = handle.cancel_goal_async()
    wait_until(cancel.done, 10.0, 'the cancel answered')
    answer = Client.result(handle)
    assert answer.status == 5, answer  # CANCELED
    assert not answer.result.reached and 'cancelled' in answer.result.message
    count = len(client.commands)
    time.sleep(0.3)  # nothing more is commanded after a cancel
    assert len(client.commands) <= count + 1
    assert np.linalg.norm(pose_xyz(client.tip.last.pose) - goal) > 0.01  # stopped short


def test_a_newer_goal_preempts_and_an_unreachable_one_says_why(harness):
    client = Client(harness, max_cable_speed=0.005)
    first = client.send(ROBOT.solve_ivp([3.0, 0.0, 0.0]).tip_position)
    wait_until(lambda: len(client.commands) >= 5, 10.0, 'the first ramp under way')
    second_goal = ROBOT.solve_ivp([0.0, 1.0, 0.0]).tip_position
    second = client.send(second_goal)
    answer = Client.result(first)
    assert answer.status == 6 and 'pre-empted' in answer.result.message, answer  # ABORTED
    assert Client.result(second).result.reached
    far = Client.result(client.send([2.0, 0.0, 0.3]))
    assert far.status == 6 and 'unreachable' in far.result.message, far


def test_an_obstacle_published_on_the_way_stops_the_goal_naming_it(harness):
    """A ball arrives on ``obstacles`` where the bent body will pass, while the goal ramps."""
    client = Client(harness, max_cable_speed=0.005)  # about 3 s to the goal
    shape = ROBOT.solve_ivp([2.0, -1.0, 0.0])
    ball = Obstacle('ball', 'sphere', (0.005,), shape.positions[len(shape.s) // 2], np.eye(3))
    obstacles = client.node.create_publisher(interfaces.Obstacles, 'obstacles', LATCHED)
    handle = client.send(shape.tip_position)
    wait_until(lambda: len(client.commands) >= 10, 10.0, 'the ramp under way')
    obstacles.publish(obstacles_msg([ball], 'base_link'))
    answer = Client.result(handle)
    assert answer.status == 6, answer  # ABORTED
    message = answer.result.message
    assert not answer.result.reached and 'obstacles changed' in message, message
    assert "obstacle 'ball'" in message, message
    count = len(client.commands)
    time.sleep(0.3)  # nothing more is commanded after the stop
    assert len(client.commands) <= count + 1
    assert np.linalg.norm(pose_xyz(client.tip.last.pose) - shape.tip_position) > 0.005
