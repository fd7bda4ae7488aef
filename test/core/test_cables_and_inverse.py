"""Cable lengths (eq. 11), Jacobians, shape estimation and tip goals."""
from core_fixtures import make_robot, tendon_robot
import numpy as np
import pytest

UPRIGHT = {'frame_id': 'base_link', 'orientation': [0.0, 0.0, 0.0, 1.0]}
GUIDES = [0.039 * k for k in range(1, 11)]
FOUR_CABLES = [{'name': 'c%d' % k, 'offset': [0.008 * np.cos(k * np.pi / 2),
                                              0.008 * np.sin(k * np.pi / 2), 0.0]}
               for k in range(4)]


def cable_robot(cables=FOUR_CABLES, gravity=(0.0, 0.0, -9.81)):
    return make_robot(base=UPRIGHT, gravity=list(gravity), cables=cables, guides=GUIDES)


def test_straight_rod_cable_lengths_equal_last_guide():
    robot = cable_robot(gravity=(0.0, 0.0, 0.0))
    shape = robot.solve_ivp(np.zeros(3))
    assert np.allclose(robot.cable_lengths(shape), GUIDES[-1], atol=1e-12)
    assert np.allclose(robot.straight_cable_lengths, GUIDES[-1], atol=1e-12)


def test_pure_bending_arc_matches_closed_form_chord_sum():
    robot = cable_robot(gravity=(0.0, 0.0, 0.0)).with_solver(steps=96)  # RK4 error < 1e-10 m
    kappa = 4.0  # 1/m about local y: bends toward +x
    shape = robot.solve_ivp([0.0, kappa, 0.0])
    stations = np.concatenate([[0.0], GUIDES])
    expected = []
    for cable in FOUR_CABLES:
        radius = 1.0 / kappa - cable['offset'][0]  # hole's distance from the centre of curvature
        expected.append(np.sum(2.0 * radius * np.sin(kappa * np.diff(stations) / 2.0)))
    lengths = robot.cable_lengths(shape)
    assert np.allclose(lengths, expected, rtol=0, atol=1e-9)
    # the inner cable (towards +x) shortens, the outer lengthens, the side ones barely change
    assert lengths[0] < lengths[1] < lengths[2]


def central_difference(f, x, h):
    columns = []
    for k in range(len(x)):
        e = np.zeros(len(x))
        e[k] = h
        columns.append((f(x + e) - f(x - e)) / (2.0 * h))
    return np.array(columns).T


def test_tip_jacobian_matches_central_differences():
    robot = tendon_robot()
    u0 = np.array([2.0, -1.0, 0.3])
    force = np.array([0.05, -0.02, -0.1])
    jac = robot.jacobian(u0, force)
    shape0 = robot.solve_ivp(u0, force)

    def tip(u, f):
        return robot.solve_ivp(u, f).tip_position

    def angle(u, f):
        # rotation vector of R R0^T: its derivative is vee(dR R0^T)
        delta = robot.solve_ivp(u, f).tip_rotation @ shape0.tip_rotation.T
        return 0.5 * np.array([delta[2, 1] - delta[1, 2], delta[0, 2] - delta[2, 0],
                               delta[1, 0] - delta[0, 1]])

    expected = np.block([
        [central_difference(lambda f: tip(u0, f), force, 1e-4),
         central_difference(lambda u: tip(u, force), u0, 1e-4)],
        [central_difference(lambda f: angle(u0, f), force, 1e-4),
         central_difference(lambda u: angle(u, force), u0, 1e-4)]])
    assert jac.shape == (6, 6)
    scale = np.abs(expected).max(axis=0)
    assert np.all(np.abs(jac - expected) <= 1e-5 * scale + 1e-9)


