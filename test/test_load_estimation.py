"""Tip-load estimation (``robot.estimate_tip_wrench``) against loads applied by forward solves.

Truth: a known tip load applied with ``solve_tensions`` / ``solve_lengths`` / ``solve_bvp``
(forward statics, not the estimator's inversion), measurements made from that equilibrium and
perturbed by seeded Gaussian noise of the stated standard deviations. The estimator must land
inside its own 3-sigma box in >= 95 % of the cases, and its reported standard deviations must
match the scatter of its errors within a factor 2 in the directions the measurements see.
"""
import dataclasses

from conftest import REPO
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.core.load_estimation import DEFAULT_NOISE, plausible_tip_load
from continuum_statics.core.robot import Robot
from continuum_statics.core.tendons import full_circle_tension

EXAMPLES = sorted(path.name for path in (REPO / 'config').glob('*.yaml')
                  if not path.name.endswith('params.yaml'))
CASES = 200
SIGMA_LENGTH, SIGMA_TENSION, SIGMA_TIP = (DEFAULT_NOISE['length'], DEFAULT_NOISE['tension'],
                                          DEFAULT_NOISE['tip_position'])


def robot_with_model(name, model):
    robot = load_robot(REPO / 'config' / name)
    return Robot(dataclasses.replace(robot.description, cable_model=model))


def load_scale(robot):
    """E I / L^2 (N): test loads are 0.1-2 of it (0.05-1 N on the example robots)."""
    return float(robot.c[0]) / robot.length ** 2


def applied_case(robot, rng):
    """Return (true force, measurements): a random load and tensions, measured with noise."""
    n = len(robot.cable_names)
    # loads that push along the rod stay below half the Euler buckling load pi^2 E I / (4 L^2):
    # nearer, a rod bent by a push explains a tip as well as a lateral load (two branches)
    while True:
        direction = rng.normal(size=3)
        force = direction / np.linalg.norm(direction) * rng.uniform(0.1, 2.0) * load_scale(robot)
        if -force @ robot.base_rotation[:, 2] < 0.5 * np.pi ** 2 / 4.0 * load_scale(robot):
            break
    if n == 0:
        shape = robot.solve_bvp(force)
        tip = shape.tip_position + shape.tip_rotation @ robot.tip_marker
        return force, {'tip_position': tip + rng.normal(0.0, SIGMA_TIP, 3)}
    # taut cables, each at least 3 sigma above zero (a reading is never below zero)
    low = robot.tendons.tension_limits[:, 0] + robot.tendons.pretension + 3.0 * SIGMA_TENSION
    tensions = low + rng.uniform(0.0, 0.05 * full_circle_tension(robot), n)
    shape = robot.solve_tensions(tensions, force)
    paths = robot.cable_lengths(shape)
    if robot.tendons.is_ideal:
        lengths, measured = paths, tensions
    else:  # the motors hold the lengths that give these tensions
        free = paths / (1.0 + tensions * robot.tendons.compliance)
        lengths = robot.tendons.lengths_for(free, robot.straight_cable_lengths)
        solution = robot.solve_lengths(lengths, force)
        assert solution.converged, solution.message
        np.testing.assert_allclose(solution.tensions, tensions, rtol=1e-5, atol=1e-8)
        measured = solution.tensions
    return force, {'lengths': lengths + rng.normal(0.0, SIGMA_LENGTH, n),
                   'tensions': np.maximum(measured + rng.normal(0.0, SIGMA_TENSION, n), 0.0)}


@pytest.mark.parametrize('model', ['point_moment', 'distributed'])
@pytest.mark.parametrize('name', EXAMPLES)
def test_estimates_fall_inside_their_covariance(name, model):
    robot = robot_with_model(name, model)
    rng = np.random.default_rng(2024)
    inside, converged, whitened = 0, 0, []
    for _ in range(CASES):
        force, measurements = applied_case(robot, rng)
        estimate = robot.estimate_tip_wrench(**measurements)
        assert np.all(np.isfinite(estimate.force)) and np.all(np.isfinite(estimate.covariance))
        error = estimate.force - force
        inside += bool(np.all(np.abs(error) <= 3.0 * estimate.sigma))
        converged += estimate.converged
        # the error along each direction the measurements pin down (sigma below a quarter of
        # E I / L^2, the scale of the loads applied here), in units of its reported sigma;
        # elsewhere the prior (10 E I / L^2, wider than these loads) speaks
        values, vectors = np.linalg.eigh(estimate.covariance)
        seen = values < (0.25 * load_scale(robot)) ** 2
        whitened.extend(error @ vectors[:, seen] / np.sqrt(values[seen]))
    assert inside >= 0.95 * CASES, '%d of %d inside 3 sigma' % (inside, CASES)
    assert converged >= 0.95 * CASES, '%d of %d converged' % (converged, CASES)
    # the reported sigma is the scatter's within a factor 2 (robust: 1.4826 median absolute
    # deviation, so that the few cases outside 3 sigma do not set it)
    whitened = np.array(whitened)
    assert whitened.size >= CASES // 4, 'the measurements see almost nothing'
    scatter = 1.4826 * np.median(np.abs(whitened - np.median(whitened)))
    assert 0.5 <= scatter <= 2.0, scatter


