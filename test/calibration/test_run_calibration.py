"""Calibration from recorded runs: recovers known parameters of synthetic runs; the real v6 data.

Synthetic truth: a run made by replaying single-tendon pulls and releases through a robot with
known hole-pattern rotations, zero offsets, tendon stiffness and friction, seen by a tracker in
a known (unknown to the fit) frame, plus noise. The fit starts from the nominal robot file.
"""
import dataclasses
import gc
import json

from conftest import REPO
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from continuum_statics import load_robot
from continuum_statics.calibration.fit import fit
from continuum_statics.calibration.parameters import turned
from continuum_statics.calibration.pool import fork_pool
from continuum_statics.calibration.recorded_run import ColumnMap, RecordedRun, read_recorded_run
from continuum_statics.calibration.replay import replay, rms
from continuum_statics.calibration.robot_writer import write_robot_file
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.calibration.runs import calibrate_run
from continuum_statics.calibration.selection import moves_the_tips, select
from continuum_statics.core.description.tendons import Tendons
from continuum_statics.tools import calibrate

V6 = REPO / 'config' / 'ftdcr_v6_robot.yaml'
DATA = REPO / 'test' / 'data' / 'ftdcr_v6'
#: Tip RMS (m) of the calibrated v6 robot file on its fitting and held-out runs (closing notes of
#: issues 14 and 21: train 8.15 mm, held out 11.37 mm; exact-Jacobian fit 8.15 / 11.36; guards
#: 0.1 mm above).
TRAIN_GUARD = 8.25e-3
VAL_GUARD = 11.47e-3


def pulls(robot, depth=0.004, steps=4, payout=0.5):
    """Motor lengths of each cable pulled by ``depth`` m and released, the others paid out."""
    rows = []
    straight = robot.straight_cable_lengths
    for j in range(len(robot.cable_names)):
        for k in list(range(1, steps + 1)) + list(range(steps - 1, -1, -1)):
            d = depth * k / steps
            lengths = straight + payout * d
            lengths[j] = straight[j] - d
            rows.append(lengths)
    return np.array(rows)


def truth_robot(robot):
    offsets = turned(robot.description.cable_offsets, np.repeat([0.0, 1.2, -0.9], 3))
    tendons = dataclasses.replace(
        Tendons.default(9), stiffness=np.repeat([300.0, 500.0, 800.0], 3),
        friction=np.full(9, 0.08),
        zero_offset=np.array([2, -1, 0, 1, 3, -2, 0, -1, 2], dtype=float) * 1e-4)
    return robot.__class__(dataclasses.replace(robot.description, cable_offsets=offsets,
                                               tendons=tendons))


def synthetic_run(robot, noise=5e-5, seed=3):
    lengths = pulls(robot)
    run = RecordedRun(times=np.arange(len(lengths), dtype=float), labels=('',) * len(lengths),
                      lengths=lengths, tips=np.zeros((len(lengths), 3)), source='synthetic')
    points, failed = replay(truth_robot(robot), run)
    assert not failed.any()
    rotation = Rotation.from_rotvec([0.2, -0.3, 0.25]).as_matrix()
    tips = points @ rotation.T + np.array([0.01, -0.02, 0.03])
    tips += np.random.default_rng(seed).normal(0.0, noise, tips.shape)
    return dataclasses.replace(run, tips=tips), rotation


def stretchy_v6(**changes):
    """Return the v6 file with stretchy, pretensioned cables (500 N, 1 N), as real ones are."""
    nominal = load_robot(V6)
    tendons = dataclasses.replace(Tendons.default(9), stiffness=np.full(9, 500.0),
                                  pretension=np.full(9, 1.0))
    return nominal.__class__(dataclasses.replace(nominal.description, tendons=tendons,
                                                 **changes))


def run_of(truth):
    """Return the exact run of :func:`pulls` on ``truth``: its replayed tips, no noise."""
    lengths = pulls(truth)
    run = RecordedRun(times=np.arange(len(lengths), dtype=float), labels=('',) * len(lengths),
                      lengths=lengths, tips=np.zeros((len(lengths), 3)), source='synthetic')
    points, failed = replay(truth, run)
    assert not failed.any()
    return dataclasses.replace(run, tips=points)


