"""Issue 23: no client wedges the controller, no bad tracker steers the robot, mistakes answered.

Each DDS test here failed on the code before the fix; the decision logic is also tested without
DDS.
"""
import math
import os
import signal
import subprocess
import sys
import threading
import time

from conftest import REPO
from nodes_helpers import (
    LATCHED,
    RELIABLE,
    Collector,
    call,
    diagnostic_values,
    pose_xyz,
    wait_until,
)
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.control.goal_run import Goal, GoalRun, RunSettings
from continuum_statics.control.handover import Handover
from continuum_statics.control.records import Measurement, TipSample
from continuum_statics.control.teleop import TeleopRun, TeleopSettings, Twist, twist_hold
from continuum_statics.control.tip_source import TipSource, disagreement_bound

TENDON = str(REPO / 'config' / 'tendon_robot.yaml')
ROBOT = load_robot(TENDON)


# -- decision logic, no DDS -----------------------------------------------------------------------
def test_the_later_of_a_goal_and_a_twist_holds_the_handover():
    handover = Handover()
    goal = handover.take('a newer goal')
    twist = handover.take('teleoperation (tip_twist)')
    assert not handover.holds(goal) and handover.holds(twist)
    assert handover.holder == 'teleoperation (tip_twist)'


def sample(position, received=0.0):
    return TipSample(np.asarray(position, dtype=float), 0, received)


def test_a_tracker_beyond_the_bound_is_set_aside_for_the_rest_of_the_goal():
    bound = disagreement_bound(ROBOT.length, 0.0)
    assert bound == pytest.approx(0.03)  # a tenth of the 0.3 m rod
    source = TipSource(bound)
    model = sample([0.0, 0.0, 0.3])
    near = sample([0.01, 0.0, 0.3])
    tip, _, name, warning = source.judged(0.0, near, [near], model, [model], 0.5, True)
    assert tip is near and name == 'tip_pose_measured' and not warning
    far = sample([0.05, 0.0, 0.3])
    tip, _, name, warning = source.judged(0.0, far, [far], model, [model], 0.5, True)
    assert tip is model and name == 'tip_pose'
    assert 'tip_pose_measured is 50.0 mm from the model tip' in warning
    # set aside until the next goal, even when it agrees again
    tip, _, _, warning = source.judged(0.0, near, [near], model, [model], 0.5, True)
    assert tip is model and not warning
    source.reset()
    assert source.judged(0.0, near, [near], model, [model], 0.5, True)[0] is near


def test_a_tracker_reading_is_compared_with_the_model_tip_of_its_own_time():
    # issue 43: the newest reading (0.2 s old while the tip moves 0.2 m/s) lay 40 mm from the
    # newest model tip though 0.5 mm from the one of its time: before, an honest tracker was set
    # aside (74 times in ten minutes of normal use)
    source = TipSource(disagreement_bound(ROBOT.length, 0.0))
    model_tips = [TipSample(np.array([0.2 * t, 0.0, 0.3]), int(t * 1e9), t + 0.001)
                  for t in np.arange(0.0, 1.0, 0.01)]
    reading = TipSample(np.array([0.2 * 0.8 + 5e-4, 0.0, 0.3]), int(0.8e9), 0.85)
    tip, _, name, warning = source.judged(1.0, reading, [reading], model_tips[-1], model_tips,
                                          0.5, True)
    assert name == 'tip_pose_measured' and not warning
    # unstamped: matched by arrival
    unstamped = [TipSample(m.position, 0, m.received) for m in model_tips]
    reading = TipSample(reading.position, 0, 0.811)
    assert source.judged(1.0, reading, [reading], unstamped[-1], unstamped, 0.5,
                         True)[2] == 'tip_pose_measured'
    # a frozen tracker is still set aside: at its own time the model is 40 mm away
    frozen = TipSample(np.array([0.2 * 0.6, 0.0, 0.3]), int(0.8e9), 0.85)
    assert 'tracker set aside' in source.judged(1.0, frozen, [frozen], model_tips[-1],
                                                model_tips, 0.5, True)[3]


