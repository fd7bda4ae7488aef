"""tip_controller with statics and the simulated driver, over DDS in one process."""
import math
import time

from conftest import REPO
from nodes_helpers import (
    LATCHED,
    RELIABLE,
    Collector,
    call,
    diagnostic_values,
    pose_xyz,
    publish_until,
    wait_until,
)
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.core.rod.rotations import (  # noqa: E402
    quaternion_to_rotation,
    rotation_to_quaternion,
)
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


def reachable(ux, uy):
    return ROBOT.solve_ivp([ux, uy, 0.0]).tip_position.copy()


class Stack:
    """The three nodes plus a client with the tip_goal service and a tip_pose collector."""

    def __init__(self, harness, statics=(), driver=(), **controller_overrides):
        harness.add(StaticsNode, marker_rate=0.0, **dict(statics))
        harness.add(CableDriverNode, **dict(driver))
        self.controller = harness.add(TipControllerNode, **controller_overrides)
        self.client = harness.client()
        self.tip = Collector(self.client, PoseStamped, 'tip_pose', LATCHED)
        self.diagnostics = Collector(self.client, DiagnosticArray, '/diagnostics', 10)
        self.service = self.client.create_client(GetPlan, 'tip_goal')
        assert self.service.wait_for_service(timeout_sec=10.0)
        wait_until(lambda: self.tip.last is not None, 10.0, 'the first tip pose')
        # The controller needs state before it accepts goals.
        wait_until(lambda: (diagnostic_values(self.diagnostics, 'tip_controller') or ({},))[0]
                   .get('have_tip_pose') == 'True', 10.0, 'the controller to hear tip_pose')

    @staticmethod
    def request(position, tolerance=1e-3, frame='base_link'):
        request = GetPlan.Request(tolerance=float(tolerance))
        request.goal.header.frame_id = frame
        p = request.goal.pose.position
        p.x, p.y, p.z = (float(v) for v in position)
        request.goal.pose.orientation.w = 1.0
        return request

    def values(self):
        found = diagnostic_values(self.diagnostics, 'tip_controller')
        return found[0] if found else {}


def test_reachable_goal_is_reached_and_answered_with_the_backbone(harness):
    stack = Stack(harness)
    goal = reachable(2.0, -1.0)
    plan = call(stack.service, stack.request(goal, 1e-3), 30.0).plan
    assert len(plan.poses) == 20
    assert plan.header.frame_id == 'base_link'
    tip = pose_xyz(plan.poses[-1].pose)
    assert np.linalg.norm(tip - goal) <= 1e-3
    # The measured tip stays there after the goal ended (the driver holds the cables): the
    # next 50 tip poses (~0.25 s of measurements) are all within the tolerance.
    seen = len(stack.tip)
    wait_until(lambda: len(stack.tip) >= seen + 50, 10.0, '50 more tip poses')
    assert all(np.linalg.norm(pose_xyz(m.pose) - goal) <= 1e-3
               for m in list(stack.tip.messages)[seen:])
    wait_until(lambda: stack.values().get('goals_reached') == '1', 5.0, 'the count')


BAD_GOALS = [
    ((math.nan, 0.0, 0.25), 1e-3, 'base_link', 'non-finite'),
    ((0.0, math.inf, 0.25), 1e-3, 'base_link', 'non-finite'),
    (tuple(reachable(1.0, 0.0)), 1e-3, 'world', "frame 'world'"),
    (tuple(reachable(1.0, 0.0)), 1e-3, '', "frame ''"),
    (tuple(reachable(1.0, 0.0)), 0.0, 'base_link', 'tolerance'),
    (tuple(reachable(1.0, 0.0)), -1e-3, 'base_link', 'tolerance'),
    (tuple(reachable(1.0, 0.0)), math.nan, 'base_link', 'tolerance'),
    (tuple(reachable(1.0, 0.0)), 1e-45, 'base_link', 'tolerance'),
    (tuple(reachable(1.0, 0.0)), 1e9, 'base_link', 'tolerance'),
    ((2.0, 0.0, 0.3), 1e-3, 'base_link', 'unreachable'),
]


