"""Real tendons over DDS (one process, private context): slack cables, tensions, the tracker loop.

Truths come from the numeric core, offline: ``solve_lengths`` (the displacement-driven statics of
rod and cables) for a paid-out cable, ``command_for``'s tension check for a goal over
``tension_limits``, and the geometry of a fixed tracker bias for ``tip_pose_measured``.
"""
import math
import time

from conftest import REPO
from nodes_helpers import (
    LATCHED,
    Collector,
    call,
    diagnostic_values,
    pose_xyz,
    publish_until,
    wait_until,
)
import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.core.estimation import shape_estimation  # noqa: E402
from continuum_statics.core.statics.tendon_commands import command_for  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

pytestmark = pytest.mark.ros
IDEAL_FILE = REPO / 'config' / 'tendon_robot.yaml'
REAL_FILE = REPO / 'config' / 'tendon_robot_real_tendons.yaml'
IDEAL = load_robot(IDEAL_FILE)
REAL = load_robot(REAL_FILE)
NAMES = list(IDEAL.cable_names)
ERROR_LEVEL = DiagnosticStatus.ERROR
#: The "real robot" of the tracker tests is off the model by this much (m, base frame).
BIAS = np.array([2e-3, -1e-3, 0.0])


def tensions_of(values):
    """{cable: N} of a statics ``tension_estimates_n`` value (empty when not estimated)."""
    text = values.get('tension_estimates_n', '')
    if not text or text.startswith('not estimated'):
        return {}
    return {name: float(value) for name, value in
            (item.strip().rsplit(' ', 1) for item in text.split(','))}


def status_of(diagnostics, suffix):
    """(values, status) of the newest status of a node, or ({}, None)."""
    found = diagnostic_values(diagnostics, suffix)
    return found if found else ({}, None)


# -- 1. statics: a paid-out cable is slack, the shape is the one without its tension ---------

def least_squares_fit(robot, lengths):
    """Return the least-squares fit alone (what statics published before slack cables)."""
    saved = shape_estimation.SLACK_RESIDUAL
    shape_estimation.SLACK_RESIDUAL = math.inf  # never try the tendon statics
    try:
        return robot.estimate_shape(lengths)
    finally:
        shape_estimation.SLACK_RESIDUAL = saved


def test_a_paid_out_cable_is_slack_and_the_tip_is_the_shape_without_its_tension(harness):
    bent = IDEAL.solve_ivp([2.0, 1.0, 0.0])
    lengths = np.asarray(IDEAL.cable_lengths(bent), dtype=float)
    paid_out = lengths.copy()
    paid_out[1] += 0.005  # cable_1 paid out 5 mm; the others at the shape's lengths
    truth = IDEAL.solve_lengths(paid_out)
    assert truth.converged and truth.slack[1] and not truth.slack[[0, 3]].any(), truth.message
    fit = least_squares_fit(IDEAL, paid_out)  # computed before any node runs (module global)
    assert np.linalg.norm(fit.shape.tip_position - truth.shape.tip_position) > 0.01

    statics = harness.add(StaticsNode, marker_rate=0.0, max_stamp_offset=1e12)  # small stamps
    client = harness.client()
    backbone = Collector(client, Path, 'backbone', LATCHED)
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)

    def feed(values, sec, settled=None):
        """Publish a measurement (repeated, as a driver does) until its tip pose comes back.

        ``settled``: the tip it should reach: statics' work per measurement is bounded, so a
        jump it cannot finish in one cycle goes on with the next ones (the same lengths).
        """
        msg = JointState(name=NAMES, position=[float(v) for v in values])
        msg.header.stamp = Time(sec=sec, nanosec=0)
        publish_until(states, msg, lambda: tip.last is not None
                      and tip.last.header.stamp.sec == sec and (
                          settled is None
                          or np.linalg.norm(pose_xyz(tip.last.pose) - settled) <= 1e-9),
                      10.0, 'the tip pose of %d' % sec)
        return pose_xyz(tip.last.pose)

    np.testing.assert_allclose(feed(lengths, 101), bent.tip_position, atol=1e-6)
    published = feed(paid_out, 102, settled=truth.shape.tip_position)
    np.testing.assert_allclose(published, truth.shape.tip_position, atol=1e-6)
    assert np.linalg.norm(published - fit.shape.tip_position) > 0.01, 'the least-squares fit'
    np.testing.assert_allclose(pose_xyz(backbone.last.poses[-1].pose), published, atol=1e-9)

    def slack_named():
        values = status_of(diagnostics, '/statics')[0]
        slack = [name.strip() for name in values.get('slack_cables', 'none').split(',')]
        # (diagnostics come once a second: one may still show a cycle that went on with the next)
        return ('cable_1' in slack and len(tensions_of(values)) == 4
                and float(values.get('residual_m', 'nan')) < 1e-9)

    wait_until(slack_named, 5.0, "statics' diagnostics to name cable_1 slack, with tensions")
    values, status = status_of(diagnostics, '/statics')
    slack = {name.strip() for name in values['slack_cables'].split(',')}
    assert not slack & {'cable_0', 'cable_3'}, values['slack_cables']  # they hold the shape
    tensions = tensions_of(values)
    assert tensions['cable_1'] == 0.0 and min(tensions.values()) >= 0.0
    # inextensible antagonists: only the difference of cable_0 and cable_2 is determined
    t = dict(zip(NAMES, truth.tensions))
    assert tensions['cable_3'] == pytest.approx(t['cable_3'], rel=1e-3), values
    assert tensions['cable_0'] - tensions['cable_2'] == pytest.approx(
        t['cable_0'] - t['cable_2'], rel=1e-3), values
    assert status.level != ERROR_LEVEL, status.message
    assert float(values['residual_m']) < 1e-9
    assert values['converged'] == 'True', values['estimate_message']
    # statics only reads cable_states (its effort is the driver's to publish)
    assert all(p.topic_name.split('/')[-1] != 'cable_states' for p in statics.publishers)