def test_tip_position_alone_gives_the_force_on_a_rod_without_cables():
    rod = load_robot(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    force = np.array([0.05, -0.08, 0.02])
    shape = rod.solve_bvp(force)
    estimate = rod.estimate_tip_wrench(tip_position=shape.tip_position,
                                       noise={'tip_position': 1e-6})
    assert estimate.converged, estimate.message
    # the rod's axial stiffness hides the force along the tip's axis; the others: exact
    seen = np.linalg.eigh(estimate.covariance)[1][:, :2]
    np.testing.assert_allclose(seen.T @ estimate.force, seen.T @ force, atol=1e-4)
    assert np.all(np.abs(estimate.force - force) <= 3.0 * estimate.sigma)


def test_force_and_moment_from_a_tracked_tip_pose():
    rod = load_robot(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    force, moment = np.array([0.03, -0.02, 0.0]), np.array([0.0, 0.004, -0.002])
    shape = rod.solve_bvp(force, moment)
    estimate = rod.estimate_tip_wrench(tip_position=shape.tip_position,
                                       tip_rotation=shape.tip_rotation, moment=True,
                                       noise={'tip_position': 1e-7, 'tip_angle': 1e-6})
    assert estimate.covariance.shape == (6, 6)
    np.testing.assert_allclose(estimate.moment, moment, atol=1e-5)
    lateral = [0, 1]
    np.testing.assert_allclose(estimate.force[lateral], force[lateral], atol=1e-4)


def test_the_unseen_direction_is_named_and_held_at_zero():
    # a straight single-section robot: cable tensions and lengths cannot tell an axial push
    robot = load_robot(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
    force = np.array([0.0, 0.0, -0.8])
    solution = robot.solve_lengths(robot.straight_cable_lengths, force)
    estimate = robot.estimate_tip_wrench(lengths=robot.straight_cable_lengths,
                                         tensions=solution.tensions)
    axial = robot.base_rotation[:, 2]
    assert len(estimate.unseen) == 1
    assert abs(estimate.unseen[0] @ axial) > 0.99
    assert 'do not determine the tip force along' in estimate.message
    assert abs(estimate.force @ axial) < 1e-3 * plausible_tip_load(robot)[0]
    assert estimate.sigma @ np.abs(axial) > 0.5 * plausible_tip_load(robot)[0]


def test_warm_estimates_follow_a_changing_load():
    robot = load_robot(REPO / 'config' / 'three_section_robot_real_tendons.yaml')
    rng = np.random.default_rng(5)
    tensions = robot.tendons.pretension + rng.uniform(0.0, 1.0, len(robot.cable_names))
    shape = robot.solve_tensions(tensions)
    free = robot.cable_lengths(shape) / (1.0 + tensions * robot.tendons.compliance)
    lengths = robot.tendons.lengths_for(free, robot.straight_cable_lengths)
    warm, solution = None, None
    for k in range(10):
        force = np.array([0.02 * k, -0.01 * k, 0.0])
        solution = robot.solve_lengths(lengths, force, warm_start=solution)
        warm = robot.estimate_tip_wrench(lengths=lengths, tensions=solution.tensions,
                                         warm_start=warm)
        cold = robot.estimate_tip_wrench(lengths=lengths, tensions=solution.tensions)
        assert warm.converged and cold.converged
        assert warm.iterations <= cold.iterations
        np.testing.assert_allclose(warm.force[:2], force[:2], atol=3.0 * warm.sigma[:2].max())
        np.testing.assert_allclose(warm.force, cold.force, atol=0.1 * warm.sigma.max())


def test_percent_tension_noise_scales_the_covariance():
    robot = load_robot(REPO / 'config' / 'three_section_robot.yaml')
    tensions = np.full(len(robot.cable_names), 2.0)
    shape = robot.solve_tensions(tensions, [0.1, 0.0, 0.0])
    lengths = robot.cable_lengths(shape)
    small = robot.estimate_tip_wrench(lengths=lengths, tensions=tensions,
                                      noise={'tension': '1%'})
    large = robot.estimate_tip_wrench(lengths=lengths, tensions=tensions,
                                      noise={'tension': '5%'})
    assert np.all(large.sigma > small.sigma)


@pytest.mark.parametrize('arguments, words', [
    ({}, 'no measurement given'),
    ({'tensions': [-1.0] * 9}, 'tensions must be >= 0'),
    ({'tip_position': [0, 0, 0.3], 'noise': {'lenght': 1e-5}}, "unknown key 'lenght'"),
    ({'tip_position': [0, 0, 0.3], 'noise': {'length': 0.0}}, 'noise length must be'),
    ({'tip_rotation': np.ones((3, 3))}, '3x3 rotation matrix'),
    ({'lengths': [0.3] * 4}, 'lengths must'),
])
def test_bad_arguments_name_the_problem(arguments, words):
    robot = load_robot(REPO / 'config' / 'three_section_robot.yaml')
    with pytest.raises(ValueError, match=words):
        robot.estimate_tip_wrench(**arguments)


def _stiffer(robot, factor):
    rod = dataclasses.replace(robot.description.rod,
                              youngs_modulus=robot.rod.youngs_modulus * factor)
    return Robot(dataclasses.replace(robot.description, rod=rod))


def test_a_payload_is_a_weight_from_the_tip_position_alone():
    """Issue 35: a hanging mass, 0-50 g, on a rod whose E is 5 % off, tracker noise 1 mm.

    With load='weight' the mass is one unknown along gravity and comes out within the 5 % the
    wrong E makes. The general 3-D force trades it against a force along the rod, and its
    covariance does not cover that (printed, not asserted: left for the general estimator).
    """
    rod = load_robot(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    truth = _stiffer(rod, 1.05)
    rng = np.random.default_rng(35)
    errors, normalised = [], []
    for mass in np.linspace(0.0, 0.05, 11):
        force = mass * np.asarray(rod.gravity)
        shape = truth.solve_bvp(tip_force=force)
        tip = shape.tip_position + shape.tip_rotation @ rod.tip_marker + rng.normal(0, 1e-3, 3)
        weight = rod.estimate_tip_wrench(tip_position=tip, noise={'tip_position': 1e-3},
                                         load='weight')
        assert weight.converged and weight.mass_sigma < 1e-3
        np.testing.assert_allclose(weight.force, weight.mass * np.asarray(rod.gravity))
        errors.append(weight.mass - mass)
        assert abs(weight.mass - mass) < 0.06 * mass + 3 * weight.mass_sigma
        for model, what in ((truth, 'right E'), (rod, 'E 5 % off')):
            general = model.estimate_tip_wrench(tip_position=tip, noise={'tip_position': 1e-3})
            values, vectors = np.linalg.eigh(general.covariance)
            normalised.append((what, np.max(np.abs(vectors.T @ (general.force - force))
                                            / np.sqrt(values))))
    print('mass RMS %.2f g; 3-D force, largest normalised error: right E %.2f, E 5 %% off %.1f'
          % (1e3 * np.sqrt(np.mean(np.square(errors))),
             max(v for w, v in normalised if w == 'right E'),
             max(v for w, v in normalised if w != 'right E')))
    assert 1e3 * np.sqrt(np.mean(np.square(errors))) < 2.0  # g


def test_load_models_agree_and_refuse_what_they_cannot_be():
    rod = load_robot(REPO / 'config' / 'jones2009_nitinol_rod.yaml')
    shape = rod.solve_bvp(tip_force=0.02 * np.asarray(rod.gravity))
    tip = shape.tip_position + shape.tip_rotation @ rod.tip_marker
    weight = rod.estimate_tip_wrench(tip_position=tip, load='weight')
    along = rod.estimate_tip_wrench(tip_position=tip, load=('direction', rod.gravity))
    np.testing.assert_allclose(along.force, weight.force, rtol=1e-6, atol=1e-9)
    assert weight.mass == pytest.approx(0.02, rel=1e-3) and along.mass is None
    robot = load_robot(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
    lengths = robot.straight_cable_lengths - np.array([0.003, 0.0, 0.0, 0.0])
    wrench = robot.estimate_tip_wrench(lengths=lengths, tensions=np.full(4, 2.0),
                                       load='wrench')
    moment = robot.estimate_tip_wrench(lengths=lengths, tensions=np.full(4, 2.0), moment=True)
    np.testing.assert_allclose(wrench.wrench, moment.wrench)
    for bad, expected in ((('size',), 'load must be one of'), ('mass', 'load must be one of'),
                          (('direction', (0, 0, 0)), 'must not be zero')):
        with pytest.raises(ValueError, match=expected):
            rod.estimate_tip_wrench(tip_position=tip, load=bad)
    flat = Robot(dataclasses.replace(rod.description, gravity=np.zeros(3)))
    with pytest.raises(ValueError, match='gravity is zero'):
        flat.estimate_tip_wrench(tip_position=tip, load='weight')
