"""tip_load_estimator over DDS (one process, private context), a load hidden in the sim driver.

Truth: the simulated driver applies ``sim_tip_wrench`` to its own tendon model (no other node is
told); the tip that load gives at the motors' final lengths is ``solve_lengths`` with it, offline.
Decision logic without DDS: :class:`ContactDetector` and the sim backend's hidden load.
"""
from conftest import REPO
from nodes_helpers import (
    LATCHED,
    Collector,
    call,
    diagnostic_values,
    publish_until,
    wait_until,
)
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.control.contact import ContactDetector
from continuum_statics.drivers.sim import SimulatedCableBackend

REAL_FILE = REPO / 'config' / 'tendon_robot_real_tendons.yaml'
REAL = load_robot(REAL_FILE)
HIDDEN = [0.12, -0.08, 0.0, 0.0, 0.0, 0.0]  # N, N m: lateral, felt through the tensions


# -- without DDS -----------------------------------------------------------------------------

def test_contact_needs_three_sigma_and_ends_below_the_threshold():
    detector = ContactDetector(0.2)
    narrow, wide = np.eye(3) * 0.01 ** 2, np.eye(3) * 0.05 ** 2
    assert not detector.update([0.22, 0.0, 0.0], wide)  # 0.22 - 3 * 0.05 < 0.2
    assert detector.update([0.25, 0.0, 0.0], narrow) and detector.in_contact
    assert not detector.update([0.21, 0.0, 0.0], wide)  # still above: no toggling on noise
    assert detector.update([0.0, 0.19, 0.0], narrow) and not detector.in_contact


def test_the_sim_backend_holds_its_lengths_and_its_tensions_feel_the_hidden_load():
    backend = SimulatedCableBackend(REAL.cable_names, REAL.cable_length_limits,
                                    REAL.straight_cable_lengths, robot=REAL)
    backend.start(0.0)
    unloaded = backend.read(0.1)
    backend.set_tip_wrench(HIDDEN)
    loaded = backend.read(0.2)
    np.testing.assert_array_equal(loaded.lengths, unloaded.lengths)
    truth = REAL.solve_lengths(REAL.straight_cable_lengths, HIDDEN[:3])
    np.testing.assert_allclose(loaded.tensions, truth.tensions, rtol=1e-7)  # solver tolerance
    assert np.max(np.abs(loaded.tensions - unloaded.tensions)) > 0.3  # N: the load is felt
    with pytest.raises(ValueError, match='6 finite numbers'):
        backend.set_tip_wrench([0.0, float('nan'), 0.0, 0.0, 0.0, 0.0])


# -- over DDS --------------------------------------------------------------------------------

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Bool  # noqa: E402

from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402
from continuum_statics.nodes.statics_node import StaticsNode  # noqa: E402
from continuum_statics.nodes.tip_controller_node import TipControllerNode  # noqa: E402
from continuum_statics.nodes.tip_load_estimator_node import TipLoadEstimatorNode  # noqa: E402


def wrench_of(msg):
    f = msg.wrench.force
    return np.array([f.x, f.y, f.z])


def sigma_of(values):
    return np.array([float(v) for v in values['force_sigma_n'].split()])