# -- 2.-3. the three nodes on the real-tendon robot with the simulated tendons ---------------

class Stack:
    """statics, cable_driver (sim) and tip_controller, plus a client with the goal service."""

    def __init__(self, harness, robot_file, controller=(), statics=(), driver=()):
        common = {'robot_file': str(robot_file)}
        self.statics = harness.add(StaticsNode, marker_rate=0.0, **common, **dict(statics))
        self.driver = harness.add(CableDriverNode, **common, **dict(driver))
        self.controller = harness.add(TipControllerNode, **common, **dict(controller))
        client = self.client = harness.client()
        self.tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
        self.states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
        self.diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
        self.service = client.create_client(GetPlan, 'tip_goal')
        assert self.service.wait_for_service(timeout_sec=10.0)
        wait_until(lambda: self.tip.last is not None and self.states.last is not None, 15.0,
                   'the first tip pose and cable states')
        wait_until(lambda: self.controller_values().get('have_tip_pose') == 'True', 10.0,
                   'the controller to hear tip_pose')

    @staticmethod
    def request(position, tolerance):
        request = GetPlan.Request(tolerance=float(tolerance))
        request.goal.header.frame_id = 'base_link'
        p = request.goal.pose.position
        p.x, p.y, p.z = (float(v) for v in position)
        request.goal.pose.orientation.w = 1.0
        return request

    def goal(self, position, tolerance, timeout=40.0):
        return call(self.service, self.request(position, tolerance), timeout).plan

    def controller_values(self):
        return status_of(self.diagnostics, '/tip_controller')[0]

    def statics_values(self):
        return status_of(self.diagnostics, '/statics')[0]