def test_cable_jacobian_matches_central_differences():
    robot = tendon_robot()
    u0 = np.array([2.0, -1.0, 0.0])
    force = np.array([0.0, 0.0, -0.1])
    expected = central_difference(
        lambda u: robot.cable_lengths(robot.solve_ivp(u, force)), u0, 1e-4)
    scale = np.abs(expected).max(axis=0)
    assert np.all(np.abs(robot.cable_jacobian(u0, force) - expected) <= 1e-5 * scale)


@pytest.mark.parametrize('u0', [(3.0, -1.5, 0.0), (-4.0, 2.0, 0.0), (0.5, 0.2, 0.0)])
def test_estimation_round_trip_recovers_tip(u0):
    robot = tendon_robot()
    force = np.array([0.03, 0.0, -0.2])
    truth = robot.solve_ivp(u0, force)
    lengths = robot.cable_lengths(truth)
    cold = robot.estimate_shape(lengths, force)
    assert cold.converged and cold.message == ''
    assert np.linalg.norm(cold.shape.tip_position - truth.tip_position) < 1e-6
    assert cold.residual < 1e-8
    # warm start from a nearby estimate, as the node does every cycle
    nearby = robot.estimate_shape(lengths + 1e-3 * np.array([1, -1, -1, 1]) / 2, force)
    warm = robot.estimate_shape(lengths, force, warm_start=nearby)
    assert warm.converged
    assert np.linalg.norm(warm.shape.tip_position - truth.tip_position) < 1e-6
    assert warm.model_runs < cold.model_runs  # it reuses the nearby estimate's Jacobians


def test_estimate_has_no_twisting_tip_moment():
    robot = tendon_robot()
    truth = robot.solve_ivp([3.0, 1.0, 0.0], (0.1, 0.0, -0.1))
    # inconsistent lengths (noise): the least-squares estimate must still be twist-free. All
    # shortened: longer cables would be explained as slack (the tendon model), shorter ones
    # by no shape of inextensible cables
    lengths = robot.cable_lengths(truth) + np.array([-2e-4, -1e-4, 0.0, -3e-4])
    est = robot.estimate_shape(lengths, (0.1, 0.0, -0.1))
    local_tip_moment = robot.c * est.shape.u[-1]
    assert abs(local_tip_moment[2]) < 1e-10
    assert est.residual > 1e-5  # the noise cannot be explained by any shape


def test_single_opposing_pair_holds_unobservable_bending_passive():
    cables = [FOUR_CABLES[0], FOUR_CABLES[2]]  # holes along local x: only bending about y is seen
    robot = cable_robot(cables=cables)
    force = np.array([0.0, 0.05, 0.0])  # pushes the tip sideways, about local x
    passive = robot.solve_bvp(tip_force=force)
    truth = robot.solve_bvp(tip_force=force, tip_moment=(0.0, 0.01, 0.0))
    est = robot.estimate_shape(robot.cable_lengths(truth), force)
    assert est.observable_bending == 1
    assert 'observe 1 of 2' in est.message
    # bending about local x (unobservable) follows the passive equilibrium: zero tip moment
    assert abs((robot.c * est.shape.u[-1])[0]) < 1e-10
    assert est.shape.tip_position[1] == pytest.approx(passive.tip_position[1], abs=2e-3)
    assert np.allclose(robot.cable_lengths(est.shape), robot.cable_lengths(truth), atol=1e-9)


def test_no_cables_estimate_is_the_passive_equilibrium():
    robot = make_robot()
    force = (0.0, 0.0, -0.2)
    est = robot.estimate_shape([], force)
    assert est.observable_bending == 0
    expected = robot.solve_bvp(tip_force=force).tip_position
    assert np.linalg.norm(est.shape.tip_position - expected) < 1e-8


def test_tip_goal_on_reachable_surface_is_reached():
    robot = tendon_robot()
    force = np.array([0.0, 0.0, -0.1])
    goal = robot.solve_ivp([-2.5, 3.5, 0.0], force).tip_position
    sol = robot.solve_tip_goal(goal, force, tolerance=1e-5)
    assert sol.converged and sol.error < 1e-5
    assert np.linalg.norm(sol.shape.tip_position - goal) < 1e-5
    # the commanded lengths reproduce the goal through the estimator
    est = robot.estimate_shape(sol.cable_lengths, force)
    assert np.linalg.norm(est.shape.tip_position - goal) < 1e-5


