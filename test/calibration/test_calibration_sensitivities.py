"""Exact tip sensitivities (implicit-function theorem) against re-solved replays.

The reference re-solves every row of the run at parameters moved both ways (each row started
from the base replay's solution of it, friction directions held, converged to 1e-12 m of
cable and a tip balance of 1e-12), Richardson-extrapolated central differences of two steps:
no part of it uses the sensitivities' linearisation. Both cable models, every physical fit
name, friction inside its range (0.08) so the central differences do not meet its bound.

Agreement: 1e-5 of each column, plus what the reference cannot resolve: re-solved points
carry up to :data:`REPLAY_FLOOR` of solver noise, which a step h turns into FLOOR / h per row
(the columns a run barely sees: extension and shear without a tip load).
"""
import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_run_calibration import V6, pulls, truth_robot

from continuum_statics import load_robot
from continuum_statics.calibration.fit import fit
from continuum_statics.calibration.recorded_run import RecordedRun
from continuum_statics.calibration.replay import replay
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.calibration.sensitivities import point_sensitivities, stencil
from continuum_statics.core.statics import length_statics

#: Every physical fit name (cable_stiffness replaces stiffness: a case of its own).
NAMES = ['section_rotation', 'cable_angle', 'cable_zero', 'stiffness', 'pretension', 'friction',
         'youngs_modulus', 'density', 'gravity', 'tip_marker', 'section_length',
         'section_bending', 'disk_mass', 'extension_shear']
#: Reference steps, in finite-difference replay steps (DIFFERENCE_STEPS): large where the model
#: is smooth, so the replays' convergence floor adds little; small for the names that move the
#: point where a cable goes slack or taut (a kink within +-10 steps on some rows: cable_zero
#: at 30 steps reads 1e-2 wrong, section_length and disk_mass at 10 steps 0.2 and 1e-2), and
#: the stick length, where a friction state reaches +-1 (the stick length 1.7 mm is not a
#: multiple of the run's 1 mm steps, which would put a kink at the base itself).
#: Friction: 0.08 +- 0.01 stays inside [0, 1].
REFERENCE_STEP_FACTOR = 30.0
#: m: largest difference of a replay's points started from two different warm starts (measured
#: 2.2e-11 and 1.8e-11 on the two robots here).
REPLAY_FLOOR = 3e-11
KINKED = {'cable_zero': 10.0, 'pretension': 10.0, 'section_length': 0.1, 'disk_mass': 0.1,
          'stick_length': 1.0}


def robot_with(cable_model, stick_length=0.0):
    """Return the truth robot of test_run_calibration with weak gravity and disk masses."""
    robot = truth_robot(load_robot(V6))
    sections = tuple(dataclasses.replace(s, disk_mass=5e-4) for s in robot.description.sections)
    tendons = dataclasses.replace(robot.tendons, stick_length=np.full(9, stick_length))
    return robot.__class__(dataclasses.replace(
        robot.description, cable_model=cable_model, gravity=np.array([0.0, -1.0, 0.0]),
        sections=sections, tendons=tendons))


def run_for(robot, tracker=np.eye(3)):
    """Return pulls and releases of every cable, tips seen in a ``tracker`` frame, 1 mm off."""
    lengths = pulls(robot, steps=2)
    run = RecordedRun(times=np.arange(len(lengths), dtype=float), labels=('',) * len(lengths),
                      lengths=lengths, tips=np.zeros((len(lengths), 3)), source='synthetic')
    points, failed = replay(robot, run)
    assert not failed.any()
    return dataclasses.replace(run, tips=points @ tracker.T + 1e-3)


def reference_steps(model):
    """Return the reference's step of every variable and the variables' fit names."""
    steps = model.vector.steps() * REFERENCE_STEP_FACTOR
    names = np.concatenate([[b.name] * b.start.size for b in model.blocks])
    steps[names == 'friction'] = 1e-2
    for name, factor in KINKED.items():
        steps[names == name] *= factor / REFERENCE_STEP_FACTOR
    return steps, names


def richardson(function, x, j, step):
    """Return d function / d x_j: central differences of ``step`` and half of it, extrapolated."""
    central = []
    for h in (step, step / 2.0):
        sides = []
        for sign in (1.0, -1.0):
            trial = x.copy()
            trial[j] += sign * h
            sides.append(function(trial))
        central.append((sides[0] - sides[1]) / (2.0 * h))
    return (4.0 * central[1] - central[0]) / 3.0


def reference(model, x, solutions):
    """Return d point / d variable (rows, 3, m) from re-solved replays (Richardson, central)."""
    steps, names = reference_steps(model)
    out = np.empty((len(model.run.tips), 3, model.size))
    for j in range(model.size):
        # the friction state's chain is the stick length's effect: whole replays
        held = None if names[j] == 'stick_length' else solutions
        out[:, :, j] = richardson(lambda trial: model.points(trial, starts=held)[0], x, j,
                                  steps[j])
    return out, names, steps