def test_a_model_tip_that_lags_the_tracker_is_compared_with_the_reading_of_its_time():
    # normal use under load (benchmarks.soak --normal-use): statics' newest tip_pose 0.3 s
    # behind the tracker while the tip moves 0.1 m/s; before, the newest reading was compared
    # with it (30.6 and 50.7 mm) and an honest tracker set aside twice in ten minutes
    source = TipSource(disagreement_bound(ROBOT.length, 0.0))
    readings = [TipSample(np.array([0.1 * t + 5e-4, 0.0, 0.3]), int(t * 1e9), t + 0.005)
                for t in np.arange(0.0, 1.0, 0.01)]
    model_tips = [TipSample(np.array([0.1 * t, 0.0, 0.3]), int(t * 1e9), t + 0.3)
                  for t in np.arange(0.0, 0.7, 0.05)]
    tip, _, name, warning = source.judged(1.0, readings[-1], readings, model_tips[-1],
                                          model_tips, 0.5, True)
    assert tip is readings[-1] and name == 'tip_pose_measured' and not warning
    # a tracker frozen since 0.3 s: at the model's time it is 35 mm away
    frozen = [TipSample(r.position if r.stamp_ns <= 0.3e9 else readings[30].position,
                        r.stamp_ns, r.received) for r in readings]
    assert 'tracker set aside' in source.judged(1.0, frozen[-1], frozen, model_tips[-1],
                                                model_tips, 0.5, True)[3]
    # nothing of one time to compare (the model 2 s behind, the tracker's history 1 s): trusted
    source.reset()
    late = [TipSample(m.position, m.stamp_ns - int(2e9), m.received) for m in model_tips]
    assert source.judged(1.0, frozen[-1], frozen[-50:], late[-1], late, 0.5,
                         True)[2] == 'tip_pose_measured'


def straight_run_to_a_goal(settings):
    """Return (run, goal, start): a GoalRun from the straight robot towards a bent goal."""
    run = GoalRun(ROBOT, settings)
    position = ROBOT.solve_ivp([2.0, 0.0, 0.0]).tip_position
    start = ROBOT.estimate_shape(ROBOT.straight_cable_lengths)
    plan = run.plan(position, 1e-3, None, ROBOT.straight_cable_lengths, np.zeros(6), True,
                    (start, ROBOT.straight_cable_lengths, start))
    goal = Goal(position=position, tolerance=1e-3, source='test', started=0.0, deadline=1e9)
    run.begin(goal, plan, 0.0)
    return run, goal, start


def test_the_corrections_of_a_goal_add_up_to_at_most_max_correction():
    # a tracker frozen 20 mm from the goal (inside its bound): each correction would add the
    # same 20 mm, so the second one would take the target 40 mm > 30 mm from the goal
    run, goal, _ = straight_run_to_a_goal(RunSettings(max_correction=0.03, settle_time=0.0))
    goal_position = goal.position
    frozen = goal_position + np.array([0.02, 0.0, 0.0])
    now = 0.0
    for _ in range(2000):
        now += 0.02
        commanded = run.commanded.copy()
        measurement = Measurement(commanded, 0, now)
        tips = [sample(frozen, now - 0.001 * k) for k in range(5)]
        run.tick(now, 0.02, measurement, tips[0], tips[::-1], np.zeros(6))
        if goal.done.is_set():
            break
    assert goal.done.is_set() and not goal.reached
    assert run.corrections == 1, goal.reason
    assert 'more than tracker_max_disagreement 30.0 mm' in goal.reason, goal.reason


def test_cables_that_do_not_follow_their_command_are_named_when_the_goal_fails():
    run, goal, start = straight_run_to_a_goal(RunSettings(max_corrections=0, settle_time=0.0))
    still = start.shape.tip_position
    now = 0.0
    for _ in range(2000):  # a driver that never moves: the cables stay straight
        now += 0.02
        measurement = Measurement(ROBOT.straight_cable_lengths, 0, now)
        run.tick(now, 0.02, measurement, sample(still, now), [sample(still, now - 0.01),
                                                            sample(still, now - 0.005),
                                                            sample(still, now)], np.zeros(6))
        if goal.done.is_set():
            break
    assert 'is cable_driver active and following cable_commands?' in goal.reason, goal.reason