def write_run_csv(path, robot, run):
    """Write a run as a lab's CSV (motor displacements and tips in mm); returns (path, header)."""
    header = ['timestamp'] + ['%s_mm' % n for n in robot.cable_names] + ['tip_x', 'tip_y',
                                                                          'tip_z']
    rows = np.column_stack([run.times, (robot.straight_cable_lengths - run.lengths) * 1e3,
                            run.tips * 1e3])
    np.savetxt(path, rows, delimiter=',', header=','.join(header), comments='')
    return path, header


def _collect_in_worker(_):
    return gc.collect() >= 0


@pytest.mark.ros
def test_fit_workers_survive_an_rclpy_node_left_as_garbage_by_the_parent():
    # Seen in the full suite: a worker forked after the DDS tests collected a dead node's cycle
    # and segfaulted (BrokenProcessPool). The node here is dropped in a cycle and left for the
    # collector, as a test or tool in the same process leaves it.
    rclpy = pytest.importorskip('rclpy')
    from std_msgs.msg import String
    enabled = gc.isenabled()
    gc.disable()
    try:
        context = rclpy.Context()
        rclpy.init(context=context)
        for index in range(3):
            node = rclpy.create_node('calibration_garbage_%d' % index, context=context)
            node.create_publisher(String, 'garbage', 10)
            cycle = {'node': node}
            cycle['cycle'] = cycle
            del node, cycle
        with fork_pool(2) as pool:
            assert all(pool.map(_collect_in_worker, range(4)))
    finally:
        if enabled:
            gc.enable()


def test_fit_recovers_the_parameters_of_a_synthetic_run():
    robot = load_robot(V6)
    run, rotation = synthetic_run(robot)
    model = RunModel(robot, ['registration', 'section_rotation', 'cable_zero', 'stiffness',
                             'friction'], run)
    lines = []
    result = fit(model, log=lines.append, workers=2)
    values = model.values(result.x)
    errors, _ = model.errors(result.x, run)
    assert rms(errors) < 1.5e-4  # noise 0.05 mm per axis: 0.087 mm RMS
    # patterns turned by 69 and -52 degrees from the file's: found by the scan, then refined
    assert np.allclose(values['section_rotation'], [1.2, -0.9], atol=0.01)
    assert np.allclose(values['friction'], 0.08, atol=0.02)
    assert np.allclose(values['stiffness'], [300.0, 500.0, 800.0], rtol=0.25)
    assert np.allclose(model.rotation, rotation, atol=0.01)
    assert np.allclose(values['cable_zero'] * 1e4, [2, -1, 0, 1, 3, -2, 0, -1, 2], atol=0.5)
    assert len(lines) >= 3 and 'RMS' in lines[-1]  # progress, a line per evaluation
    assert 'pattern rotations scanned' in lines[0]


def test_calibrate_command_on_a_recorded_csv_writes_a_robot_file_that_reproduces_the_fit(
        tmp_path, capsys):
    robot = load_robot(V6)
    run, _ = synthetic_run(robot)
    csv, header = write_run_csv(tmp_path / 'run.csv', robot, run)
    output = tmp_path / 'calibrated.yaml'
    code = calibrate.main([
        '--robot', str(V6), '--data', str(csv), '--validate', str(csv), '--json',
        '--fit', 'registration', 'section_rotation', 'stiffness', 'friction',
        '--max-evaluations', '6',
        '--cable-columns', ','.join(header[1:10]), '--cable-kind', 'displacement',
        '--cable-scale', '0.001', '--tip-scale', '0.001', '--output', str(output),
        '--model-uncertainty'])
    assert code == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary['rms_after'] < 0.5 * summary['rms_before']  # zero offsets not fitted
    assert summary['validate_rms'] == pytest.approx(summary['rms_after'], rel=1e-6)
    assert summary['rms_aligned_after'] <= summary['rms_after']
    # the written file, replayed in its own (tracker) frame, gives the fitted errors
    written = load_robot(output)
    points, failed = replay(written, run)
    assert not failed.any()
    # the model's own error, measured on the run, is written (state estimation's prior)
    uncertainty = written.model_uncertainty
    assert uncertainty.correlation_time == pytest.approx(
        summary['model_uncertainty']['correlation_time'], rel=1e-5)
    assert uncertainty.any and uncertainty.correlation_time > 0.0
    assert rms(points - run.tips) == pytest.approx(summary['rms_after'],
                                                                    rel=1e-3)