def test_bad_and_unreachable_goals_are_rejected_at_once(harness):
    # A long goal timeout: an answer within seconds means "rejected at once", not "timed out".
    stack = Stack(harness, goal_timeout=60.0)
    start_tip = pose_xyz(stack.tip.last.pose)
    for count, (position, tolerance, frame, reason) in enumerate(BAD_GOALS, 1):
        started = time.monotonic()
        response = call(stack.service, stack.request(position, tolerance, frame), 10.0)
        assert time.monotonic() - started < 5.0, reason
        assert len(response.plan.poses) == 0, reason
        wait_until(lambda: stack.values().get('goals_rejected') == str(count), 5.0,
                   'rejection %d on diagnostics' % count)
        assert reason in stack.values()['last_outcome'], stack.values()['last_outcome']
    # Nothing moved, and the controller still works.
    np.testing.assert_allclose(pose_xyz(stack.tip.last.pose), start_tip, atol=1e-9)
    goal = reachable(0.0, 1.5)
    plan = call(stack.service, stack.request(goal, 1e-3), 30.0).plan
    assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3


def test_a_dead_driver_fails_goals_with_the_reason(harness):
    # Only the controller: the test publishes one measurement and one tip pose, then nothing,
    # as when the actuator link or statics died.
    harness.add(TipControllerNode, max_state_age=0.05, goal_timeout=60.0)
    client = harness.client()
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    tips = client.create_publisher(PoseStamped, 'tip_pose', LATCHED)
    straight = ROBOT.solve_ivp([0.0, 0.0, 0.0])
    tip = PoseStamped()
    tip.header.frame_id = 'base_link'
    tip.pose.position.x, tip.pose.position.y, tip.pose.position.z = (
        float(v) for v in straight.tip_position)
    tips.publish(tip)
    state = JointState(name=list(ROBOT.cable_names),
                       position=[float(v) for v in ROBOT.cable_lengths(straight)])

    def values():
        found = diagnostic_values(diagnostics, 'tip_controller')
        return found[0] if found else {}

    publish_until(states, state, lambda: values().get('have_cable_states') == 'True'
                  and values().get('have_tip_pose') == 'True', 10.0, 'the controller to hear both')
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    started = time.monotonic()
    response = call(service, Stack.request(reachable(1.0, 0.0), 1e-3), 20.0)
    assert time.monotonic() - started < 5.0, 'a dead link must not wait for the goal timeout'
    assert len(response.plan.poses) == 0
    wait_until(lambda: 'running?' in values().get('last_outcome', ''), 5.0, 'the reason')
    assert 'no cable_states' in values()['last_outcome'] or 'no tip_pose' in values()[
        'last_outcome']


def test_a_new_goal_preempts_the_one_in_progress(harness):
    stack = Stack(harness, max_cable_speed=0.004)  # slow: the first goal is still moving
    first = stack.service.call_async(stack.request(reachable(2.5, 0.0), 1e-3))
    wait_until(lambda: stack.values().get('phase') == 'ramp', 10.0, 'the first goal to move')
    harness.nodes[2].set_parameters([Parameter('max_cable_speed', value=0.05)])
    second_goal = reachable(-1.0, 1.0)
    second = call(stack.service, stack.request(second_goal, 1e-3), 30.0)
    wait_until(first.done, 5.0, 'the pre-empted goal to answer')
    assert len(first.result().plan.poses) == 0
    assert np.linalg.norm(pose_xyz(second.plan.poses[-1].pose) - second_goal) <= 1e-3
    assert stack.values()['goals_preempted'] == '1'


def test_streaming_goals_on_tip_goal_pose(harness):
    stack = Stack(harness, default_tolerance=5e-4)
    goals = stack.client.create_publisher(PoseStamped, 'tip_goal_pose', RELIABLE)
    goal = reachable(-1.5, -1.5)
    msg = PoseStamped()
    msg.header.frame_id = 'base_link'
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in goal)
    msg.pose.orientation.w = 1.0
    publish_until(goals, msg, lambda: stack.values().get('phase') in ('ramp', 'settle'), 10.0,
                  'the streamed goal to start')
    wait_until(lambda: np.linalg.norm(pose_xyz(stack.tip.last.pose) - goal) <= 5e-4
               and stack.values().get('phase') == 'idle', 20.0, 'the tip at the streamed goal')


