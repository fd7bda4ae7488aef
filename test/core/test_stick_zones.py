"""Stick zones: a reversed cable's friction turns over a travel ``tendons.stick_length``.

The friction state sigma (the fraction of the capstan band each hole holds) moves with the motor
travel and carries from call to call. Checked: its definition step by step, the limit of a
short stick length (the sliding model: the state is the sign of the last motion), that a
shape inside the stick zone lies between the pulled and the released branch at the same motor
position (friction only scales the band), recovery by the run calibration, and the robot file.
"""
import copy
import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from test_run_calibration import V6, truth_robot
from test_section_properties import make, robot_file
import yaml

from continuum_statics import load_robot
from continuum_statics.calibration.fit import fit
from continuum_statics.calibration.recorded_run import RecordedRun
from continuum_statics.calibration.replay import replay
from continuum_statics.calibration.robot_writer import write_robot_file
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.statics.length_statics import motion_since, solve_lengths

STICK = 1.7e-3  # m (not a multiple of the runs' steps: no state lands on +-1 by accident)


def with_stick(robot, stick, friction=0.08):
    tendons = dataclasses.replace(robot.tendons, stick_length=np.full(len(robot.cable_names),
                                                                      stick),
                                  friction=np.full(len(robot.cable_names), friction))
    return robot.__class__(dataclasses.replace(robot.description, tendons=tendons))


def cycle_run(robot, cable=0, depth=4e-3, step=2.5e-4):
    """One cable pulled by ``depth`` and released in ``step``s, the others held."""
    travel = np.concatenate([np.arange(0.0, depth, step), np.arange(depth, -step / 2, -step)])
    lengths = np.tile(robot.straight_cable_lengths, (len(travel), 1))
    lengths[:, cable] -= travel
    return RecordedRun(times=np.arange(len(travel), dtype=float), labels=('',) * len(travel),
                       lengths=lengths, tips=np.zeros((len(travel), 3)), source='cycle')


def test_the_state_turns_linearly_over_the_stick_length_and_ignores_noise():
    robot = with_stick(truth_robot(load_robot(V6)), STICK)
    free = np.full(9, 0.2)
    warm = SimpleNamespace(motion=np.ones(9), motion_reference=free.copy(), free_lengths=free)
    paid = free.copy()
    paid[0] += 0.25 * STICK  # paid out a quarter of the stick length: half way from +1 to 0
    paid[1] += 3.0 * STICK  # far beyond: fully turned
    paid[2] += 5e-8  # encoder noise under the motion threshold: no change
    paid[3] -= 1e-3  # pulled on: stays +1
    motion, reference = motion_since(robot, paid, warm)
    np.testing.assert_allclose(motion[:4], [0.5, -1.0, 1.0, 1.0])
    assert reference[2] == free[2] and reference[0] == paid[0]
    sliding = with_stick(truth_robot(load_robot(V6)), 0.0)
    np.testing.assert_array_equal(motion_since(sliding, paid, warm)[0][:4], [-1, -1, 1, 1])


def test_a_short_stick_length_is_the_sliding_model():
    robot = truth_robot(load_robot(V6))
    run = cycle_run(robot)
    sliding, _ = replay(with_stick(robot, 0.0), run)
    short, _ = replay(with_stick(robot, 1e-9), run)  # under the run's step: turns at once
    np.testing.assert_array_equal(short, sliding)
    sticky, _ = replay(with_stick(robot, STICK), run)
    assert np.max(np.linalg.norm(sticky - sliding, axis=1)) > 1e-4  # visible on the tip


def test_inside_the_stick_zone_the_shape_lies_between_the_two_branches():
    """After a reversal by less than the stick length, at the same motor position."""
    robot = with_stick(truth_robot(load_robot(V6)), STICK, friction=0.2)
    lengths = robot.straight_cable_lengths.copy()
    pulled = lengths.copy()
    pulled[0] -= 4e-3
    start = solve_lengths(robot, lengths)
    top = solve_lengths(robot, pulled, warm_start=start)  # pulled: sigma +1
    back = pulled.copy()
    back[0] += 0.25 * STICK  # half way from +1 to 0
    inside = solve_lengths(robot, back, warm_start=top)
    assert 0.0 < inside.motion[0] < 1.0
    branches = []
    for sigma in (1.0, -1.0):
        warm = dataclasses.replace(top, motion=np.where(np.arange(9) == 0, sigma, top.motion),
                                   motion_reference=robot.tendons.free_lengths(
                                       back, robot.straight_cable_lengths))
        branches.append(solve_lengths(robot, back, warm_start=warm).shape.tip_position)
    along = branches[1] - branches[0]
    fraction = float((inside.shape.tip_position - branches[0]) @ along / (along @ along))
    assert np.linalg.norm(along) > 1e-4 and 0.0 < fraction < 1.0
    assert inside.converged and all(solve.converged for solve in (start, top))


def test_the_fit_recovers_a_stick_length_from_a_synthetic_run(tmp_path):
    truth = with_stick(truth_robot(load_robot(V6)), STICK)
    runs = [cycle_run(truth, cable) for cable in (0, 4, 8)]
    run = RecordedRun(times=np.arange(sum(len(r) for r in runs), dtype=float),
                      labels=('',) * sum(len(r) for r in runs),
                      lengths=np.concatenate([r.lengths for r in runs]),
                      tips=np.zeros((sum(len(r) for r in runs), 3)), source='cycles')
    points, failed = replay(truth, run)
    assert not failed.any()
    run = dataclasses.replace(run, tips=points)
    start = with_stick(truth_robot(load_robot(V6)), 0.0, friction=0.05)
    model = RunModel(start, ['friction', 'stick_length'], run)
    result = fit(model, log=lambda line: None, workers=2)
    values = model.values(result.x)
    # the fit stops (ftol) at 0.3 um RMS: 1 % of the stick length moves the tips that little
    assert np.sqrt(np.mean(result.residuals ** 2)) < 1e-6
    assert values['stick_length'][0] == pytest.approx(STICK, rel=1e-2)
    assert values['friction'][0] == pytest.approx(0.08, rel=1e-3)
    path = tmp_path / 'fitted.yaml'
    write_robot_file(path, V6, model.robot_for(result.x, frame='tracker'), model.fit, [])
    np.testing.assert_allclose(load_robot(path).tendons.stick_length, values['stick_length'][0],
                               rtol=1e-5)


def test_robot_files_take_a_stick_length_and_refuse_a_negative_one():
    data = robot_file()
    data['tendons'] = {'friction': 0.1, 'stick_length': 0.002}
    assert np.all(make(data).tendons.stick_length == 0.002)
    data['tendons']['stick_length'] = -0.001
    with pytest.raises(ValueError, match='stick_length must be >= 0'):
        parse_robot_description(copy.deepcopy(data))
    assert np.all(make(robot_file()).tendons.stick_length == 0.0)


def test_a_fitted_stick_length_replaces_every_one_the_file_gave(tmp_path):
    document = yaml.safe_load(V6.read_text())
    document['tendons'] = dict(document.get('tendons') or {}, friction=0.1, stick_length=0.003)
    document['sections'][1]['cables'][0]['stick_length'] = 0.004
    source = tmp_path / 'source.yaml'
    source.write_text(yaml.safe_dump(document))
    assert load_robot(source).tendons.stick_length.max() == 0.004
    fitted = with_stick(load_robot(source), 0.0, friction=0.1)  # the fit found none
    write_robot_file(tmp_path / 'fitted.yaml', source, fitted, ['stick_length'], [])
    assert np.all(load_robot(tmp_path / 'fitted.yaml').tendons.stick_length == 0.0)