@pytest.mark.ros
def test_the_estimator_finds_the_hidden_load_and_raises_contact(harness):
    common = {'robot_file': str(REAL_FILE)}
    harness.add(CableDriverNode, sim_tip_wrench=HIDDEN, **common)
    harness.add(TipLoadEstimatorNode, contact_threshold=0.5, **common)
    client = harness.client()
    estimates = Collector(client, WrenchStamped, 'tip_wrench_estimate', 10)
    contact = Collector(client, Bool, 'tip_contact', LATCHED)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)

    def values():
        found = diagnostic_values(diagnostics, '/tip_load_estimator')
        return found[0] if found else {}

    wait_until(lambda: len(estimates) >= 20 and 'force_sigma_n' in values(), 20.0,
               'estimates and their sigma')
    force, sigma = wrench_of(estimates.last), sigma_of(values())
    assert estimates.last.header.frame_id == REAL.base_frame_id
    # the cables feel the lateral load (sigma: its coupling with the unseen push along the
    # rod, whose prior is 10 E I / L^2 = 5 N); the push itself they do not see: held at zero
    assert np.all(np.abs(force[:2] - HIDDEN[:2]) <= 3.0 * sigma[:2]), (force, sigma)
    assert sigma[0] < 0.2 and sigma[1] < 0.2 and sigma[2] > 1.0, sigma
    assert abs(force[2]) <= 0.05 and values()['unseen_directions'] != 'none'
    assert contact.last is not None and contact.last.data is False
    # a push past the threshold, through the topic: contact, WARN; released: no contact
    load = client.create_publisher(WrenchStamped, 'sim_tip_wrench', 10)
    msg = WrenchStamped()
    msg.header.frame_id = REAL.base_frame_id
    msg.wrench.force.x = 0.9

    def pushed():
        load.publish(msg)
        return contact.last.data is True

    wait_until(pushed, 15.0, 'tip_contact true under a 0.9 N push')
    wait_until(lambda: 'contact on the tip' in (diagnostic_values(
        diagnostics, '/tip_load_estimator') or ({}, None))[1].message, 5.0, 'a contact WARN')
    msg.wrench.force.x = 0.0

    def released():
        load.publish(msg)
        return contact.last.data is False

    wait_until(released, 15.0, 'tip_contact false once the push is gone')


@pytest.mark.ros
def test_a_goal_with_the_estimated_load_lands_on_the_goal_while_the_load_is_on(harness):
    common = {'robot_file': str(REAL_FILE)}
    estimate = {'tip_wrench_source': 'estimate'}
    harness.add(CableDriverNode, sim_tip_wrench=HIDDEN, **common)
    harness.add(TipLoadEstimatorNode, **common)
    harness.add(StaticsNode, marker_rate=0.0, **common, **estimate)
    controller = harness.add(TipControllerNode, min_tension=1.0, **common, **estimate)
    client = harness.client()
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    estimates = Collector(client, WrenchStamped, 'tip_wrench_estimate', 10)
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    wait_until(lambda: tip.last is not None and len(estimates) >= 10, 20.0,
               'tip_pose and estimates')
    goal = REAL.solve_ivp([2.0, 0.5, 0.0]).tip_position
    request = GetPlan.Request(tolerance=1e-3)
    request.goal.header.frame_id = REAL.base_frame_id
    p = request.goal.pose.position
    p.x, p.y, p.z = (float(v) for v in goal)
    request.goal.pose.orientation.w = 1.0
    plan = call(service, request, 60.0).plan
    assert len(plan.poses) > 0, controller.control.last_outcome
    # where the simulated robot really is: its motors' lengths under the hidden load
    lengths = np.array(states.last.position)
    loaded = REAL.solve_lengths(lengths, HIDDEN[:3])
    unloaded = REAL.solve_lengths(lengths)
    assert loaded.converged and unloaded.converged
    assert np.linalg.norm(loaded.shape.tip_position - goal) <= 1.5e-3
    # and the load matters: the model without it puts that tip elsewhere
    assert np.linalg.norm(unloaded.shape.tip_position - goal) > 3e-3