def test_invalid_parameter_sets_are_rejected_with_a_reason(harness):
    controller = harness.add(TipControllerNode)
    for name, value, reason in [('max_cable_speed', 0.0, 'max_cable_speed'),
                                ('goal_timeout', math.nan, 'goal_timeout'),
                                ('default_tolerance', -1e-3, 'default_tolerance'),
                                ('max_corrections', -1, 'max_corrections'),
                                ('robot_file', '/tmp/x.yaml', 'read-only'),
                                ('control_rate', 'fast', 'type')]:
        result = controller.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful, (name, value)
        assert reason.lower() in result.reason.lower(), (name, result.reason)
    assert controller.set_parameters([Parameter('control_rate', value=100.0)])[0].successful


def test_every_command_while_moving_is_a_shape_of_the_robot(harness):
    stack = Stack(harness)
    commands = Collector(stack.client, JointState, 'cable_commands', RELIABLE)
    # The two goals of issue 7: a straight line in cable space between them is no shape.
    for goal in [(-0.0209, 0.1418, 0.2482), (0.0428, -0.1420, 0.2439)]:
        plan = call(stack.service, stack.request(goal, 1e-3), 30.0).plan
        assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    assert len(commands) > 20
    speed = stack.controller.get_parameter('max_cable_speed').value
    previous, warm = None, None
    for msg in list(commands.messages):
        lengths = np.asarray(msg.position)
        warm = ROBOT.estimate_shape(lengths, warm_start=warm, exact=True)
        assert warm.residual < 2e-6, 'command %s is not a shape (residual %.3g m)' % (
            lengths, warm.residual)
        stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        if previous is not None and stamp > previous[1]:
            # no cable faster than max_cable_speed (with the tick jitter of a 50 Hz timer)
            dt = max(stamp - previous[1], 1.0 / 50.0)
            assert np.max(np.abs(lengths - previous[0])) <= 3.0 * speed * dt + 1e-9
        previous = (lengths, stamp)


def test_from_cable_lengths_that_are_no_shape_the_next_goal_is_reached(harness):
    stack = Stack(harness)
    commands = stack.client.create_publisher(JointState, 'cable_commands', RELIABLE)
    a = ROBOT.cable_lengths(ROBOT.solve_ivp([3.0, 0.0, 0.0]))
    b = ROBOT.cable_lengths(ROBOT.solve_ivp([0.0, 3.0, 0.0]))
    inconsistent = JointState(name=list(ROBOT.cable_names),
                              position=[float(v) for v in 0.5 * (a + b) + [4e-4, 0, 4e-4, 0]])
    assert ROBOT.estimate_shape(inconsistent.position).residual > 1e-4
    states = Collector(stack.client, JointState, 'cable_states', qos_profile_sensor_data)
    publish_until(commands, inconsistent, lambda: states.last is not None and np.max(np.abs(
        np.asarray(states.last.position) - inconsistent.position)) < 1e-6, 10.0,
        'the cables at the hand-made lengths')
    goal = reachable(-1.0, -2.0)
    plan = call(stack.service, stack.request(goal, 1e-3), 30.0).plan
    assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    wait_until(lambda: stack.values().get('moved_onto_model_total') == '1', 5.0,
               'the move back onto the model on diagnostics')


def test_goals_on_a_robot_without_cables_are_rejected_at_once(harness):
    controller = harness.add(TipControllerNode,
                             robot_file=str(REPO / 'config' / 'jones2009_nitinol_rod.yaml'))
    client = harness.client()
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    started = time.monotonic()
    response = call(service, Stack.request((0.3, 0.0, -0.05), 1e-3), 10.0)
    assert time.monotonic() - started < 1.5, 'no wait for a state that never comes'
    assert len(response.plan.poses) == 0
    assert 'robot has no cables' in controller.control.last_outcome