def test_real_tendons_report_tensions_and_min_tension_keeps_antagonists_taut(harness):
    stack = Stack(harness, REAL_FILE, controller={'min_tension': 1.0},
                  driver={'publish_rate': 100.0})
    # at home every cable carries its 2 N pretension, measured by the simulated tendons
    efforts = [list(m.effort) for m in list(stack.states.messages)[-20:] if m.effort]
    assert efforts, 'cable_states carries no effort'
    for effort in efforts:
        assert len(effort) == 4 and all(math.isfinite(t) and t >= 0.0 for t in effort)
        np.testing.assert_allclose(effort, 2.0, atol=0.01)
    goal = REAL.solve_ivp([2.0, 0.5, 0.0]).tip_position
    plan = stack.goal(goal, 1e-3)
    assert len(plan.poses) == 20, stack.controller_values().get('last_outcome')
    assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    # the model's tensions (statics) and the simulated ones (driver): antagonists at ~1 N
    # (>= 0.85, not 1: a cable last paid out reads exp(-mu wrap) ~ 0.92 of it at the motor)
    wait_until(lambda: len(tensions_of(stack.statics_values())) == 4
               and min(tensions_of(stack.statics_values()).values()) >= 0.85
               and np.linalg.norm(pose_xyz(stack.tip.last.pose) - goal) <= 1e-3, 5.0,
               "statics' tension estimates after the goal: %s" % stack.statics_values().get(
                   'tension_estimates_n'))
    estimates = tensions_of(stack.statics_values())
    assert sorted(estimates) == NAMES
    assert min(estimates.values()) <= 1.2, 'some antagonist is held near min_tension'
    assert max(estimates.values()) > 3.0, 'the bend needs tension'
    effort = np.asarray(stack.states.last.effort)
    assert effort.shape == (4,) and np.all(np.isfinite(effort)) and np.min(effort) >= 0.85, effort
    assert stack.statics_values().get('slack_cables') == 'none'


def test_lengths_and_tensions_of_the_tendon_model_itself_are_not_distrusted(harness):
    goal = REAL.solve_ivp([2.0, 0.5, 0.0]).tip_position
    lengths = command_for(REAL, REAL.solve_tip_goal(goal).shape, 1.0).lengths
    held = REAL.solve_lengths(lengths)  # what the motors' lengths give: shape and tensions
    assert held.converged and not held.slack.any(), held.message
    harness.add(StaticsNode, marker_rate=0.0, robot_file=str(REAL_FILE), max_stamp_offset=1e12)
    client = harness.client()
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    msg = JointState(name=NAMES, position=[float(v) for v in lengths],
                     effort=[float(t) for t in held.tensions])
    msg.header.stamp = Time(sec=201, nanosec=0)
    publish_until(states, msg, lambda: tip.last is not None and tip.last.header.stamp.sec == 201,
                  10.0, 'the tip pose of the measurement')
    published = pose_xyz(tip.last.pose)
    np.testing.assert_allclose(published, held.shape.tip_position, atol=1e-6)
    text = '%.5f %.5f %.5f' % tuple(published)
    wait_until(lambda: status_of(diagnostics, '/statics')[0].get('tip_position_m') == text,
               5.0, 'diagnostics of the measurement')
    values, status = status_of(diagnostics, '/statics')
    assert values['tensions_distrusted_total'] == '0', status.message
    assert status.level == DiagnosticStatus.OK, status.message


def test_a_goal_over_the_tension_limits_is_rejected_with_the_reason(harness, tmp_path):
    data = yaml.safe_load(REAL_FILE.read_text())
    data['tendons']['tension_limits'] = [0.0, 3.0]
    limited_file = tmp_path / 'limited_tendons.yaml'
    limited_file.write_text(yaml.safe_dump(data))
    limited = load_robot(limited_file)
    goal = limited.solve_ivp([3.0, 0.0, 0.0]).tip_position  # needs ~13 N on one cable
    stack = Stack(harness, limited_file, controller={'goal_timeout': 60.0},
                  driver={'publish_rate': 100.0})
    start_tip = pose_xyz(stack.tip.last.pose)
    started = time.monotonic()
    plan = stack.goal(goal, 1e-3, timeout=20.0)
    assert time.monotonic() - started < 10.0, 'rejected at once, not after the goal timeout'
    assert len(plan.poses) == 0
    wait_until(lambda: stack.controller_values().get('goals_rejected') == '1', 5.0,
               'the rejection on diagnostics')
    outcome = stack.controller_values()['last_outcome']
    assert 'tension_limits' in outcome and '> 3 N' in outcome, outcome
    assert stack.controller_values()['goals_reached'] == '0'
    np.testing.assert_allclose(pose_xyz(stack.tip.last.pose), start_tip, atol=1e-5)


# -- 4. tip_pose_measured closes the loop ----------------------------------------------------