@pytest.mark.parametrize('cable_model, names, stick_length', [
    ('point_moment', NAMES, 0.0), ('distributed', NAMES, 0.0),
    ('distributed', ['cable_stiffness'], 0.0),
    ('point_moment', ['friction', 'stick_length', 'cable_zero'], 1.7e-3),
    ('point_moment', ['registration', 'gravity', 'cable_angle'], 0.0)])
def test_sensitivities_equal_re_solved_replays(cable_model, names, stick_length, monkeypatch):
    monkeypatch.setattr(length_statics, 'BALANCE_TOLERANCE', 1e-12)
    robot = robot_with(cable_model, stick_length)
    # with a registration the fit's evaluation moves it after the replay: gravity (tracker
    # frame) must stay turned as that replay had it
    tracker = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    model = RunModel(robot, names, run_for(robot, tracker))
    x = model.start()
    model.residuals(x, update=True)
    assert 'registration' not in names or not np.allclose(model.rotation, model.gravity_frame)
    solutions = model.solutions
    exact = point_sensitivities(model, x, solutions, workers=2)
    expected, names, steps = reference(model, x, solutions)
    rows = len(solutions)
    for j in range(model.size):
        size = np.linalg.norm(expected[:, :, j])
        assert size > 0.0, names[j]
        floor = 2.0 * np.sqrt(3 * rows) * REPLAY_FLOOR / steps[j]
        assert np.linalg.norm(exact[:, :, j] - expected[:, :, j]) <= 1e-5 * size + floor, \
            names[j]
        # where the reference resolves a column, the bound alone
        if size > 1e3 * floor:
            assert np.linalg.norm(exact[:, :, j] - expected[:, :, j]) <= 1e-5 * size


def test_a_row_without_a_solution_has_no_sensitivity():
    robot = robot_with('point_moment')
    model = RunModel(robot, ['cable_zero'], run_for(robot))
    x = model.start()
    model.points(x)
    full = point_sensitivities(model, x, model.solutions)
    solutions = list(model.solutions)
    solutions[3] = None  # its solve raised
    exact = point_sensitivities(model, x, solutions, workers=2)
    assert np.any(full[3] != 0.0) and np.all(exact[3] == 0.0)
    assert np.array_equal(np.delete(exact, 3, axis=0), np.delete(full, 3, axis=0))


def test_stencils_stay_inside_the_bounds():
    assert stencil(0.5, 0.1, 0.0, 1.0) == ((-0.1, 0.1), (-0.5, 0.5))
    offsets, weights = stencil(0.0, 0.1, 0.0, 1.0)  # friction found to be none
    assert min(offsets) == 0.0 and sum(weights) == 0.0
    assert sum(w * o for w, o in zip(weights, offsets)) == pytest.approx(0.1)  # d x / d x = 1
    offsets, weights = stencil(1.0, 0.1, 0.0, 1.0)
    assert max(offsets) == 0.0 and sum(w * o for w, o in zip(weights, offsets)) == \
        pytest.approx(0.1)


def test_a_fit_on_exact_jacobians_ends_where_the_finite_difference_fit_does():
    """The synthetic run's zero offsets and stiffness (test_run_calibration's truth)."""
    truth = robot_with('point_moment')
    run = run_for(truth)
    run = dataclasses.replace(run, tips=run.tips - 1e-3)
    nominal = load_robot(V6)
    ends = {}
    for jacobian in ('implicit', 'differences'):
        model = RunModel(nominal, ['cable_zero', 'stiffness', 'friction'], run)
        result = fit(model, log=lambda line: None, workers=2, jacobian=jacobian)
        ends[jacobian] = model.errors(result.x, run)[0]
    # the finite-difference fit ends where the round-off of its Jacobians lets it: fused
    # multiply-adds in the kernel (the same model to ~1e-15) moved its RMS from 38.872 to
    # 39.154 mm while the implicit fit's stayed at 38.969 mm (to 1e-11)
    assert np.sqrt(np.mean(np.sum(ends['implicit'] ** 2, axis=1))) == pytest.approx(
        np.sqrt(np.mean(np.sum(ends['differences'] ** 2, axis=1))), abs=5e-4)


def test_the_residual_jacobian_lets_the_registration_follow(monkeypatch):
    """RunModel.jacobian against re-solved residuals: Kabsch registration and gauge rows."""
    monkeypatch.setattr(length_statics, 'BALANCE_TOLERANCE', 1e-12)
    robot = robot_with('point_moment')
    tracker = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    model = RunModel(robot, ['registration', 'section_rotation', 'cable_angle', 'cable_zero',
                             'tip_marker'], run_for(robot, tracker))
    x = model.start()
    model.residuals(x, update=True)
    solutions, points = model.solutions, model.replayed
    exact = model.jacobian(x, points, point_sensitivities(model, x, solutions, workers=2))
    steps, _ = reference_steps(model)
    for j in range(model.size):
        expected = richardson(lambda trial: model.residuals(trial, starts=solutions), x, j,
                              steps[j])
        size = np.linalg.norm(expected)
        floor = 2.0 * np.sqrt(expected.size) * REPLAY_FLOOR / steps[j]
        assert size > 0.0
        assert np.linalg.norm(exact[:, j] - expected) <= 1e-5 * size + floor, j
    assert exact.shape[0] > 3 * len(points)  # the gauge rows are there
