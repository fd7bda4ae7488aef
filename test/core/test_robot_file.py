"""Robot files: the shipped ones load; every kind of bad value is a ValueError naming its field."""
from core_fixtures import PAPER_ROD, TENDON_ROBOT, description, make_robot
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.core.description.robot_file import parse_robot_description

ROD = description()['rod']
CABLE = {'name': 'a', 'offset': [0.01, 0.0, 0.0]}


def test_paper_rod_file_matches_the_paper():
    robot = load_robot(PAPER_ROD)
    assert robot.length == pytest.approx(0.39)
    # section IV and errata: I = 0.291 mm^4, J = 0.581 mm^4, G = E / (2 (1 + nu)) = 20.8 GPa
    assert robot.rod.second_moment == pytest.approx(0.291e-12, rel=2e-3)
    assert robot.rod.polar_moment == pytest.approx(0.581e-12, rel=2e-3)
    assert robot.rod.shear_modulus == pytest.approx(20.8e9, rel=2e-3)
    # mounted along +x: the paper's R(0) = [e2 e3 e1]
    assert np.allclose(robot.base_rotation, [[0, 0, 1], [1, 0, 0], [0, 1, 0]])
    assert robot.cable_names == ()


def test_tendon_robot_file():
    robot = load_robot(TENDON_ROBOT)
    assert len(robot.cable_names) in (3, 4)
    assert robot.guides[-1] == pytest.approx(robot.length)
    assert np.all(robot.cable_length_limits[:, 0] < robot.straight_cable_lengths)
    assert np.all(robot.straight_cable_lengths < robot.cable_length_limits[:, 1])


def with_rod(**values):
    return {'rod': {**ROD, **values}}


BAD_FILES = [
    ({'rod': {k: v for k, v in ROD.items() if k != 'length'}}, 'rod.length'),
    ({'rod': {k: v for k, v in ROD.items() if k != 'poisson_ratio'}}, 'rod.poisson_ratio'),
    (with_rod(length=0.0), 'rod.length'),
    (with_rod(length=-0.1), 'rod.length'),
    (with_rod(diameter=0.0), 'rod.diameter'),
    (with_rod(youngs_modulus=-5.0), 'rod.youngs_modulus'),
    (with_rod(poisson_ratio=0.7), 'rod.poisson_ratio'),
    ({'rod': {**{k: v for k, v in ROD.items() if k != 'poisson_ratio'},
              'shear_modulus': 0.0}}, 'rod.shear_modulus'),
    (with_rod(density=-1.0), 'rod.density'),
    (with_rod(length=float('nan')), 'rod.length'),
    (with_rod(density=float('inf')), 'rod.density'),
    (with_rod(diameter='thick'), 'rod.diameter'),
    ({'base': {'frame_id': 'b', 'orientation': [0.0, 0.0, 0.0, 2.0]}}, 'base.orientation'),
    ({'base': {'frame_id': 'b', 'orientation': [0.0, 0.0, 1.0]}}, 'base.orientation'),
    ({'base': {'frame_id': '', 'orientation': [0.0, 0.0, 0.0, 1.0]}}, 'base.frame_id'),
    ({'base': {'frame_id': 'b', 'position': [0.0, float('nan'), 0.0],
               'orientation': [0.0, 0.0, 0.0, 1.0]}}, 'base.position'),
    ({'gravity': [0.0, 0.0]}, 'gravity'),
    ({'guides': [0.1, 0.5]}, 'guides[1]'),
    ({'guides': [-0.01, 0.1]}, 'guides[0]'),
    ({'guides': [0.2, 0.1]}, 'guides'),
    ({'guides': [0.1, 0.1]}, 'guides'),
    ({'guides': [0.1, 0.39], 'cables': [CABLE, {**CABLE}]}, 'cables[1].name'),
    ({'guides': [0.39], 'cables': [{'name': 'a', 'offset': [0.01, float('nan'), 0.0]}]},
     'cables[0].offset'),
    ({'guides': [0.39], 'cables': [{'name': 'a'}]}, 'cables[0].offset'),
    ({'guides': [0.39], 'cables': [{**CABLE, 'length_limits': [0.4, 0.3]}]},
     'cables[0].length_limits'),
    ({'guides': [], 'cables': [CABLE]}, 'guides'),
    ({'solver': {'steps': 0}}, 'solver.steps'),
    # issue 17: values that loaded and then made every measurement fail without a name
    (with_rod(youngs_modulus=1e-30), 'rod.youngs_modulus'),
    (with_rod(density=1e12), 'rod.density'),
    ({'guides': [0.39], 'cables': [{'name': 'a', 'offset': [0.01, 0.0, 0.05]}]},
     'cables[0].offset z'),
    ({'solver': {'steps': 100000}}, 'solver.steps'),
    ({'solver': {'bvp_tolerance': -1.0}}, 'solver.bvp_tolerance'),
    ({'solver': {'stepz': 10}}, 'solver'),
]