def test_unknown_fit_names_are_refused(tmp_path):
    with pytest.raises(ValueError, match='unknown parameter.*fittable: registration'):
        calibrate_run(V6, DATA / 'tendon_pull_subset.csv', ['elasticity'],
                                      None)


def test_the_calibrated_v6_robot_keeps_its_held_out_error():
    """Guard the real robot's figures: the calibrated file replays its runs within them.

    config/ftdcr_v6_calibrated.yaml is what ``calibrate`` wrote from train.csv (its header says
    how); val.csv was never fitted. Replayed in the tracker's frame, registration held.
    """
    robot = load_robot(REPO / 'config' / 'ftdcr_v6_calibrated.yaml')
    columns = read_column_map(robot)
    for name, guard in (('train.csv', TRAIN_GUARD), ('val.csv', VAL_GUARD)):
        run = read_recorded_run(DATA / name, robot.cable_names, robot.straight_cable_lengths,
                                columns)
        points, failed = replay(robot, run)
        assert not failed.any()
        errors = points - run.tips
        assert rms(errors) < guard, name


def read_column_map(robot):
    return ColumnMap(cables=tuple('%s_mm' % name for name in robot.cable_names),
                     kind='displacement', scale=1e-3, tip_scale=1e-3)


def test_fit_recovers_section_lengths_and_writes_them(tmp_path):
    """Sections 1 mm longer, 1 mm shorter and 0.5 mm longer than the file says: found.

    The truth moves the guides with their section; the run's motor lengths are the truth's
    (homed straight). Cables stretch and carry a pretension, as real ones do.
    """
    robot = stretchy_v6()
    truth_lengths = np.array([0.101, 0.099, 0.0225])
    truth = RunModel(robot, ['section_length'], None).vector.robot_for(
        np.log(truth_lengths / np.array([0.1, 0.1, 0.022])))
    run = run_of(truth)
    model = RunModel(robot, ['registration', 'section_length'], run)
    start = rms(model.residuals(model.start())[:3 * len(run)].reshape(-1, 3))
    result = fit(model, log=lambda line: None, workers=2)
    found = model.values(result.x)['section_length']
    errors, _ = model.errors(result.x, run)
    # slack cables make the cost a staircase in the lengths: the fit ends on a step near the
    # truth (0.46 mm RMS from 14 mm), not at zero
    assert rms(errors) < 0.1 * start
    assert np.allclose(found, truth_lengths, atol=1.5e-4)
    assert np.allclose(model.robot_for(result.x).description.guides, truth.description.guides,
                       atol=3e-4)
    output = tmp_path / 'stretched.yaml'
    fitted = model.robot_for(result.x, frame='tracker')
    write_robot_file(output, V6, fitted, model.fit, ['test'])
    written = load_robot(output)
    assert np.allclose(written.description.guides, fitted.description.guides, atol=1e-9)
    assert written.length == pytest.approx(fitted.length, abs=1e-9)
    assert np.all(np.isinf(written.tendons.stiffness))  # the file's: tendons were not fitted