def test_a_driver_that_acts_on_commands_late_is_waited_for_before_the_tip_is_judged():
    # seen in CI on a loaded 2-core machine (a fast goal on the simulated rod in motion): the
    # driver moved 0.1-0.3 s after the ramp's command, so within settle_time the gap had not
    # closed, "stopped closing" ended the wait and the tip of the old lengths was judged: a
    # correction of 160-246 mm, the goal refused. A driver 0.3 s late, cables at 0.2 m/s.
    speed, latency, period = 0.2, 0.3, 0.02
    run, goal, start = straight_run_to_a_goal(RunSettings(max_cable_speed=speed,
                                                          settle_time=0.2))
    lengths, commands, tips, warm = ROBOT.straight_cable_lengths.copy(), [], [], None
    now = 0.0
    for _ in range(1000):
        now += period
        late = [c for t, c in commands if t <= now - latency]
        if late:  # the driver follows the command it has at max speed
            lengths = lengths + np.clip(late[-1] - lengths, -speed * period, speed * period)
        warm = ROBOT.estimate_shape(lengths, warm_start=warm)
        tips.append(sample(warm.shape.tip_position, now))
        command = run.tick(now, period, Measurement(lengths.copy(), 0, now), tips[-1],
                           tips[-10:], np.zeros(6))
        if command is not None:
            commands.append((now, command.copy()))
        if goal.done.is_set():
            break
    assert goal.reached, goal.reason
    assert run.corrections == 0 and goal.error < 1e-3, goal.reason


def test_the_tip_stops_within_a_few_message_intervals_after_the_last_twist():
    settings = TeleopSettings(max_tip_speed=0.05, twist_timeout=0.5)
    run = TeleopRun(ROBOT, settings)
    start = ROBOT.estimate_shape(ROBOT.cable_lengths(ROBOT.solve_ivp([2.0, 1.0, 0.0])))
    run.start(start, ROBOT.cable_lengths(start.shape))
    velocity = np.array([0.0, 0.02, 0.0])
    period, now, previous = 0.02, 0.0, None
    for _ in range(10):  # a 50 Hz stream
        hold = twist_hold(previous, now, settings.twist_timeout)
        twist = Twist(velocity, np.zeros(3), now, hold)
        previous = now
        run.tick(now, period, twist, np.zeros(6))
        now += period
    assert hold == pytest.approx(2.5 * period)
    last = run.state.tip_position.copy()
    while run.active:  # no more messages: the dead-man ends the run after twist_timeout
        run.tick(now, period, twist, np.zeros(6))
        now += period
    travel = float(np.linalg.norm(run.state.tip_position - last))
    # before: the last twist drove for the whole twist_timeout (0.5 s x 20 mm/s = 10 mm)
    assert travel <= 0.02 * (hold + period) + 1e-4, travel
    assert 'dead-man' in run.reason


def test_a_twist_along_a_straight_section_says_why_the_tip_cannot_follow():
    run = TeleopRun(ROBOT, TeleopSettings())
    start = ROBOT.estimate_shape(ROBOT.straight_cable_lengths)
    run.start(start, ROBOT.straight_cable_lengths)
    twist = Twist(np.array([0.0, 0.0, -0.02]), np.zeros(3), 0.0, 0.5)
    run.tick(0.0, 0.02, twist, np.zeros(6))
    assert 'no freedom in that direction' in run.stopped, run.stopped


# -- over DDS ----------------------------------------------------------------------------------
rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, TwistStamped  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics.nodes.action_client import HandoverActionClient  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.qos import ACTION_SERVICE_QOS  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

MoveTip = pytest.importorskip('continuum_statics_interfaces.action').MoveTip