def test_a_float32_tolerance_of_the_rod_length_means_that_length(harness):
    stack = Stack(harness)
    goal = reachable(1.0, 1.0)
    request = stack.request(goal, ROBOT.length)  # 0.3 arrives as 0.30000001192092896
    plan = call(stack.service, request, 30.0).plan
    assert len(plan.poses) == 20, stack.values().get('last_outcome')


@pytest.mark.parametrize('noise, tolerance', [(2e-4, 1e-3), (1e-3, 5e-3)])
def test_goals_are_reached_with_noisy_encoders(harness, noise, tolerance):
    # Tip noise is ~15x the length noise (L / 2r); the controller judges the mean tip.
    stack = Stack(harness, statics={'length_noise_std': noise},
                  driver={'sim.noise_std': noise, 'sim.seed': 7})
    for goal in [reachable(2.0, -1.0), reachable(-1.5, 0.5)]:
        plan = call(stack.service, stack.request(goal, tolerance), 40.0).plan
        assert len(plan.poses) == 20, stack.values().get('last_outcome')
    wait_until(lambda: stack.values().get('goals_reached') == '2', 5.0, 'two goals reached')


def test_a_two_section_robot_reaches_a_goal_with_commands_that_are_shapes(harness):
    robot_file = str(REPO / 'config' / 'two_section_robot.yaml')
    robot = load_robot(robot_file)
    stack = Stack(harness, statics={'robot_file': robot_file},
                  driver={'robot_file': robot_file}, robot_file=robot_file)
    commands = Collector(stack.client, JointState, 'cable_commands', RELIABLE)
    markers = Collector(stack.client, MarkerArray, 'backbone_markers', LATCHED)
    harness.nodes[0].set_parameters([Parameter('marker_rate', value=20.0)])
    shape = robot.solve_tensions([0.0, 0.6, 0.0, 0.0, 0.0, 0.4])
    assert np.all(np.abs(robot.cable_lengths(shape) - robot.straight_cable_lengths) < 0.02)
    goal = shape.tip_position
    plan = call(stack.service, stack.request(goal, 1e-3), 40.0).plan
    assert len(plan.poses) == 20, stack.values().get('last_outcome')
    assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    warm = None
    for msg in list(commands.messages)[::5]:
        assert list(msg.name) == list(robot.cable_names)
        warm = robot.estimate_shape(np.asarray(msg.position), warm_start=warm, exact=True)
        assert warm.residual < 2e-6
    wait_until(lambda: len(markers) > 0, 5.0, 'markers')
    cables = [m for m in markers.last.markers if m.ns.endswith('cables')]
    assert sorted(len(m.points) for m in cables) == [7, 7, 7, 13, 13, 13]


def test_goal_orientation_direction_points_the_tip_of_a_two_section_robot(harness):
    robot_file = str(REPO / 'config' / 'two_section_robot.yaml')
    robot = load_robot(robot_file)
    stack = Stack(harness, statics={'robot_file': robot_file},
                  driver={'robot_file': robot_file}, robot_file=robot_file,
                  goal_orientation='direction')
    # an S-shape: for its tip position alone the controller would pick a tip axis 19 deg away
    shape = robot.solve_tensions([12.0, 0.0, 0.0, 0.0, 8.0, 0.0])
    goal, axis = shape.tip_position, shape.tip_rotation[:, 2]
    request = stack.request(goal, 1e-3)
    q = request.goal.pose.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in rotation_to_quaternion(shape.tip_rotation))
    plan = call(stack.service, request, 40.0).plan
    assert len(plan.poses) == 20, stack.values().get('last_outcome')
    tip = plan.poses[-1].pose
    assert np.linalg.norm(pose_xyz(tip) - goal) <= 1e-3
    reached_axis = quaternion_to_rotation(np.array(
        [tip.orientation.x, tip.orientation.y, tip.orientation.z, tip.orientation.w]))[:, 2]
    assert np.degrees(np.arccos(np.clip(reached_axis @ axis, -1.0, 1.0))) < 1.0
    # the same position with the tip pointing straight down is out of reach: rejected
    request = stack.request(goal, 1e-3)
    request.goal.pose.orientation.x, request.goal.pose.orientation.w = 1.0, 0.0
    assert len(call(stack.service, request, 40.0).plan.poses) == 0
    wait_until(lambda: 'direction' in stack.values().get('last_outcome', ''), 5.0,
               'the rejection, with the direction, on diagnostics')