def test_fit_recovers_section_bending_stiffness_and_writes_it(tmp_path):
    """Disks that stiffen the proximal section 2.5x and the middle 1.6x (distal bare): found.

    Without gravity (as the v6 file) and with stretchy, pretensioned cables.
    """
    robot = stretchy_v6()
    scales = np.array([2.5, 1.6, 1.0])
    truth = RunModel(robot, ['section_bending'], None).vector.robot_for(np.log(scales))
    assert [s.bending_scale for s in truth.sections] == pytest.approx(scales.tolist())
    run = run_of(truth)
    model = RunModel(robot, ['registration', 'section_bending'], run)
    start = rms(model.residuals(model.start())[:3 * len(run)].reshape(-1, 3))
    result = fit(model, log=lambda line: None, workers=2)
    found = model.values(result.x)['section_bending']
    errors, _ = model.errors(result.x, run)
    assert start > 1e-3  # the bare rod misses the tips by millimetres
    assert rms(errors) < 1e-3 * start
    np.testing.assert_allclose(found, scales, rtol=1e-3)
    output = tmp_path / 'stiffened.yaml'
    write_robot_file(output, V6, model.robot_for(result.x, frame='tracker'), model.fit, ['test'])
    written = load_robot(output)
    np.testing.assert_allclose([s.bending_scale for s in written.sections], found, rtol=1e-5)


def test_fit_recovers_disk_masses():
    """Guide disks of 0.3 g, 0.2 g and 0.1 g (proximal to distal) under gravity: found.

    On the v6 rod, gravity across its axis (tips 10 mm from the weightless disks'), to 1e-4.

    Heavier disks (4 g) bend this thin rod by centimetres and the fit's trial steps then jump
    between equilibria of the slack cables; the fit stops short of the truth (noted in
    issue 21's closing note).
    """
    robot = stretchy_v6(gravity=np.array([0.0, -9.81, 0.0]))
    masses = np.array([0.0003, 0.0002, 0.0001])
    truth = RunModel(robot, ['disk_mass'], None).vector.robot_for(masses)
    run = run_of(truth)
    model = RunModel(robot, ['disk_mass'], run)
    start = rms(model.residuals(model.start())[:3 * len(run)].reshape(-1, 3))
    result = fit(model, log=lambda line: None, workers=2)
    errors, _ = model.errors(result.x, run)
    assert start > 5e-3
    assert rms(errors) < 1e-4 * start
    np.testing.assert_allclose(model.values(result.x)['disk_mass'], masses, rtol=1e-4)


