"""The command line: ``python -m continuum_statics solve`` as a user runs it."""
import json
import subprocess
import sys

from core_fixtures import PAPER_ROD, paper_rod
import numpy as np
import pytest

pytestmark = pytest.mark.ros  # starts DDS or a process


def run(*args):
    return subprocess.run([sys.executable, '-m', 'continuum_statics', *args],
                          capture_output=True, text=True, timeout=120)


def test_solve_json_matches_the_api():
    result = run('solve', '--robot', str(PAPER_ROD), '--tip-force', '0', '0', '-0.2', '--json')
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    expected = paper_rod().solve_bvp(tip_force=(0.0, 0.0, -0.2))
    assert np.allclose(data['tip_position'], expected.tip_position, atol=1e-12)
    assert len(data['shape']['positions']) == len(expected.s)
    assert data['frame_id'] == 'base_link'


def test_solve_prints_tip_pose():
    result = run('solve', '--robot', str(PAPER_ROD))
    assert result.returncode == 0, result.stderr
    assert 'tip position' in result.stdout and 'x=+0.389' in result.stdout


def test_solve_reports_bad_robot_file(tmp_path):
    bad = tmp_path / 'robot.yaml'
    bad.write_text(PAPER_ROD.read_text().replace('length: 0.39', 'length: -0.39'))
    result = run('solve', '--robot', str(bad))
    assert result.returncode == 1
    assert 'rod.length must be > 0' in result.stderr


def test_fusion_simulated_truth_json():
    """``fusion --simulate``: a row per number of sensors, errors shrinking along the rod's tip."""
    result = run('fusion', '--robot', 'config/tendon_robot_sensors.yaml', '--simulate', '20',
                 '--json')
    assert result.returncode == 0, result.stderr
    rows = json.loads(result.stdout)['rows']
    assert [len(row['sensors']) for row in rows] == [0, 1, 2]
    assert rows[1]['rms'][-1] < 0.5 * rows[0]['rms'][-1]
    refused = run('fusion', '--robot', 'config/tendon_robot.yaml', '--simulate', '5')
    assert refused.returncode == 1 and 'no model_uncertainty' in refused.stderr
