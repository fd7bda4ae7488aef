"""One estimator in normal use over DDS (issue 43 items 1 and 4).

The simulated robot in motion (``sim.dynamics``) carries a hidden 10 g payload
(``sim_tip_wrench``); a tracker (the test's relay of ``sim/tip_pose_true``, 0.3 mm noise, the
true stamps) sees its tip. The robot file names ``load_model: weight``: statics estimates the
payload with the shape and publishes it, tip_controller takes it (``tip_wrench_source:
estimate``) for its goals. Before, the estimate came from the tip_load_estimator node and went
back into statics as its tip load, and the tracker was counted twice: the estimate swung by
newtons and the model tip wandered 45.6 mm with the cables still.

The payload's mean is printed, not asserted: a tracker alone barely sees a weight that hangs
along the straight rod, the stand-in model uncertainty explains much of what it does see, and
the readings of the rod in motion carry its lag behind the statics, which no covariance here
holds (estimates of -6 to 16 g for 10 g; with sigmas of 1.4-1.6 g in the last runs, 3-6 sigma
off: overconfident, open).
In a fresh-clone CI run beside another DDS test, a load held at 14.7 g (the rod still swinging
when the load was updated, or the simulation behind real time) set the honest tracker aside and
the fused tip went 9 mm from it until the load was renewed: the test now runs alone, and
measures from 2 s after the last goal.
"""
import threading
import time

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
import yaml

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.core.estimation.state_estimation import LOAD_SETTLE  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402

PAYLOAD = 0.01  # kg, hidden
NOISE = 3e-4  # m, the tracker's
TOLERANCE = 1e-3  # m, the goals'


def payload_robot(tmp_path):
    """Write the dynamic tendon robot with a tip tracker and load_model: weight; return it."""
    document = yaml.safe_load((REPO / 'config' / 'tendon_robot_dynamic.yaml').read_text())
    document['sensors'] = [{'name': 'tip_tracker', 'at': 'tip', 'noise': {'position': NOISE}}]
    document.update(load_model='weight', load_prior=0.05)
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(document))
    return str(path)


class Relay:
    """A tracker: sim/tip_pose_true plus noise on tip_pose_measured, each at its true stamp."""

    def __init__(self, node):
        self.rng = np.random.default_rng(43)
        self.lock = threading.Lock()
        self.truth = []  # (stamp s, position (3,))
        self.publisher = node.create_publisher(PoseStamped, 'tip_pose_measured',
                                               qos_profile_sensor_data)
        node.create_subscription(PoseStamped, 'sim/tip_pose_true', self.on_truth,
                                 qos_profile_sensor_data)

    def on_truth(self, msg):
        position = pose_xyz(msg.pose)
        with self.lock:
            self.truth.append((msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec,
                               position))
        if len(self.truth) % 10:  # 100 Hz of the driver's 1 kHz
            return
        seen = PoseStamped(header=msg.header)
        seen.pose.orientation.w = 1.0
        seen.pose.position.x, seen.pose.position.y, seen.pose.position.z = (
            float(v) for v in position + self.rng.normal(0.0, NOISE, 3))
        self.publisher.publish(seen)

    def last(self):
        with self.lock:
            return self.truth[-1][1]


@pytest.mark.ros
@pytest.mark.alone  # a real-time simulation of the rod in motion: a core of its own
def test_the_payload_estimated_with_the_shape_holds_at_rest_and_goals_reach_the_true_tip(
        harness, tmp_path):
    robot_file = payload_robot(tmp_path)
    robot = load_robot(robot_file)
    gravity = np.asarray(robot.gravity)
    common = {'robot_file': robot_file}
    harness.add(CableDriverNode, **common, **{'sim.dynamics': True},
                sim_tip_wrench=[*(PAYLOAD * gravity), 0.0, 0.0, 0.0])
    harness.add(StaticsNode, marker_rate=0.0, **common)
    # goals 150 mm apart on the rod in motion took 2.9-9.4 s (1-6 corrections) on a 2-GHz
    # machine, where the simulation keeps 1.1-1.8x real time: the default 10 s failed 2 of 4 runs
    controller = harness.add(TipControllerNode, tip_wrench_source='estimate', goal_timeout=30.0,
                             **common)
    client = harness.client()
    relay = Relay(client)
    wrenches = Collector(client, WrenchStamped, 'tip_wrench_estimate', 10)
    estimates = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    wait_until(lambda: len(wrenches) >= 20 and len(relay.truth) >= 10, 60.0,
               'the load estimate and the true tip')
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    errors = []
    for bending in ([3.0, 0.0], [0.0, -4.0], [-2.5, 2.5]):
        goal = robot.solve_ivp([bending[0], bending[1], 0.0]).tip_position
        request = goal_request(robot.base_frame_id, goal, TOLERANCE)
        assert call(service, request, 60.0).plan.poses, controller.control.last_outcome
        # the true tip at rest on the goal: within the tolerance, 1 mm of the statics' friction
        # resolution (the dynamics test's), and 3 sigma of the tracker's noise
        bound = TOLERANCE + 1e-3 + 3.0 * NOISE
        wait_until(lambda: np.linalg.norm(relay.last() - goal) < bound, 10.0,
                   'the true tip at rest on the goal (%.2f mm away)'
                   % (1e3 * np.linalg.norm(relay.last() - goal)))
        errors.append(np.linalg.norm(relay.last() - goal))
    # at rest, the cables still: the load estimate and the model tip hold, from when the load
    # is updated again (LOAD_SETTLE after the last motion) and the rod has stopped swinging
    time.sleep(LOAD_SETTLE + 1.0)
    start = len(wrenches)
    tips = len(estimates)
    wait_until(lambda: len(wrenches) >= start + 100, 20.0, 'estimates at rest')
    forces = np.array([[w.wrench.force.x, w.wrench.force.y, w.wrench.force.z]
                       for w in wrenches.messages[start:]])
    masses = forces @ gravity / (gravity @ gravity)
    wander = np.array([pose_xyz(m.pose) for m in estimates.messages[tips:]])
    wait_until(lambda: (diagnostic_values(diagnostics, '/statics') or [{}])[0].get(
        'mass_sigma_kg'), 5.0, "the payload's sigma on /diagnostics")
    sigma = float(diagnostic_values(diagnostics, '/statics')[0]['mass_sigma_kg'])
    print('true tip at rest %s mm from the goals; payload %.1f g: estimate at rest %.2f g '
          '(sigma %.2f g), spread %.3f g over %d estimates; fused tip wander %.3f mm' % (
              np.round(1e3 * np.array(errors), 2).tolist(), 1e3 * PAYLOAD,
              1e3 * np.mean(masses), 1e3 * sigma, 1e3 * np.std(masses), len(masses),
              1e3 * np.max(np.ptp(wander, axis=0))))
    # the targets at rest: the load's spread within its own 3 sigma, the model tip
    # within 2 mm; statics never silent for more than 0.5 s (the stamps of tip_pose)
    assert np.ptp(masses) < 3.0 * sigma
    assert np.max(np.ptp(wander, axis=0)) < 2e-3
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec
                       for m in estimates.messages])
    assert np.max(np.diff(stamps)) < 0.5, np.max(np.diff(stamps))