@pytest.mark.parametrize('changes,field', BAD_FILES)
def test_invalid_robot_file_names_the_field(changes, field):
    with pytest.raises(ValueError, match=field.replace('[', r'\[').replace(']', r'\]')):
        parse_robot_description(description(**changes))


def test_missing_file_and_bad_yaml(tmp_path):
    with pytest.raises(ValueError, match='cannot read'):
        load_robot(tmp_path / 'absent.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('rod: [unclosed\n')
    with pytest.raises(ValueError, match='not valid YAML'):
        load_robot(bad)


def test_shear_modulus_may_be_given_directly():
    rod = {k: v for k, v in ROD.items() if k != 'poisson_ratio'}
    robot = make_robot(rod={**rod, 'shear_modulus': 25e9})
    assert robot.c[2] == pytest.approx(25e9 * robot.rod.polar_moment)


def test_implausible_values_are_warned_by_field():

    data = description(cables=[{'name': 'a', 'offset': [0.5, 0.0, 0.0]}], guides=[0.39])
    data['rod']['diameter'] = 0.05
    warnings = parse_robot_description(data).warnings
    assert any(w.startswith('rod.diameter') for w in warnings)
    assert any(w.startswith('cables[0].offset') for w in warnings)
    assert parse_robot_description(description()).warnings == ()


def test_sections_validation_names_the_field():

    section = {'name': 'a', 'guides': [0.1, 0.2],
               'cables': [{'name': 'c', 'offset': [0.01, 0.0, 0.0]}]}
    cases = [
        ({'sections': [section, dict(section, name='b', guides=[0.15, 0.3])]},
         r'sections\[1\]\.guides must start after'),
        ({'sections': [section, dict(section, name='b', guides=[0.25, 0.3])]},
         r'sections\[1\]\.cables\[0\]\.name: duplicate cable name'),
        ({'sections': [section, dict(section, name='a', guides=[0.25])]},
         r'sections\[1\]\.name: duplicate section name'),
        ({'sections': [dict(section, guides=[])]}, r'sections\[0\]\.guides must list'),
        ({'sections': [section], 'cables': []}, 'either sections or top-level'),
        ({'sections': [section], 'cable_model': 'magic'}, 'cable_model must be one of'),
    ]
    for changes, message in cases:
        data = description()
        del data['cables'], data['guides']
        data.update(changes)
        with pytest.raises(ValueError, match=message):
            parse_robot_description(data)


def test_a_straight_length_outside_the_cable_limits_is_an_error_naming_the_cable():
    from continuum_statics.core.robot import Robot

    data = description(guides=[0.39], cables=[{**CABLE, 'length_limits': [0.1, 0.2]}])
    with pytest.raises(ValueError, match="cable 'a': length_limits .* straight length 0.39"):
        Robot(parse_robot_description(data))


def test_solve_prints_the_plausibility_warnings(tmp_path, capsys):
    import yaml

    from continuum_statics.tools.solve import solve_main

    path = tmp_path / 'thick.yaml'
    path.write_text(yaml.safe_dump(description(**with_rod(diameter=0.05))))
    assert solve_main(['--robot', str(path)]) == 0
    assert 'warning: rod.diameter' in capsys.readouterr().err


@pytest.mark.parametrize('changes, words', [
    ({'load_model': 'mass'}, 'load_model must be one of'),
    ({'load_direction': [0, 0, -1]}, 'without load_model'),
    ({'load_model': 'direction'}, "load_direction goes with load_model 'direction'"),
    ({'load_model': 'force', 'load_direction': [0, 0, -1]}, 'load_direction goes with'),
    ({'load_model': 'force', 'load_prior': [0.1, 0.2]}, 'load_prior for load'),
    ({'load_model': 'weight', 'gravity': [0, 0, 0]}, "load='weight' needs gravity"),
])
def test_a_bad_load_model_is_refused_at_load_naming_the_key(changes, words):
    with pytest.raises(ValueError, match=words):
        make_robot(**changes)


def test_the_load_model_of_the_file_is_in_the_fused_state():
    robot = make_robot(load_model='direction', load_direction=[0, 0, -2], load_prior=0.3)
    assert robot.load_model.name == 'direction' and robot.load_model.prior.tolist() == [0.3]
    np.testing.assert_allclose(robot.load_model.basis[:, 0], [0, 0, -1, 0, 0, 0])
    assert robot.model_uncertainty is not None  # the fused estimator carries the load
    estimate = robot.estimate_shape([], stamp=0.0)
    assert estimate.unmodelled.names[0] == 'tip_load.force'
    np.testing.assert_allclose(estimate.tip_wrench, 0.0)
    assert estimate.tip_wrench_covariance[2, 2] == pytest.approx(0.3 ** 2)
    assert robot.without_load_model().load_model is None