class Robot:
    """statics, the simulated driver and tip_controller, with a client of every goal source."""

    def __init__(self, harness, **controller):
        harness.add(StaticsNode, robot_file=TENDON, marker_rate=0.0)
        self.driver = harness.add(CableDriverNode, robot_file=TENDON)
        self.controller = harness.add(TipControllerNode, robot_file=TENDON, **controller)
        self.node = harness.client()
        self.tip = Collector(self.node, PoseStamped, 'tip_pose', LATCHED)
        self.commands = Collector(self.node, JointState, 'cable_commands', RELIABLE)
        self.diagnostics = Collector(self.node, DiagnosticArray, '/diagnostics', 10)
        self.action = action_client(self.node)
        self.service = self.node.create_client(GetPlan, 'tip_goal')
        self.goal_pose = self.node.create_publisher(PoseStamped, 'tip_goal_pose', RELIABLE)
        self.twists = self.node.create_publisher(TwistStamped, 'tip_twist', RELIABLE)
        assert self.action.wait_for_server(timeout_sec=10.0)
        assert self.service.wait_for_service(timeout_sec=10.0)
        wait_until(lambda: self.tip.last is not None, 10.0, 'the first tip pose')

    def values(self, node='tip_controller', since=None):
        """Return the node's newest /diagnostics values (``since``: published after, s wall)."""
        if since is not None:
            for array in reversed(tuple(self.diagnostics.messages)):
                stamp = array.header.stamp
                if stamp.sec + 1e-9 * stamp.nanosec < since:
                    return {}
                for status in array.status:
                    if status.name.endswith(node):
                        return {kv.key: kv.value for kv in status.values}
            return {}
        found = diagnostic_values(self.diagnostics, node)
        return found[0] if found else {}

    def send(self, position, tolerance=1e-3):
        """Send a move_tip goal; return the future of its goal handle."""
        return send_goal(self.action, position, tolerance)

    def reach(self, position, tolerance=1e-3, timeout=30.0):
        request = GetPlan.Request(tolerance=float(tolerance))
        request.goal.header.frame_id = 'base_link'
        p = request.goal.pose.position
        p.x, p.y, p.z = (float(v) for v in position)
        return call(self.service, request, timeout).plan


def action_client(node):
    """Return a move_tip client for bursts: its services as deep as the server's."""
    return HandoverActionClient(node, MoveTip, 'move_tip',
                                goal_service_qos_profile=ACTION_SERVICE_QOS,
                                result_service_qos_profile=ACTION_SERVICE_QOS,
                                cancel_service_qos_profile=ACTION_SERVICE_QOS)


def accepted_goals(action, position, timeout=60.0):
    """Send goals to ``position`` every 5 s until one is accepted; return the accepted handles.

    rmw_fastrtps drops a service response when the server has not yet matched the client's
    response reader ("client will not receive response", after 100 ms), and
    ``server_is_ready`` sees only the client's side of the match: on a loaded machine the first
    goal after discovery can go unanswered. An answered goal shows the way back is matched.
    """
    deadline = time.monotonic() + timeout
    sent = []
    while not any(f.done() for f in sent):
        assert time.monotonic() < deadline, 'no goal answered in %g s' % timeout
        sent.append(send_goal(action, position))
        resend = time.monotonic() + 5.0
        while not sent[-1].done() and time.monotonic() < resend:
            time.sleep(0.01)
    return [f.result() for f in sent if f.done() and f.result().accepted]


def send_goal(action, position, tolerance=1e-3):
    """Send a move_tip goal from ``action`` (a HandoverActionClient); return its future."""
    goal = MoveTip.Goal(tolerance=float(tolerance))
    goal.target.header.frame_id = 'base_link'
    p = goal.target.pose.position
    p.x, p.y, p.z = (float(v) for v in position)
    goal.target.pose.orientation.w = 1.0
    return action.send_goal_async(goal)


def results_of(handles_futures, timeout, what):
    """Wait for every goal's acceptance, then for every accepted goal's result."""
    wait_until(lambda: all(f.done() for f in handles_futures), timeout, what + ': accepted')
    handles = [f.result() for f in handles_futures]
    results = [h.get_result_async() for h in handles if h.accepted]
    wait_until(lambda: all(f.done() for f in results), timeout, what + ': answered')
    return handles, [f.result() for f in results]


def reachable(seed, count):
    rng = np.random.default_rng(seed)
    return [ROBOT.solve_ivp([*rng.uniform(-2.5, 2.5, 2), 0.0]).tip_position
            for _ in range(count)]


