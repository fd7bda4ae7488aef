"""The Cosserat IVP/BVP against independent truths: arcs, beam theory, elastica, convergence."""
from core_fixtures import make_robot, paper_rod
import numpy as np
import pytest

NO_GRAVITY = {'gravity': [0.0, 0.0, 0.0]}
UPRIGHT = {'base': {'frame_id': 'base_link', 'orientation': [0.0, 0.0, 0.0, 1.0]}}


def test_pure_tip_moment_gives_exact_circular_arc():
    # RK4 is not exact for a rotation at constant curvature: 64 steps put its error (~1e-10 m)
    # well below the 1e-9 m the arc is checked to
    robot = make_robot(**NO_GRAVITY, **UPRIGHT).with_solver(steps=64)
    ei = robot.c[0]
    moment = 1.2 * ei / robot.length  # 1.2 rad of total bending about global y
    shape = robot.solve_bvp(tip_moment=(0.0, moment, 0.0))
    kappa = moment / ei
    s = shape.s
    arc = np.stack([(1.0 - np.cos(kappa * s)) / kappa, np.zeros_like(s),
                    np.sin(kappa * s) / kappa], axis=1)
    assert np.allclose(shape.u0, [0.0, kappa, 0.0], rtol=0, atol=1e-9 * kappa)
    assert np.linalg.norm(shape.tip_position - arc[-1]) < 1e-9
    assert np.max(np.linalg.norm(shape.positions - arc, axis=1)) < 1e-9
    # the rotation stays orthonormal along the whole rod
    gram = np.einsum('nji,njk->nik', shape.rotations, shape.rotations)
    assert np.max(np.abs(gram - np.eye(3))) < 1e-12


@pytest.mark.parametrize('axis', [0, 1])
def test_small_tip_load_matches_euler_bernoulli(axis):
    # stiff rod, tiny load: deflection/L ~ 1e-4, so geometric nonlinearity is far below 0.5 %
    robot = make_robot(**NO_GRAVITY)
    load = 1e-4 * 3.0 * robot.c[0] / robot.length ** 2
    force = np.zeros(3)
    force[1 + axis] = -load  # rod along +x: load along -y or -z
    shape = robot.solve_bvp(tip_force=force)
    expected = load * robot.length ** 3 / (3.0 * robot.c[0])
    deflection = -shape.tip_position[1 + axis]
    assert deflection == pytest.approx(expected, rel=5e-3)


def test_small_self_weight_matches_euler_bernoulli():
    # thick rod so its own weight only deflects it by ~1e-4 L
    robot = make_robot(rod={'length': 0.39, 'diameter': 20e-3, 'youngs_modulus': 54.0e9,
                            'poisson_ratio': 0.3, 'density': 6800.0})
    w = robot.rod.mass_per_length * 9.81
    expected = w * robot.length ** 4 / (8.0 * robot.c[0])
    shape = robot.solve_bvp()
    assert -shape.tip_position[2] == pytest.approx(expected, rel=5e-3)


# Cantilever elastica with a tip load P normal to the undeformed rod: horizontal shortening
# (L - x)/L, deflection y/L and tip angle (rad) for P L^2 / (E I) = 1, 2, 5, 10.
# Bisshopp & Drucker, Q. Appl. Math. 3 (1945); Mattiasson, IJNME 17 (1981), Table I.
ELASTICA = [
    (1.0, 0.05643, 0.30172, 0.46135),
    (2.0, 0.16064, 0.49346, 0.78175),
    (5.0, 0.38763, 0.71379, 1.21537),
    (10.0, 0.55500, 0.81061, 1.43029),
]


@pytest.mark.parametrize('alpha,shortening,deflection,angle', ELASTICA)
def test_large_deflection_matches_published_elastica(alpha, shortening, deflection, angle):
    robot = make_robot(**NO_GRAVITY)
    length = robot.length
    load = alpha * robot.c[0] / length ** 2
    shape = robot.solve_bvp(tip_force=(0.0, 0.0, -load))  # from a straight start
    x, _, z = shape.tip_position
    assert abs((length - x) - shortening * length) < 1e-4 * length
    assert abs(-z - deflection * length) < 1e-4 * length
    tangent = shape.tip_rotation[:, 2]
    assert np.arctan2(-tangent[2], tangent[0]) == pytest.approx(angle, abs=1e-4)


def test_bvp_solves_beyond_the_papers_load_range():
    robot = paper_rod()
    for mass in (0.0, 0.045, 0.2, 1.0):
        shape = robot.solve_bvp(tip_force=(0.0, 0.0, -9.81 * mass))
        assert np.linalg.norm(shape.tip_moment) < 1e-8 * robot.c[0] / robot.length
        assert np.all(np.isfinite(shape.positions))


def test_rk4_converges_at_fourth_order():
    base = paper_rod()
    force = (0.0, 0.0, -9.81 * 0.045)
    u0 = base.with_solver(steps=4096).solve_bvp(tip_force=force).u0
    reference = base.with_solver(steps=4096).solve_ivp(u0, force).tip_position
    errors = [np.linalg.norm(base.with_solver(steps=n).solve_ivp(u0, force).tip_position
                             - reference) for n in (8, 16, 32, 64)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.6) & (orders < 4.4)), (errors, orders)


def test_default_steps_are_within_a_hundredth_of_a_millimetre():
    robot = paper_rod()
    fine = robot.with_solver(steps=2048)
    for mass in np.linspace(0.0, 0.045, 4):
        force = (0.0, 0.0, -9.81 * mass)
        error = np.linalg.norm(robot.solve_bvp(tip_force=force).tip_position
                               - fine.solve_bvp(tip_force=force).tip_position)
        assert error < 1e-5


def test_bvp_u0_fed_to_ivp_gives_the_requested_tip_load():
    robot = make_robot(**UPRIGHT)
    force = np.array([0.05, -0.02, -0.1])
    moment = np.array([0.002, -0.001, 0.0005])
    shape = robot.solve_bvp(tip_force=force, tip_moment=moment)
    replay = robot.solve_ivp(shape.u0, force)
    assert np.allclose(replay.tip_moment, moment, atol=1e-9)
    assert np.allclose(replay.n[-1], force, atol=1e-9)
    # eq. 3 with uniform gravity: n(0) = F + rho A g L e_g
    weight = robot.rod.mass_per_length * robot.length * np.array(robot.gravity)
    assert np.allclose(replay.n[0], force + weight, atol=1e-9)


def test_sagging_paper_rod_bends_down_and_shortens():
    robot = paper_rod()
    light = robot.solve_bvp(tip_force=(0.0, 0.0, -0.01 * 9.81)).tip_position
    heavy = robot.solve_bvp(tip_force=(0.0, 0.0, -0.04 * 9.81)).tip_position
    assert heavy[2] < light[2] < 0.0
    assert heavy[0] < light[0] < robot.length
    assert abs(heavy[1]) < 1e-12