def test_tip_goal_off_surface_reports_nearest_reachable():
    robot = tendon_robot()
    on_surface = robot.solve_ivp([2.0, 0.0, 0.0]).tip_position
    # push the goal 2 cm along the tip's outward normal-ish direction: radially inwards
    goal = on_surface + np.array([0.0, 0.0, -0.02])
    sol = robot.solve_tip_goal(goal, tolerance=1e-4)
    assert not sol.converged
    assert 'goal not reached' in sol.message
    assert sol.error == pytest.approx(np.linalg.norm(sol.shape.tip_position - goal))
    assert 1e-4 < sol.error < 0.02
    assert abs((robot.c * sol.shape.u[-1])[2]) < 1e-10  # still no twisting moment


def test_tip_goal_respects_cable_length_limits():
    robot = tendon_robot()
    # a half circle (tip at x = 2 L / pi, z = 0) needs cable_0 at 0.30 - 0.01 pi < 0.27 m
    sol = robot.solve_tip_goal([2 * robot.length / np.pi, 0.0, 0.0])
    lo, hi = robot.cable_length_limits.T
    assert not sol.converged
    assert sol.limited_cables
    assert np.all(sol.cable_lengths >= lo - 1e-9) and np.all(sol.cable_lengths <= hi + 1e-9)


@pytest.mark.parametrize('call', [
    lambda r: r.solve_ivp([np.nan, 0, 0]),
    lambda r: r.solve_ivp([0, 0]),
    lambda r: r.solve_ivp([0, 0, 0], tip_force=[0, np.inf, 0]),
    lambda r: r.estimate_shape([0.3, 0.3, 0.3]),
    lambda r: r.estimate_shape([0.3, 0.3, np.nan, 0.3]),
    lambda r: r.solve_tip_goal([0.1, np.nan, 0.2]),
    lambda r: r.solve_tip_goal([0.1, 0.0, 0.2], tolerance=0.0),
    lambda r: r.jacobian([0, 0, 0, 0]),
])
def test_bad_numeric_input_raises_value_error(call):
    with pytest.raises(ValueError):
        call(tendon_robot())


def test_external_tip_moment_enters_the_passive_directions():
    # an opposing pair along local x cannot bend the rod about local x; an external tip moment
    # about that axis must then be carried by the rod, and the estimate must show it
    robot = cable_robot(cables=[FOUR_CABLES[0], FOUR_CABLES[2]])
    force = np.array([0.0, 0.0, -0.1])
    external = np.array([0.004, 0.0, 0.0])
    # truth: the cables add 0.006 N m about the tip's local y (the only axis they can); the
    # tip frame depends on the shape, so iterate the BVP to the fixed point
    truth = robot.solve_bvp(tip_force=force, tip_moment=external)
    for _ in range(30):
        cable_moment = truth.tip_rotation @ [0.0, 0.006, 0.0]
        truth = robot.solve_bvp(tip_force=force, tip_moment=external + cable_moment,
                                u0_guess=truth.u0)
    assert np.allclose(truth.tip_moment, external + truth.tip_rotation @ [0.0, 0.006, 0.0],
                       atol=1e-12)
    lengths = robot.cable_lengths(truth)
    est = robot.estimate_shape(lengths, force, tip_moment=external)
    assert np.linalg.norm(est.shape.tip_position - truth.tip_position) < 1e-6
    ignored = robot.estimate_shape(lengths, force)
    assert np.linalg.norm(ignored.shape.tip_position - truth.tip_position) > 1e-3
    goal = robot.solve_tip_goal(truth.tip_position, force, tip_moment=external, tolerance=1e-6)
    assert goal.converged