@pytest.mark.ros
def test_many_identical_goals_and_a_burst_all_get_answers_and_the_node_stays_responsive(
        harness):
    # before: each identical goal held one of the 8 executor threads; with 8 held the control
    # timer, cancels and diagnostics stopped for good
    # a slow ramp (4.8 s): the goals overlap, and the ramp outlasts the 24 acceptances even on a
    # loaded machine (at 0.005 m/s it ended 2.4 s in, before a CI run looked for it)
    robot = Robot(harness, max_cable_speed=0.0025)
    goal = ROBOT.solve_ivp([2.5, 0.0, 0.0]).tip_position
    same = [robot.send(goal) for _ in range(24)]
    wait_until(lambda: all(f.done() for f in same), 10.0, 'the identical goals accepted')
    wait_until(lambda: robot.values().get('phase') == 'ramp', 5.0, 'the ramp under way')
    count = len(robot.commands)
    wait_until(lambda: len(robot.commands) > count + 10, 5.0, 'the control timer to run')
    # a burst of 50 different goals from one client (before: 38 results were lost)
    burst = [robot.send(position) for position in reachable(1, 50)]
    handles, results = results_of(same + burst, 60.0, '74 goals')
    assert all(h.accepted for h in handles)
    assert len(results) == 74
    assert sum(r.result.reached for r in results) >= 1  # the last of the burst
    assert all(r.status in (4, 6) for r in results), {r.status for r in results}
    # answered, and still serving: a service goal is reached
    assert robot.reach(reachable(2, 1)[0]).poses, robot.values().get('last_outcome')


@pytest.mark.ros
def test_a_goal_sent_during_teleoperation_never_runs_after_the_dead_man_stop(harness):
    # before: a goal solved while the twists kept coming was parked behind teleoperation and
    # ran after the operator let go (4 of 10 trials moved the cables 9-12 mm)
    robot = Robot(harness, twist_timeout=0.2)
    twist = TwistStamped()
    twist.header.frame_id = 'base_link'
    answers = []
    for trial, goal in enumerate(reachable(3, 10)):
        # 0.4 s of twists at 100 Hz, a goal in the middle; they go on until the controller has
        # answered the goal's request: under a CPU hog it was handled after the twists that
        # followed it, so it came last and rightly ran
        k, deadline = 0, time.monotonic() + 10.0
        while k < 40 or not answers[-1].done():
            assert time.monotonic() < deadline, 'trial %d: the goal never answered' % trial
            twist.twist.linear.y = 0.01 * (1 if trial % 2 else -1)
            robot.twists.publish(twist)
            if k == 20:
                answers.append(robot.send(goal))
            k += 1
            time.sleep(0.01)
        # the controller settled after the last twist: teleoperation ended, nothing running (a
        # status published before it handled the twists that followed the goal shows the goal
        # ramping: under a CPU hog the test once read that one). A goal that ran after the
        # stop ends reached or failed, not pre-empted (the results, below)
        last_twist = time.time()
        wait_until(lambda: robot.values(since=last_twist).get('phase') == 'idle'
                   and robot.values(since=last_twist).get('teleoperation') == 'False',
                   10.0, 'the dead-man stop')
        # no goal runs after the operator let go (before: it started and moved the cables)
        stopped = time.monotonic()
        while time.monotonic() - stopped < 0.5:
            values = robot.values(since=last_twist)
            assert values.get('phase') == 'idle' or values.get('teleoperation') == 'True', (
                'trial %d: a goal runs after the dead-man stop: %s' % (trial, values))
            time.sleep(0.02)
    _, results = results_of(answers, 10.0, 'the goals')
    assert all('pre-empted by teleoperation' in r.result.message for r in results), [
        (r.status, r.result.message) for r in results]


class FrozenTracker:
    """A tracker stuck at one position (a lost marker the software keeps reporting)."""

    def __init__(self, node, position):
        self.position = np.asarray(position, dtype=float)
        self.publisher = node.create_publisher(PoseStamped, 'tip_pose_measured',
                                               qos_profile_sensor_data)
        self.timer = node.create_timer(0.01, self.publish)

    def publish(self):
        msg = PoseStamped()
        msg.header.frame_id = 'base_link'
        p = msg.pose.position
        p.x, p.y, p.z = (float(v) for v in self.position)
        msg.pose.orientation.w = 1.0
        self.publisher.publish(msg)


@pytest.mark.parametrize('offset', [(0.0, 0.0, 0.0), (0.2, 0.0, 0.0)],
                         ids=['frozen', '200 mm bias'])
@pytest.mark.ros
def test_a_faulty_tracker_is_set_aside_and_the_goal_continues_on_the_model(harness, offset):
    # before: the frozen tracker ended the tip 214 mm from its goal, the biased one 186 mm
    robot = Robot(harness)
    start = pose_xyz(robot.tip.last.pose)
    FrozenTracker(robot.node, start + np.asarray(offset))
    wait_until(lambda: robot.values().get('have_tip_pose_measured') == 'True', 10.0,
               'the controller to hear the tracker')
    goal = ROBOT.solve_ivp([3.0, -1.0, 0.0]).tip_position  # 90 mm from the start
    plan = robot.reach(goal)
    values = robot.values()
    assert plan.poses, values.get('last_outcome')
    assert np.linalg.norm(pose_xyz(robot.tip.last.pose) - goal) <= 1e-3
    wait_until(lambda: 'tracker set aside' in robot.values().get('last_rejection', ''), 5.0,
               'the warning naming the tracker')