class Tracker:
    """A fake motion-capture tracker: statics' tip position + BIAS, on tip_pose_measured."""

    def __init__(self, node, frame='base_link'):
        self.frame = frame
        self.published = 0
        self.last = None  # the newest measured (biased) position
        self._publisher = node.create_publisher(PoseStamped, 'tip_pose_measured',
                                                qos_profile_sensor_data)
        self._subscription = node.create_subscription(PoseStamped, 'tip_pose', self._on_tip,
                                                      LATCHED)

    def _on_tip(self, msg):
        measured = PoseStamped()
        measured.header.stamp = msg.header.stamp
        measured.header.frame_id = self.frame
        position = pose_xyz(msg.pose) + BIAS
        p = measured.pose.position
        p.x, p.y, p.z = (float(v) for v in position)
        measured.pose.orientation.w = 1.0  # a marker frame of its own: not the tip's
        self._publisher.publish(measured)
        self.last = position
        self.published += 1


def tracker_stack(harness, frame='base_link', **controller):
    stack = Stack(harness, IDEAL_FILE, controller=controller)
    stack.tracker = Tracker(stack.client, frame)
    wait_until(lambda: stack.tracker.published > 0, 10.0, 'the tracker to see tip_pose')
    return stack


def test_tip_pose_measured_closes_the_loop_on_the_tracked_tip(harness):
    stack = tracker_stack(harness)
    wait_until(lambda: stack.controller_values().get('have_tip_pose_measured') == 'True', 10.0,
               'the controller to hear the tracker')
    goal = IDEAL.solve_ivp([2.0, -1.0, 0.0]).tip_position
    plan = stack.goal(goal, 5e-4)
    assert len(plan.poses) == 20, stack.controller_values().get('last_outcome')
    # the "real" tip is at the goal, the model's (statics, and the answered plan) is off by BIAS
    measured_error = np.linalg.norm(stack.tracker.last - goal)
    model_error = np.linalg.norm(pose_xyz(stack.tip.last.pose) - goal)
    assert measured_error <= 5e-4, (measured_error, model_error)
    assert model_error == pytest.approx(np.linalg.norm(BIAS), abs=5e-4), model_error
    assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) > 1.5e-3
    wait_until(lambda: stack.controller_values().get('goals_reached') == '1', 5.0, 'the count')
    assert stack.controller_values()['tip_source'] == 'tip_pose_measured'


def test_without_use_measured_tip_the_model_tip_is_judged(harness):
    stack = tracker_stack(harness, use_measured_tip=False)
    wait_until(lambda: stack.controller_values().get('have_tip_pose_measured') == 'True', 10.0,
               'the controller to hear the tracker')
    goal = IDEAL.solve_ivp([2.0, -1.0, 0.0]).tip_position
    plan = stack.goal(goal, 5e-4)
    assert len(plan.poses) == 20, stack.controller_values().get('last_outcome')
    model_error = np.linalg.norm(pose_xyz(stack.tip.last.pose) - goal)
    measured_error = np.linalg.norm(stack.tracker.last - goal)
    assert model_error <= 5e-4, (model_error, measured_error)
    assert measured_error == pytest.approx(np.linalg.norm(BIAS), abs=5e-4), measured_error
    wait_until(lambda: stack.controller_values().get('goals_reached') == '1', 5.0, 'the count')
    assert stack.controller_values()['tip_source'] == 'tip_pose'


def test_a_tip_pose_measured_in_another_frame_is_rejected_and_goals_use_tip_pose(harness):
    stack = tracker_stack(harness, frame='mocap_world')
    wait_until(lambda: "'mocap_world'" in stack.controller_values().get('last_rejection', ''),
               10.0, 'the rejection of the tracker frame on diagnostics')
    values = stack.controller_values()
    assert 'tip_pose_measured' in values['last_rejection'], values['last_rejection']
    assert values['have_tip_pose_measured'] == 'False'
    goal = IDEAL.solve_ivp([-1.0, 2.0, 0.0]).tip_position
    plan = stack.goal(goal, 5e-4)
    assert len(plan.poses) == 20, stack.controller_values().get('last_outcome')
    assert np.linalg.norm(pose_xyz(stack.tip.last.pose) - goal) <= 5e-4
    wait_until(lambda: stack.controller_values().get('goals_reached') == '1', 5.0, 'the count')
    assert stack.controller_values()['tip_source'] == 'tip_pose'
    assert int(stack.controller_values()['rejected_tip_pose_measured']) > 0
