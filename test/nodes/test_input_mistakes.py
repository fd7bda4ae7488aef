"""Issue 23: input mistakes answered with their cause, never a traceback or a meaningless result.

Each test failed on the code before the fix: tips in mm (a ZeroDivisionError traceback, or a fit
error of 378,905 mm written out), tip-load data that cannot determine the fit (sigmas ~1e14),
tendon blocks no robot has (loaded silently), solve's "converged" best fit, the finalized
driver's "configure and activate", and a silent 20,000-row fit.
"""
from types import SimpleNamespace

from conftest import REPO
import numpy as np
import pytest
import yaml

from continuum_statics import load_robot
from continuum_statics.calibration import summary, tip_loads
from continuum_statics.calibration.tip_loads import calibrate_tip_loads
from continuum_statics.tools import calibrate, solve

PAPER_ROD = REPO / 'config' / 'jones2009_nitinol_rod.yaml'
V6 = REPO / 'test' / 'data' / 'ftdcr_v6'
V6_CABLES = ('servo_1_mm,servo_20_mm,servo_23_mm,servo_9_mm,servo_6_mm,servo_11_mm,'
             'servo_24_mm,servo_2_mm,servo_3_mm')
HEADER = 'tip_force_x,tip_force_y,tip_force_z,tip_x,tip_y,tip_z'


def write_tip_loads(path, forces, tips):
    rows = [HEADER] + [','.join('%.12g' % v for v in (*f, *t)) for f, t in zip(forces, tips)]
    path.write_text('\n'.join(rows) + '\n')
    return path


def paper_rows(count):
    robot = load_robot(PAPER_ROD)
    forces = np.zeros((count, 3))
    forces[:, 2] = -np.linspace(0.0, 0.04, count) * 9.81
    return forces, np.array([robot.solve_bvp(tip_force=f).tip_position for f in forces])


# -- calibrate --------------------------------------------------------------------------------
def test_a_recorded_run_with_tips_in_mm_is_refused_naming_tip_scale(capsys):
    # the README's v6 command without --tip-scale 0.001 (before: ZeroDivisionError traceback)
    code = calibrate.main([
        '--robot', str(REPO / 'config' / 'ftdcr_v6_robot.yaml'), '--data',
        str(V6 / 'train.csv'), '--cable-columns', V6_CABLES, '--cable-kind', 'displacement',
        '--cable-scale', '0.001'])
    err = capsys.readouterr().err
    assert code == 1
    assert 'are the tips in mm?' in err and '--tip-scale 0.001' in err, err
    assert 'Traceback' not in err


def test_tip_load_tips_in_mm_are_refused_and_nothing_is_written(tmp_path):
    forces, tips = paper_rows(12)
    data = write_tip_loads(tmp_path / 'mm.csv', forces, tips * 1e3)
    output = tmp_path / 'out.yaml'
    with pytest.raises(ValueError, match='are the tips in mm'):
        calibrate_tip_loads(PAPER_ROD, data, ['youngs_modulus'], output)
    assert not output.exists()


@pytest.mark.parametrize('count', [1, 12], ids=['one row', '12 identical rows'])
def test_tip_load_rows_that_cannot_determine_the_fit_are_refused(tmp_path, count):
    forces, tips = paper_rows(2)
    data = write_tip_loads(tmp_path / 'same.csv', np.repeat(forces[1:], count, axis=0),
                           np.repeat(tips[1:], count, axis=0))
    with pytest.raises(ValueError, match=r'1 distinct row\(s\) \(of %d\) cannot determine 2 '
                                         'parameter' % count):
        calibrate_tip_loads(PAPER_ROD, data, ['youngs_modulus', 'base_pitch'],
                            tmp_path / 'out.yaml')
    assert not (tmp_path / 'out.yaml').exists()


def test_parameters_the_data_do_not_separate_are_refused(tmp_path):
    # the rod sagging under its own weight only (no tip load): the sag sees rho / E, never E and
    # the density apart (before: fitted and written with sigmas ~1e14)
    forces, tips = paper_rows(1)
    rng = np.random.default_rng(0)
    noisy = tips + rng.normal(0.0, 1e-5, (6, 3))
    data = write_tip_loads(tmp_path / 'sag.csv', np.zeros((6, 3)), noisy)
    with pytest.raises(ValueError, match='the data do not determine'):
        calibrate_tip_loads(PAPER_ROD, data, ['youngs_modulus', 'density'],
                            tmp_path / 'out.yaml')
    assert not (tmp_path / 'out.yaml').exists()