@pytest.mark.ros
def test_a_goal_fails_naming_the_driver_when_it_is_deactivated(harness):
    # before: "still 85 mm from the goal after 10 corrections", never naming the driver
    robot = Robot(harness, max_cable_speed=0.005)
    future = robot.send(ROBOT.solve_ivp([3.0, 0.0, 0.0]).tip_position)
    wait_until(lambda: len(robot.commands) >= 5, 10.0, 'the ramp under way')
    robot.driver.trigger_deactivate()
    _, (answer,) = results_of([future], 15.0, 'the goal')
    assert answer.status == 6, answer
    message = answer.result.message
    assert 'cable_driver refuses cable_commands' in message and 'inactive' in message, message
    # a goal meanwhile is rejected with the same reason (after state_wait)
    robot.controller.set_parameters([rclpy.parameter.Parameter('state_wait', value=0.2)])
    _, (rejected,) = results_of([robot.send(reachable(4, 1)[0])], 10.0, 'the next goal')
    assert 'cable_driver refuses cable_commands' in rejected.result.message
    # active again: goals work without a restart
    robot.driver.trigger_activate()
    _, (again,) = results_of([robot.send(reachable(5, 1)[0])], 30.0, 'a goal after activate')
    assert again.result.reached, again.result.message


@pytest.mark.ros
def test_goal_mistakes_are_answered_with_the_cause(harness):
    robot = Robot(harness)
    for position, cause in (((1e308, 0.0, 0.3), 'unreachable'),
                            ((-1e30, 0.0, 0.3), 'unreachable')):
        _, (answer,) = results_of([robot.send(position)], 10.0, 'the goal')
        message = answer.result.message
        assert cause in message and 'must be finite' not in message, message
        assert 'infs or NaNs' not in message, message
        assert answer.result.error == -1.0  # documented: no tip judged
    # a NaN goal is refused at acceptance: counted and on diagnostics
    handle = robot.send((math.nan, 0.0, 0.3))
    wait_until(handle.done, 10.0, 'the NaN goal refused')
    assert not handle.result().accepted
    wait_until(lambda: robot.values().get('goals_rejected') == '3', 5.0, 'three rejections')
    assert 'non-finite' in robot.values()['last_outcome']


@pytest.mark.ros
def test_twists_stamped_far_from_now_are_refused_with_the_reason(harness):
    robot = Robot(harness)
    twist = TwistStamped()
    twist.header.frame_id = 'base_link'
    twist.header.stamp.sec = 1  # 1970
    twist.twist.linear.y = 0.01
    for _ in range(20):
        robot.twists.publish(twist)
        time.sleep(0.01)
    wait_until(lambda: 'stamped' in robot.values().get('last_rejection', ''), 5.0,
               'the rejection')
    assert robot.values()['teleoperation'] == 'False'
    assert len(robot.commands) == 0


class Bringup:
    """``python -m continuum_statics bringup`` in a process of its own, and a client context."""

    def __init__(self, log, namespace, *ros_args):
        self.log = log  # a file, not a pipe: a full pipe would block the process's logging
        with open(log, 'wb') as out:
            self.process = subprocess.Popen(
                [sys.executable, '-m', 'continuum_statics', 'bringup', '--robot', TENDON,
                 '--namespace', namespace, *(('--ros-args', *ros_args) if ros_args else ())],
                cwd=str(REPO), env=dict(os.environ), stdout=out, stderr=subprocess.STDOUT)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)

    def output(self):
        return self.log.read_text()[-3000:]

    def interrupt(self, timeout):
        """SIGINT; return the exit code, or fail when the process outlives ``timeout`` s."""
        self.process.send_signal(signal.SIGINT)
        try:
            return self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            pytest.fail('bringup still running %g s after SIGINT: %s'
                        % (timeout, self.output()))

    def close(self):
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()
        rclpy.try_shutdown(context=self.context)


