"""The nodes against the robot in motion (issue 36): ``sim.dynamics`` over DDS.

The simulated driver integrates the rod's dynamics behind its motors in real time; the statics
node only sees the motors' lengths and tensions. The true tip on ``sim/tip_pose_true`` must
come to rest on the goals the controller says it reached.
"""
from conftest import REPO
from nodes_helpers import (
    LATCHED,
    Collector,
    call,
    diagnostic_values,
    goal_request,
    pose_xyz,
    wait_until,
)
import numpy as np
import pytest

from continuum_statics import load_robot

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402

from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

DYNAMIC_FILE = str(REPO / 'config' / 'tendon_robot_dynamic.yaml')
ROBOT = load_robot(DYNAMIC_FILE)
TOLERANCE = 1e-3  # m, the goals'
#: s of simulated time the driver may drop (slower than real time) before the comparison
#: with simulate means nothing
DROPPED = 0.05
#: ... and the real-time factor it needs to step each command on time (bench_dynamics: 10.7-11.4
#: on the machine this test was written on, 4.0 on a 2-GHz Zen 1)
MIN_REAL_TIME = 3.0


@pytest.mark.ros
def test_goals_on_the_robot_in_motion_come_to_rest_where_the_controller_says(harness):
    common = {'robot_file': DYNAMIC_FILE}
    harness.add(CableDriverNode, **common, **{'sim.dynamics': True})
    harness.add(StaticsNode, marker_rate=0.0, **common)
    controller = harness.add(TipControllerNode, **common)
    client = harness.client()
    true_tips = Collector(client, PoseStamped, 'sim/tip_pose_true', qos_profile_sensor_data)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    estimates = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    wait_until(lambda: len(true_tips) >= 10 and len(estimates) >= 1, 60.0,
               'the true tip and the estimate')
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    rest = []
    for bending in ([3.0, 0.0], [0.0, -4.0], [-2.5, 2.5]):
        goal = ROBOT.solve_ivp([bending[0], bending[1], 0.0]).tip_position
        request = goal_request(ROBOT.base_frame_id, goal, TOLERANCE)
        assert call(service, request, 60.0).plan.poses, controller.control.last_outcome

        def true_error():
            return np.linalg.norm(pose_xyz(true_tips.last.pose) - goal)

        # it swings after the motors stop (5 % of critical damping): it comes to rest on the
        # goal, within the tolerance and 1 mm of the statics' friction resolution (0.1-1.3 mm
        # seen in all)
        wait_until(lambda: true_error() < TOLERANCE + 1e-3, 10.0,
                   'the true tip at rest on the goal (%.2f mm away)' % (1e3 * true_error()))
        rest.append(true_error())
    values = diagnostic_values(diagnostics, 'cable_driver')[0]
    print('true tip at rest %s mm from the goals; driver: real-time factor %s, step %s ms, '
          '%s s dropped, %s failed steps' % (
              np.round(1e3 * np.array(rest), 2).tolist(), values.get('real_time_factor'),
              values.get('step_time_ms'), values.get('dropped_time_s'),
              values.get('failed_steps')))
    assert values['failed_steps'] == '0'