@pytest.mark.ros
def test_bad_input_is_rejected_the_last_estimate_kept_and_nothing_non_finite_published(harness):
    harness.add(TipLoadEstimatorNode, robot_file=str(REAL_FILE))
    client = harness.client()
    estimates = Collector(client, WrenchStamped, 'tip_wrench_estimate', 10)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    states = client.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
    tracker = client.create_publisher(PoseStamped, 'tip_pose_measured', 10)
    held = REAL.solve_lengths(REAL.straight_cable_lengths, HIDDEN[:3])
    good = JointState(name=list(REAL.cable_names),
                      position=[float(v) for v in REAL.straight_cable_lengths],
                      effort=[float(t) for t in held.tensions])

    def values():
        found = diagnostic_values(diagnostics, '/tip_load_estimator')
        return found[0] if found else {}

    def published():
        states.publish(good)
        return len(estimates) >= 5

    wait_until(published, 15.0, 'estimates of good cable_states')
    count = len(estimates)
    bad = [JointState(name=list(REAL.cable_names), position=[float('nan')] * 4),
           JointState(name=['cable_0', 'nope', 'cable_2', 'cable_3'], position=[0.3] * 4),
           JointState(name=list(REAL.cable_names), position=[0.3] * 4,
                      effort=[1.0, float('inf'), 1.0, -2.0])]
    # the newest measurement only (sensor QoS): each bad one is sent until it is counted
    for index, msg in enumerate(bad, start=1):
        publish_until(states, msg, lambda: int(values().get('rejected_cable_states', 0))
                      >= index, 10.0, 'rejection %d counted on /diagnostics' % index)
    pose = PoseStamped()
    pose.header.frame_id = 'elsewhere'
    publish_until(tracker, pose, lambda: int(values().get('rejected_tip_pose_measured', 0))
                  >= 1, 10.0, 'the tracker in another frame rejected')
    assert 'elsewhere' in values()['last_rejection']
    # the good stream goes on and every published wrench is finite
    publish_until(states, good, lambda: len(estimates) > count + 3, 10.0, 'estimates again')
    for msg in estimates.messages:
        assert np.all(np.isfinite(wrench_of(msg)))
    assert np.all(np.abs(wrench_of(estimates.last)[:2] - HIDDEN[:2])
                  <= 3.0 * sigma_of(values())[:2])


@pytest.mark.ros
def test_a_payload_is_weighed_with_load_model_weight(harness):
    # a rod without cables, a tracker on its tip, 20 g hung there: the mass on /diagnostics
    rod_file = REPO / 'config' / 'jones2009_nitinol_rod.yaml'
    rod = load_robot(rod_file)
    harness.add(TipLoadEstimatorNode, robot_file=str(rod_file), load_model='weight',
                noise_tip_position=1e-3, diagnostics_rate=10.0)
    client = harness.client()
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    tracker = client.create_publisher(PoseStamped, 'tip_pose_measured', 10)
    tip = rod.solve_bvp(0.02 * np.asarray(rod.gravity)).tip_position
    pose = PoseStamped()
    pose.header.frame_id = rod.base_frame_id
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in tip)
    pose.pose.orientation.w = 1.0

    def values():
        found = diagnostic_values(diagnostics, '/tip_load_estimator')
        return found[0] if found else {}

    seen = {}

    def weighed():  # the tracker streams (stamped now) until the mass is on /diagnostics
        pose.header.stamp = client.get_clock().now().to_msg()
        tracker.publish(pose)
        seen.update(values())
        return 'mass_kg' in seen

    wait_until(weighed, 30.0, 'mass_kg on /diagnostics')
    mass, sigma = float(seen['mass_kg']), float(seen['mass_sigma_kg'])
    assert seen['load_model'] == 'weight'
    assert abs(mass - 0.02) <= 3.0 * sigma and sigma < 1e-3, (mass, sigma)
    force = np.array([float(v) for v in seen['force_n'].split()])
    np.testing.assert_allclose(force, mass * np.asarray(rod.gravity), rtol=1e-3, atol=1e-9)


@pytest.mark.ros
def test_the_estimator_node_refuses_a_robot_file_whose_load_statics_estimates(harness,
                                                                           tmp_path):
    """Two estimates of one load on tip_wrench_estimate: refused at start, saying why."""
    import yaml

    document = yaml.safe_load(REAL_FILE.read_text())
    document['load_model'] = 'weight'
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(document))
    with pytest.raises(ValueError, match='statics estimates the tip load'):
        harness.add(TipLoadEstimatorNode, robot_file=str(path))