@pytest.mark.ros
def test_a_soak_of_a_thousand_goals_from_four_clients_all_answered_then_sigint(tmp_path):
    """1,000 move_tip goals in seeded bursts from 4 clients, cancels and twists interleaved.

    Identical and different goals, against bringup in its own process: every goal answered, the
    controller still reaches a goal after, and SIGINT ends the process (before: 8 waiting goals
    froze it for good, and a burst lost most of its results).
    """
    rng = np.random.default_rng(23)
    bringup = Bringup(tmp_path / 'bringup.log', 'soak23')
    try:
        node = rclpy.create_node('soak_client', namespace='/soak23', context=bringup.context)
        executor = rclpy.executors.MultiThreadedExecutor(num_threads=2,
                                                         context=bringup.context)
        executor.add_node(node)
        clients = [action_client(node) for _ in range(4)]
        service = node.create_client(GetPlan, 'tip_goal')
        twists = node.create_publisher(TwistStamped, 'tip_twist', RELIABLE)
        tip = Collector(node, PoseStamped, 'tip_pose', LATCHED)
        threading.Thread(target=executor.spin, daemon=True).start()
        wait_until(lambda: all(c.server_is_ready() for c in clients) and tip.last is not None,
                   60.0, 'bringup up')
        targets = reachable(6, 40)
        sent, cancels = [], 0
        twist = TwistStamped()
        twist.header.frame_id = 'base_link'
        while len(sent) < 1000:
            size = int(rng.integers(5, 60))
            identical = rng.random() < 0.5
            target = targets[int(rng.integers(len(targets)))]
            for _ in range(min(size, 1000 - len(sent))):
                if not identical:
                    target = targets[int(rng.integers(len(targets)))]
                client = clients[int(rng.integers(4))]
                sent.append(send_goal(client, target))
            if rng.random() < 0.3:  # an operator nudges the stick
                twist.twist.linear.x = float(rng.uniform(-0.01, 0.01))
                for _ in range(5):
                    twists.publish(twist)
                    time.sleep(0.01)
            deadline = time.monotonic() + 60.0
            while not all(f.done() for f in sent):
                assert time.monotonic() < deadline, 'goal responses: %d of %d, cancels %d' % (
                    sum(f.done() for f in sent), len(sent), cancels)
                time.sleep(0.01)
            for future in rng.choice(sent[-size:], size=min(3, size), replace=False):
                if future.result().accepted and rng.random() < 0.5:
                    future.result().cancel_goal_async()
                    cancels += 1
        # the results of 1,000 goals take long under load: ~115 s (0.1 s a result) on a loaded
        # 2-core machine, before this stop's changes as after; 120 s failed 1 CI run in 3
        handles, results = results_of(sent, 300.0, '1000 goals')
        assert len(results) == sum(h.accepted for h in handles) == 1000
        statuses = {r.status for r in results}
        assert statuses <= {4, 5, 6}, statuses  # succeeded, canceled, aborted: all answered
        assert all(r.result.message for r in results if r.status != 4)
        # still serving, without a restart
        request = GetPlan.Request(tolerance=1e-3)
        request.goal.header.frame_id = 'base_link'
        p = request.goal.pose.position
        p.x, p.y, p.z = (float(v) for v in targets[0])
        assert call(service, request, 30.0).plan.poses
        assert bringup.interrupt(5.0) == 0, bringup.output()
        executor.shutdown()
    finally:
        bringup.close()


def test_an_abort_without_a_tracker_does_not_blame_one():
    # issue 38: with no tracker running the abort said "the measured tip and the model disagree
    # (check the tracker ...)"; the judged tip was the model's own, moved by its inputs
    run, goal, _ = straight_run_to_a_goal(RunSettings(max_correction=0.03, settle_time=0.0))
    run.tip_source = 'tip_pose'
    away = goal.position + np.array([0.02, 0.0, 0.0])
    now = 0.0
    while not goal.done.is_set() and now < 40.0:
        now += 0.02
        tips = [sample(away, now - 0.001 * k) for k in range(5)]
        run.tick(now, 0.02, Measurement(run.commanded.copy(), 0, now), tips[0], tips[::-1],
                 np.zeros(6))
    assert goal.done.is_set() and not goal.reached
    assert 'no tracker is used' in goal.reason and 'check the tracker' not in goal.reason
