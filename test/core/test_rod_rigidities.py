"""A backbone's own extension and shear rigidities (``rod.axial_rigidity``, ``shear_rigidity``).

Against hand-derived statics of a straight cantilever (eq. 6, n = R D (v - e3)): an axial tip
force stretches it by F L / (E A), a small transverse one deflects it by F L^3 / (3 E I) (bending)
plus F L / (G A) (shear), with the given rigidities in place of the solid section's. Then the
fit name ``extension_shear`` recovers them from a synthetic run and writes them.
"""
import copy
import dataclasses

import numpy as np
import pytest
from test_run_calibration import V6, run_of, stretchy_v6
from test_section_properties import LENGTH, make, robot_file

from continuum_statics import load_robot
from continuum_statics.calibration.fit import fit, standard_errors
from continuum_statics.calibration.parameters import candidate_robot, scaled_rod
from continuum_statics.calibration.robot_writer import write_robot_file
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.core.description.robot_file import parse_robot_description

AXIAL, SHEAR = 2.0e3, 1.0  # N: far below the solid rod's E A, G A (the shear term is large)


def soft_file(**changes):
    data = robot_file(1.0, 1.0)
    data['rod'].update(axial_rigidity=AXIAL, shear_rigidity=SHEAR, **changes)
    return data


def test_an_axial_tip_force_stretches_the_rod_by_f_l_over_ea():
    robot = make(soft_file())
    force = 5.0  # N along the rod (its local z is the base frame's z here)
    shape = robot.solve_bvp(tip_force=[0.0, 0.0, force])
    assert shape.positions[-1][2] - LENGTH == pytest.approx(force * LENGTH / AXIAL, rel=1e-9)
    solid = make(robot_file(1.0, 1.0)).solve_bvp(tip_force=[0.0, 0.0, force])
    assert solid.positions[-1][2] - LENGTH < 0.05 * force * LENGTH / AXIAL


def test_a_transverse_tip_force_adds_shear_f_l_over_ga_to_bending():
    robot = make(soft_file())
    ei = robot.c[0]
    force = 1e-5 * ei / LENGTH ** 2  # linear to ~1e-10
    tip = robot.solve_bvp(tip_force=[force, 0.0, 0.0]).positions[-1]
    expected = force * LENGTH ** 3 / (3.0 * ei) + force * LENGTH / SHEAR
    assert force * LENGTH / SHEAR > 0.3 * expected  # the shear term is large here
    assert tip[0] == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize('key', ['axial_rigidity', 'shear_rigidity'])
@pytest.mark.parametrize('value', [0.0, -1.0, 'stiff'])
def test_rigidities_must_be_positive_numbers(key, value):
    data = robot_file(1.0, 1.0)
    data['rod'][key] = value
    with pytest.raises(ValueError, match='rod.' + key):
        parse_robot_description(copy.deepcopy(data))


def test_a_fitted_youngs_modulus_leaves_given_rigidities_and_the_fit_name_sets_them():
    robot = make(soft_file())
    rod = scaled_rod(robot.rod, 2.0 * robot.rod.youngs_modulus, robot.rod.density)
    np.testing.assert_array_equal(rod.shear_stiffness, [SHEAR, SHEAR, AXIAL])
    fitted = candidate_robot(make(robot_file(1.0, 1.0)),
                             {'extension_shear': np.array([AXIAL, SHEAR]),
                              'youngs_modulus': np.array([1e11])})
    np.testing.assert_array_equal(fitted.d, [SHEAR, SHEAR, AXIAL])
    assert fitted.rod.youngs_modulus == 1e11
    plain = make(robot_file(1.0, 1.0))
    assert dataclasses.replace(plain.rod).axial_rigidity is None
    np.testing.assert_allclose(plain.d[2], plain.rod.youngs_modulus * plain.rod.area)


def test_the_fit_recovers_the_backbone_extension_from_a_synthetic_run_and_writes_it(tmp_path):
    """A distributed-load robot (the cables compress the backbone) 10x softer in extension.

    The cables pull along the backbone, so a run without tip loads or gravity shows E A but
    not G A: the shear factor is left where the fit finds no gradient, and its 1-sigma says so.
    """
    nominal = stretchy_v6(cable_model='distributed')
    shear, _, axial = nominal.rod.shear_stiffness
    truth = nominal.__class__(dataclasses.replace(nominal.description, rod=dataclasses.replace(
        nominal.rod, axial_rigidity=0.1 * axial, shear_rigidity=0.05 * shear)))
    run = run_of(truth)
    model = RunModel(nominal, ['extension_shear'], run)
    result = fit(model, log=lambda line: None, workers=2)
    ea, ga = model.values(result.x)['extension_shear']
    assert ea == pytest.approx(0.1 * axial, rel=1e-4)
    assert np.sqrt(np.mean(result.residuals ** 2)) < 1e-7
    sigma = standard_errors(result.jacobian, result.residuals,
                            model.vector.derivatives(result.x))
    assert sigma[0] < 1e-3 * ea and not sigma[1] < 0.1 * ga
    path = tmp_path / 'fitted.yaml'
    write_robot_file(path, V6, model.robot_for(result.x, frame='tracker'), model.fit, [])
    written = load_robot(path)
    assert written.rod.axial_rigidity == pytest.approx(ea, rel=1e-5)
    assert written.rod.shear_rigidity == pytest.approx(ga, rel=1e-5)