def test_selection_keeps_the_physics_the_run_shows_and_drops_what_it_does_not():
    """Truth with capstan friction: cross-validation keeps friction, not a tip-marker shift.

    Nine patterns (one per cable's pull), three folds of whole patterns; the fit of each fold
    never saw the pulls it is scored on.
    """
    robot = load_robot(V6)
    truth = robot.__class__(dataclasses.replace(robot.description, tendons=dataclasses.replace(
        Tendons.default(9), stiffness=np.full(9, 500.0), friction=np.full(9, 0.1))))
    lengths = pulls(robot, payout=0.2)
    labels = tuple('rep1_tendon%d_pull' % (i // 8) for i in range(len(lengths)))
    run = RecordedRun(times=np.arange(len(lengths), dtype=float), labels=labels,
                      lengths=lengths, tips=np.zeros((len(lengths), 3)), source='synthetic')
    points, failed = replay(truth, run)
    assert not failed.any()
    noisy = points + np.random.default_rng(8).normal(0.0, 5e-5, points.shape)
    run = dataclasses.replace(run, tips=noisy)
    start = dataclasses.replace(robot.description, tendons=dataclasses.replace(
        Tendons.default(9), stiffness=np.full(9, 300.0)))
    lines = []
    result = select(robot.__class__(start), run, ['registration', 'stiffness'],
                    ['friction', 'tip_marker'], log=lines.append, workers=2)
    assert result['kept'] == ['friction']
    assert result['fit'] == ['registration', 'stiffness', 'friction']
    assert result['candidates']['friction'] < 0.5 * result['base']
    assert result['selected'] == result['candidates']['friction']
    assert len(lines) == 3 and all('cross-validated (3 folds' in line for line in lines)


def test_jacobian_columns_from_the_base_rows_equal_whole_replays():
    """A column whose rows start from the base replay's rows equals one of a whole new replay.

    Friction (mu 0.1) makes each row depend on the cables' directions of motion: a shifted zero
    offset must not read as a motion. The replays converge to 1e-12 m of cable, so the two
    differences agree to 2e-4 of the column (at a node's 1e-9 m the base rows' bias was 2 %).
    The zero-offset columns (1e-6 m steps) sit at that convergence floor: 0.8-1.0e-4 measured,
    moving with round-off when the kernel's arithmetic is regrouped.
    """
    robot = truth_robot(load_robot(V6))
    lengths = pulls(robot)
    run = RecordedRun(times=np.arange(len(lengths), dtype=float), labels=('',) * len(lengths),
                      lengths=lengths, tips=np.zeros((len(lengths), 3)), source='synthetic')
    points, _ = replay(robot, run)
    run = dataclasses.replace(run, tips=points + 1e-3)
    model = RunModel(robot, ['section_rotation', 'cable_angle', 'cable_zero', 'stiffness',
                             'pretension', 'friction'], run)
    x = model.start()
    base = model.residuals(x)
    starts = model.solutions
    steps = model.vector.steps()
    for i in range(model.size):
        trial = x.copy()
        trial[i] += steps[i]
        whole = (model.residuals(trial) - base) / steps[i]
        from_base = (model.residuals(trial, starts=starts) - base) / steps[i]
        assert np.linalg.norm(whole) > 0.0
        assert np.linalg.norm(from_base - whole) <= 2e-4 * np.linalg.norm(whole), i


def test_a_fit_of_more_names_starts_where_its_default_names_end(tmp_path):
    """Adding names never makes the training error worse: the default part is fitted first."""
    robot = load_robot(V6)
    run, _ = synthetic_run(robot)
    csv, header = write_run_csv(tmp_path / 'run.csv', robot, run)
    columns = ColumnMap(cables=tuple(header[1:10]), kind='displacement', scale=1e-3,
                        tip_scale=1e-3)
    default = ['registration', 'section_rotation', 'stiffness']
    lines = []
    plain = calibrate_run(V6, csv, default, columns, log=lambda line: None, workers=2)
    staged = calibrate_run(V6, csv, default + ['pretension', 'tip_marker'], columns,
                           log=lines.append, workers=2)
    assert any(line.startswith('calibrate: first registration section_rotation stiffness')
               for line in lines)
    assert staged['rms_after'] <= plain['rms_after'] * (1.0 + 1e-6)
    # where the time went: both fits' scans and steps, the file as given, the errors
    assert {'read', 'scan', 'fit', 'before', 'validate'} <= set(staged['phases'])
    assert all(entry['wall'] >= 0.0 and entry['cpu'] >= 0.0
               for entry in staged['phases'].values())
    assert staged['rms_before'] == pytest.approx(plain['rms_before'], rel=1e-12)


def test_selection_does_not_score_a_name_that_changes_nothing_on_the_run():
    """Disk masses weigh nothing without gravity: not a candidate.

    Its score would differ from the base's only by the fit's path. With gravity across the rod
    they move the tips.
    """
    weightless = stretchy_v6()
    run = run_of(weightless)
    assert not moves_the_tips(weightless, run, 'disk_mass')
    assert moves_the_tips(stretchy_v6(gravity=np.array([0.0, -9.81, 0.0])), run, 'disk_mass')
    assert moves_the_tips(weightless, run, 'section_bending')
    lines = []
    result = select(weightless, run, ['registration'], ['disk_mass'], log=lines.append,
                    workers=2)
    assert result['candidates'] == {} and result['kept'] == []
    assert any('disk_mass changes no tip of this run' in line for line in lines)


def test_selection_refuses_a_run_of_one_motion_pattern():
    robot = load_robot(V6)
    run, _ = synthetic_run(robot)
    run = dataclasses.replace(run, labels=('rep1_seg1_dir0',) * len(run))
    with pytest.raises(ValueError, match='at least 2 motion patterns'):
        select(robot, run, ['registration'], ['friction'], log=lambda line: None, workers=1)
