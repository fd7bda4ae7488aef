"""``solve --cable-lengths / --tensions / --plot``: the command line against the Python API."""
import json
import subprocess
import sys

from conftest import REPO
import numpy as np
import pytest

from continuum_statics import Robot, load_robot

TENDON = REPO / 'config' / 'tendon_robot.yaml'
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


def solve(*args):
    result = subprocess.run([sys.executable, '-m', 'continuum_statics', 'solve', '--robot',
                             str(TENDON), *args], capture_output=True, text=True, timeout=300)
    return result


@pytest.mark.ros
def test_cable_lengths_give_back_the_shape_they_came_from(tmp_path):
    robot = load_robot(TENDON)
    shape = robot.solve_ivp([2.0, -1.0, 0.0])
    lengths = robot.cable_lengths(shape)
    png = tmp_path / 'backbone.png'
    result = solve('--cable-lengths', *('%.12f' % v for v in lengths), '--plot', str(png),
                   '--json')
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data['estimate']['converged']
    np.testing.assert_allclose(data['tip_position'], shape.tip_position, atol=1e-6)
    np.testing.assert_allclose(data['cable_lengths'], lengths, atol=1e-8)
    assert png.read_bytes().startswith(PNG_SIGNATURE) and png.stat().st_size > 20000


@pytest.mark.skipif(not hasattr(Robot, 'solve_tensions'), reason='core without solve_tensions')
@pytest.mark.ros
def test_tensions_bend_toward_the_pulled_cable():
    result = solve('--tensions', '2.0', '0', '0', '0', '--json')
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    # cable_0 runs at +x in the rod's frame (= base frame here): pulling it bends the tip to +x
    # and shortens it the most.
    assert data['tip_position'][0] > 0.01
    assert np.argmin(data['cable_lengths']) == 0
    slack = json.loads(solve('--json').stdout)
    assert slack['tip_position'] != data['tip_position']


@pytest.mark.ros
def test_human_output_names_the_cables():
    result = solve('--tip-force', '0', '0', '-0.1')
    assert result.returncode == 0, result.stderr
    assert 'cable lengths' in result.stdout and 'cable_3=' in result.stdout


@pytest.mark.parametrize('option', ['--tensions', '--cable-lengths'])
@pytest.mark.ros
def test_wrong_number_of_cable_values_is_a_clear_error(option):
    result = solve(option, '0.3', '0.3')
    assert result.returncode == 1
    assert '%s needs 4 values, one per cable (cable_0, cable_1, cable_2, cable_3), got 2' % (
        option) in result.stderr


@pytest.mark.ros
def test_estimate_load_finds_the_force_that_bent_the_rod():
    # tensions and the tip position of a known load: the JSON gives it back within 3 sigma
    robot = load_robot(TENDON)
    tensions = np.array([1.5, 0.4, 0.6, 1.1])
    force = np.array([0.1, -0.2, 0.0])
    shape = robot.solve_tensions(tensions, force)
    result = solve('--estimate-load', '--tensions', *('%.9f' % t for t in tensions),
                   '--tip-position', *('%.9f' % v for v in shape.tip_position),
                   '--noise', 'tip_position', '1e-5', '--noise', 'tension', '1%', '--json')
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data['converged'] and data['frame_id'] == 'base_link'
    error = np.array(data['force_n']) - force
    assert np.all(np.abs(error) <= 3.0 * np.array(data['force_sigma_n'])), data
    assert max(data['force_sigma_n'][:2]) < 0.05
    human = solve('--estimate-load', '--tensions', *('%.9f' % t for t in tensions))
    assert human.returncode == 0 and 'force  [N]' in human.stdout and 'sigma' in human.stdout
    # tensions alone, no tip: nothing sees the load, and the output says so
    assert 'do not determine the tip force' in human.stdout
    wrong = solve('--tip-position', '0', '0', '0.3')
    assert wrong.returncode == 1 and '--estimate-load' in wrong.stderr


@pytest.mark.parametrize('args, words', [
    (('--tip-force', '0.1', '0', '0'), '--tip-force, --tip-moment and --plot do not go with'),
    (('--plot', 'x.png'), 'do not go with --estimate-load'),
    (('--noise', 'length', '2%'), 'a percentage P% only for tension'),
])
@pytest.mark.ros
def test_estimate_load_refuses_options_it_would_ignore_with_the_reason(args, words):
    # issue 38: --tip-force and --plot were ignored silently; '2%' for a length said "could not
    # convert string to float"
    result = solve('--estimate-load', '--tensions', '1', '1', '1', '1', *args)
    assert result.returncode == 1 and words in result.stderr, result.stderr


@pytest.mark.ros
def test_estimate_load_weighs_a_payload():
    # a 20 g mass hung on the Jones rod: --load weight gives it back in g, --json in kg
    rod_file = REPO / 'config' / 'jones2009_nitinol_rod.yaml'
    rod = load_robot(rod_file)
    tip = rod.solve_bvp(0.02 * np.asarray(rod.gravity)).tip_position
    args = [sys.executable, '-m', 'continuum_statics', 'solve', '--robot', str(rod_file),
            '--estimate-load', '--tip-position', *('%.9f' % v for v in tip),
            '--noise', 'tip_position', '1e-3']

    def run(*extra):
        return subprocess.run(args + list(extra), capture_output=True, text=True, timeout=300)

    result = run('--load', 'weight', '--json')
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert data['load'] == 'weight'
    assert abs(data['mass'] - 0.02) <= 3.0 * data['mass_sigma'] and data['mass_sigma'] < 1e-3
    human = run('--load', 'weight')
    assert human.returncode == 0 and 'mass   [g]    20' in human.stdout, human.stdout
    force = json.loads(run('--json').stdout)  # the default: three unknowns, no mass
    assert force['load'] == 'force' and force['mass'] is None
    along = json.loads(run('--load', 'direction', '0', '0', '-2', '--json').stdout)
    assert along['load'] == 'direction'
    assert along['force_n'][2] == pytest.approx(0.02 * rod.gravity[2], rel=1e-3)
    wrong = run('--load', 'direction', '0', '0')
    assert wrong.returncode == 1 and 'needs three numbers DX DY DZ' in wrong.stderr
    wrong = run('--load', 'mass')
    assert wrong.returncode == 1 and '--load must be weight, force, wrench or direction' in \
        wrong.stderr