def test_a_long_fit_prints_progress_on_stderr(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(tip_loads, 'PROGRESS_S', 0.0)  # every evaluation, for the test
    forces, tips = paper_rows(8)
    data = write_tip_loads(tmp_path / 'loads.csv', forces, tips)
    assert calibrate.main(['--robot', str(PAPER_ROD), '--data', str(data), '--json']) == 0
    captured = capsys.readouterr()
    assert 'model evaluations of 8 rows' in captured.err
    assert captured.out.count('\n') == 1  # --json: stdout stays one object


def test_friction_fitted_to_nothing_is_reported_as_none():
    notes = summary.notes({'friction': {'after': 2.5e-10}, 'stiffness': {'after': [80.0]}})
    assert notes and 'friction: the data show none (fitted 2.5e-10' in notes[0]
    assert summary.notes({'friction': {'after': 0.08}}) == []


# -- robot file -------------------------------------------------------------------------------
def tendon_robot(tmp_path, tendons, cable=None):
    document = yaml.safe_load((REPO / 'config' / 'tendon_robot.yaml').read_text())
    document['tendons'] = tendons
    if cable:
        document['cables'][0].update(cable)
    path = tmp_path / 'robot.yaml'
    path.write_text(yaml.safe_dump(document))
    return path


@pytest.mark.parametrize('tendons, cable, message', [
    ({'stiffness': 2000.0, 'pretension': 40.0, 'tension_limits': [0.0, 30.0]}, None,
     'pretension 40 N is outside tension_limits'),
    ({'stiffness': 2000.0}, {'zero_offset': 1.0}, 'zero_offset 1 m is more than 0.1'),
    ({'stiffness': 2000.0}, {'zero_offset': -0.1}, 'zero_offset -0.1 m is more than 0.1'),
    ({'stiffness': 1e-6}, None, 'stiffness (EA) 1e-06 N is outside'),
    ({'stiffness': 1e12}, None, 'stiffness (EA) 1e+12 N is outside'),
    ({'stiffness': 20.0, 'tension_limits': [0.0, 30.0]}, None, 'outside [30, 1e+10] N'),
], ids=['pretension over limit', 'zero offset 1 m', 'zero offset -0.1 m', 'EA 1e-6',
        'EA 1e12', 'EA below the tension limit'])
def test_implausible_tendon_blocks_are_refused_naming_the_cable(tmp_path, tendons, cable,
                                                                message):
    with pytest.raises(ValueError, match="cable 'cable_0'") as error:
        load_robot(tendon_robot(tmp_path, tendons, cable))
    assert message in str(error.value), str(error.value)


def test_plausible_tendon_blocks_still_load(tmp_path):
    robot = load_robot(tendon_robot(tmp_path, {'stiffness': 2000.0, 'pretension': 2.0,
                                               'tension_limits': [0.0, 30.0]},
                                    {'zero_offset': -0.002}))
    assert robot.tendons.zero_offset[0] == pytest.approx(-0.002)


# -- solve ------------------------------------------------------------------------------------
def test_solve_calls_a_converged_best_fit_what_it_is():
    best_fit = SimpleNamespace(converged=True, message='best fit: the lengths fit no shape to '
                                                       'RMS 0.003 m')
    assert solve._estimate_status(best_fit) == 'best fit (no exact shape)'
    assert solve._estimate_status(SimpleNamespace(converged=True, message='')) == 'converged'
    assert solve._estimate_status(SimpleNamespace(converged=False, message='x')) == (
        'NOT converged')


# -- cable_driver after shutdown --------------------------------------------------------------
@pytest.mark.ros
def test_a_finalized_driver_says_so_and_refuses_commands(harness):
    pytest.importorskip('rclpy')
    from diagnostic_msgs.msg import DiagnosticArray
    from nodes_helpers import Collector, diagnostic_values, wait_until

    from continuum_statics.nodes.cable_driver_node import CableDriverNode

    driver = harness.add(CableDriverNode, robot_file=str(REPO / 'config' / 'tendon_robot.yaml'))
    client = harness.client()
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)

    def status():
        found = diagnostic_values(diagnostics, 'cable_driver')
        return found[0] if found else {}

    wait_until(lambda: status().get('lifecycle') == 'active', 10.0, 'the driver active')
    driver.trigger_shutdown()
    wait_until(lambda: status().get('lifecycle') == 'finalized', 10.0, 'the finalized state')
    values = status()
    assert values['accepts_commands'] == 'False'
    assert 'shut down' in values['refusal'], values
    messages = [s.message for m in diagnostics.messages for s in m.status
                if s.name.endswith('cable_driver')]
    assert 'shut down (lifecycle finalized)' in messages[-1], messages[-1]
    assert 'configure and activate' not in messages[-1]