def test_a_goal_before_any_state_waits_for_it_and_the_controller_says_it_is_starting(harness):
    # The controller alone first: it is up but cannot serve yet, and says so.
    harness.add(TipControllerNode, state_wait=20.0)
    client = harness.client()
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)

    def status():
        found = diagnostic_values(diagnostics, 'tip_controller')
        return (found[0], found[1].message) if found else ({}, '')

    wait_until(lambda: status()[0].get('state') == 'starting', 10.0, 'a starting status')
    assert status()[1].startswith('starting: waiting for state: no cable_states'), status()[1]
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    goal = reachable(1.0, -1.0)
    future = service.call_async(Stack.request(goal, 1e-3))
    time.sleep(0.3)  # the goal is waiting for state now; then statics and the driver start
    assert not future.done(), 'a goal before the first state must wait, not fail at once'
    harness.add(StaticsNode, marker_rate=0.0)
    harness.add(CableDriverNode)
    wait_until(future.done, 30.0, 'the goal to be answered')
    plan = future.result().plan
    assert plan.poses, status()
    assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    wait_until(lambda: status()[0].get('state') == 'ready', 10.0, 'a ready status')


def test_a_click_on_the_workspace_markers_is_a_tip_goal(harness):
    from geometry_msgs.msg import PointStamped

    stack = Stack(harness)
    workspace = Collector(stack.client, MarkerArray, 'workspace_markers', LATCHED)
    wait_until(lambda: workspace.last is not None, 10.0, 'the workspace markers')
    points = workspace.last.markers[0].points
    assert len(points) == 400
    clicked = points[7]  # what RViz's Publish Point tool sends for a click on that sphere
    msg = PointStamped()
    msg.header.frame_id = 'base_link'
    msg.point = clicked
    goal = np.array([clicked.x, clicked.y, clicked.z])
    publisher = stack.client.create_publisher(PointStamped, 'tip_goal_point', RELIABLE)
    publish_until(publisher, msg, lambda: stack.values().get('goals_reached') == '1', 20.0,
                  'the clicked goal reached')
    assert np.linalg.norm(pose_xyz(stack.tip.last.pose) - goal) <= 1e-3


def test_streamed_goals_never_run_in_the_control_timers_callback_group(harness):
    # a streamed goal waits for state (up to state_wait) and solves: in the control timer's
    # group it would stall the running goal's ticks for that long
    controller = harness.add(TipControllerNode)
    control_group = controller.control.timer.callback_group
    groups = {sub.topic_name.rsplit('/', 1)[-1]: sub.callback_group
              for sub in controller.subscriptions}
    services = {srv.srv_name.rsplit('/', 1)[-1]: srv.callback_group
                for srv in controller.services}
    for group in (groups['tip_goal_pose'], groups['tip_goal_point'], services['tip_goal']):
        assert group is not control_group and group is controller.goal_group


def test_a_matched_state_publisher_never_heard_is_named_on_diagnostics(harness):
    # a tip_controller restarted after SIGKILL heard neither state nor goals from its peers
    # (eProsima/Fast-DDS#5053) and said "waiting for state": here the client's publishers of
    # cable_states and tip_pose are matched and send nothing
    harness.add(TipControllerNode)
    client = harness.client()
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    silent = [client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data),
              client.create_publisher(PoseStamped, 'tip_pose', LATCHED)]

    def status():
        found = diagnostic_values(diagnostics, 'tip_controller')
        return found[1] if found else None

    wait_until(lambda: status() is not None and 'restart cable_driver' in status().message,
               15.0, 'the unheard publisher named')
    assert status().level == b'\x01' and 'no cable_states' in status().message
    assert len(silent) == 2
