"""``solve --obstacles FILE``: the body resting on obstacles from the command line."""
import json

from conftest import REPO
import numpy as np

from continuum_statics import load_robot
from continuum_statics.core.description.obstacles import parse_obstacles
from continuum_statics.tools.solve import solve_main

ROBOT = REPO / 'config' / 'two_section_robot.yaml'
BALL = {'name': 'ball', 'sphere': {'radius': 0.02}, 'position': [0.035, 0.0, 0.2]}


def test_solve_prints_the_contacts_the_api_finds(tmp_path, capsys):
    path = tmp_path / 'obstacles.yaml'
    path.write_text('obstacles:\n  - {name: ball, sphere: {radius: 0.02}, '
                    'position: [0.035, 0.0, 0.2]}\n')
    tensions = ['3', '0', '0', '0', '0', '0']
    assert solve_main(['--robot', str(ROBOT), '--tensions', *tensions, '--obstacles',
                       str(path), '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    shape = load_robot(ROBOT).solve_tensions([3.0, 0, 0, 0, 0, 0],
                                             obstacles=parse_obstacles([BALL]))
    (contact,) = data['contacts']
    assert contact['obstacle'] == 'ball'
    assert np.isclose(contact['force'], shape.contacts[0].force, rtol=1e-9)
    np.testing.assert_allclose(data['tip_position'], shape.tip_position, atol=1e-12)
    assert solve_main(['--robot', str(ROBOT), '--tensions', *tensions, '--obstacles',
                       str(path)]) == 0
    assert "contact with 'ball'" in capsys.readouterr().out


def test_solve_names_a_bad_obstacles_file(tmp_path, capsys):
    path = tmp_path / 'obstacles.yaml'
    path.write_text('- {name: ball, sphere: {radius: -1}}\n')
    assert solve_main(['--robot', str(ROBOT), '--obstacles', str(path)]) == 1
    assert 'sizes must be in' in capsys.readouterr().err