@pytest.mark.ros
def test_a_fast_goal_overshoots_and_settles_as_simulate_predicts(harness):
    """The driver's rod in real time against ``simulate`` replaying the same cable_commands."""
    from sensor_msgs.msg import JointState

    from continuum_statics.core.dynamics.response import overshoot, settling_time
    from continuum_statics.tools.simulate import run

    def stamp(msg):
        return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec

    common = {'robot_file': DYNAMIC_FILE}
    speed = 0.2  # m/s: motors and ramps ten times the defaults, a goal in ~0.1 s
    harness.add(CableDriverNode, **common, **{'sim.dynamics': True, 'sim.max_speed': speed})
    harness.add(StaticsNode, marker_rate=0.0, **common)
    harness.add(TipControllerNode, max_cable_speed=speed, **common)
    client = harness.client()
    true_tips = Collector(client, PoseStamped, 'sim/tip_pose_true', qos_profile_sensor_data)
    commands = Collector(client, JointState, 'cable_commands', 100)
    estimates = Collector(client, PoseStamped, 'tip_pose', 100)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    wait_until(lambda: len(true_tips) >= 10, 60.0, 'the true tip')
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    wait_until(lambda: diagnostic_values(diagnostics, 'cable_driver')[0], 5.0, 'the driver')
    before = float(diagnostic_values(diagnostics, 'cable_driver')[0]['dropped_time_s'])
    goal = ROBOT.solve_ivp([0.0, -6.0, 0.0]).tip_position
    request = goal_request(ROBOT.base_frame_id, goal, TOLERANCE)
    assert call(service, request, 60.0).plan.poses
    answered = client.get_clock().now().nanoseconds * 1e-9
    # by the stamps, not a count: a loaded machine publishes the true tip at 40 Hz, not 200
    wait_until(lambda: stamp(true_tips.last) > answered + 2.0, 20.0,
               '2 s of the true tip after the goal')
    driver = diagnostic_values(diagnostics, 'cable_driver')[0]
    if (float(driver['dropped_time_s']) - before > DROPPED
            or float(driver['real_time_factor']) < MIN_REAL_TIME):
        # a rod that skipped simulated time, or stepped late behind its commands, moved
        # otherwise than simulate's: nothing to compare (the driver's WARN says so). On a 2-GHz
        # Zen 1 machine with the three nodes as threads of one process: real-time factor
        # 1.5-1.8, up to 0.55 s dropped, overshoot 1.2 % against simulate's 6.0 % with none
        pytest.skip('the simulated rod kept no real time (%.2f s dropped during the goal, '
                    'real-time factor %s)' % (float(driver['dropped_time_s']) - before,
                                              driver['real_time_factor']))

    names = list(ROBOT.cable_names)
    sent = [(stamp(m), [m.position[list(m.name).index(n)] for n in names])
            for m in commands.messages]
    start = sent[0][0]
    times = np.array([t for t, _ in sent]) - start
    targets = np.array([lengths for _, lengths in sent])
    observed = [(stamp(m) - start, pose_xyz(m.pose)) for m in true_tips.messages
                if stamp(m) >= start - 0.05]
    observed_t = np.array([t for t, _ in observed])
    observed_tip = np.array([xyz for _, xyz in observed])
    predicted = run(ROBOT, observed_t[-1], commands=(times, targets),
                    motor_bandwidth=1.0 / (2.0 * np.pi * 0.02), max_speed=speed)
    figures = {}
    for name, t, tips in (('nodes', observed_t, observed_tip),
                          ('simulate', predicted['time'], predicted['tip'])):
        figures[name] = (overshoot(tips), settling_time(t, tips))
    print('overshoot %%, settling time s: %s' % figures)
    assert abs(figures['nodes'][0] - figures['simulate'][0]) < 3.0
    assert figures['nodes'][1] is not None and figures['simulate'][1] is not None
    # 0.005 s apart on an idle machine; 0.19 s under a loaded one (20 demo runs at once: the
    # real-time rod drops backlog), so the bound leaves room for a busy 2-core CI machine
    assert abs(figures['nodes'][1] - figures['simulate'][1]) < 0.25
    # the statics node sees lengths, not motion: its tip lags the true one by the rod's dynamic
    # deflection, which simulate gives as its tip against the statics of its motors' lengths
    statics = [(stamp(m) - start, pose_xyz(m.pose)) for m in estimates.messages
               if 0.0 <= stamp(m) - start <= observed_t[-1]]
    lag = max(np.linalg.norm(xyz - np.array([np.interp(t, observed_t, observed_tip[:, i])
                                               for i in range(3)]))
              for t, xyz in statics)
    every = 5  # ms
    warm = None
    quasi = []
    for lengths in predicted['motors'][::every]:
        warm = ROBOT.solve_lengths(lengths, warm_start=warm)
        quasi.append(warm.shape.tip_position)
    expected = np.max(np.linalg.norm(predicted['tip'][::every] - np.array(quasi), axis=1))
    print('largest lag of the statics estimate behind the true tip: %.2f mm (the dynamics '
          'say %.2f mm)' % (1e3 * lag, 1e3 * expected))
    assert expected > 1e-3  # a fast goal: the rod lags its statics visibly
    # within half: 3-9 % apart alone, 27 % in a loaded CI run (the statics node's own latency
    # and the driver behind the clock add to the rod's lag)
    assert abs(lag - expected) < 0.5 * expected
