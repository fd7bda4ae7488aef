"""What a section's disks do to the rod, against hand-derived statics.

``sections[k].bending_scale``: the disks stiffen the rod over the section's span, C becomes
``bending_scale`` C there. ``sections[k].disk_mass``: each guide disk is a point weight.
Checked against the Euler-Bernoulli/Timoshenko cantilever (piecewise E I; point loads at the
disks), exact torsion of a straight rod, and recovery by the run calibration (test_run_
calibration.py) from a synthetic run.
"""
import copy

import numpy as np
import pytest

from continuum_statics.calibration.parameters import candidate_robot
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

LENGTH, SPLIT = 0.30, 0.12  # m: the proximal section ends at SPLIT


def robot_file(proximal=3.0, distal=1.0, model='point_moment', gravity=(0.0, 0.0, 0.0),
               orientation=(0.0, 0.0, 0.0, 1.0), density=6450.0):
    return {
        'name': 'stiffened',
        'rod': {'length': LENGTH, 'diameter': 2.0e-3, 'youngs_modulus': 58.0e9,
                'poisson_ratio': 0.33, 'density': density},
        'base': {'frame_id': 'base', 'orientation': list(orientation)},
        'gravity': list(gravity),
        'cable_model': model,
        'sections': [
            {'name': 'proximal', 'guides': [0.04, 0.08, SPLIT], 'bending_scale': proximal,
             'cables': [{'name': 'p0', 'offset': [0.01, 0.0, 0.0]},
                        {'name': 'p1', 'offset': [-0.01, 0.0, 0.0]}]},
            {'name': 'distal', 'guides': [0.18, 0.24, LENGTH], 'bending_scale': distal,
             'cables': [{'name': 'd0', 'offset': [0.0, 0.01, 0.0]},
                        {'name': 'd1', 'offset': [0.0, -0.01, 0.0]}]},
        ],
        'solver': {'steps': 200},
    }


def make(data):
    return Robot(parse_robot_description(copy.deepcopy(data)))


@pytest.mark.parametrize('proximal, distal', [(3.0, 1.0), (1.0, 0.5), (2.0, 4.0)])
def test_cantilever_with_a_stiffer_section_deflects_as_euler_bernoulli(proximal, distal):
    """Tip deflection F [ (L^3 - (L-a)^3) / k1 + (L-a)^3 / k2 ] / (3 E I) + F L / (G A).

    Small load; the last term is the shear of eq. 6 (D = diag(GA, GA, EA)), which the disks do
    not stiffen.
    """
    robot = make(robot_file(proximal, distal))
    ei = robot.c[0]
    force = 1e-5 * ei / LENGTH ** 2  # deflection ~ 1e-5 L: linear to ~1e-10
    tip = robot.solve_bvp(tip_force=[force, 0.0, 0.0]).positions[-1]
    rest = (LENGTH - SPLIT) ** 3
    expected = (force * ((LENGTH ** 3 - rest) / proximal + rest / distal) / (3.0 * ei)
                + force * LENGTH / robot.d[0])
    assert tip[0] == pytest.approx(expected, rel=1e-6)


def test_torsion_adds_the_sections_compliances():
    """A twisting tip moment on a straight rod: angle = tau (a / k1 + (L - a) / k2) / GJ."""
    robot = make(robot_file(3.0, 1.5))
    tau = 1e-4
    shape = robot.solve_bvp(tip_moment=[0.0, 0.0, tau])
    angle = np.arctan2(shape.rotations[-1][1, 0], shape.rotations[-1][0, 0])
    expected = tau * (SPLIT / 3.0 + (LENGTH - SPLIT) / 1.5) / robot.c[2]
    assert angle == pytest.approx(expected, rel=1e-9)
    # the shape's moment is the rod's, C u, with C of each node's section: tau everywhere
    np.testing.assert_allclose(shape.m[:, 2], tau, rtol=1e-9)


def test_a_scale_of_one_is_the_bare_rod():
    plain = make(robot_file(1.0, 1.0, model='distributed', gravity=(0.0, -9.81, 0.0)))
    data = robot_file(1.0, 1.0, model='distributed', gravity=(0.0, -9.81, 0.0))
    for section in data['sections']:
        del section['bending_scale']
    bare = make(data)
    assert plain.interval_scale is None and len(plain.params) == len(bare.params)
    tensions = [1.0, 0.0, 0.5, 0.0]
    np.testing.assert_array_equal(plain.solve_tensions(tensions).positions,
                                  bare.solve_tensions(tensions).positions)


@pytest.mark.parametrize('model', ['point_moment', 'distributed'])
def test_point_moment_arcs_follow_each_sections_stiffness(model):
    """A distal cable's point moment bends both sections; the proximal one by t r / (k1 E I)."""
    robot = make(robot_file(2.5, 1.0, model=model))
    shape = robot.solve_tensions([0.0, 0.0, 0.0, 2.0])
    u = shape.u
    s = shape.s
    inside = (s > 0.01) & (s < SPLIT - 0.01)
    outside = s > SPLIT + 0.01
    ratio = np.median(np.linalg.norm(u[outside, :2], axis=1)) / np.median(
        np.linalg.norm(u[inside, :2], axis=1))
    assert ratio == pytest.approx(2.5, rel=2e-2 if model == 'distributed' else 1e-6)


def test_calibration_candidate_sets_each_sections_scale():
    robot = make(robot_file(1.0, 1.0))
    fitted = candidate_robot(robot, {'section_bending': np.array([2.0, 0.7])})
    assert [s.bending_scale for s in fitted.sections] == [2.0, 0.7]
    reference = make(robot_file(2.0, 0.7))
    np.testing.assert_array_equal(fitted.params, reference.params)


def test_bending_scale_out_of_range_names_the_field():
    data = robot_file(0.01)
    with pytest.raises(ValueError, match=r'sections\[0\]\.bending_scale must be in'):
        parse_robot_description(data)


def test_disk_weights_deflect_a_cantilever_as_point_loads():
    """Disks as point weights: tip deflection sum m g [s_g^2 (3 L - s_g) / (6 E I) + s_g / (G A)].

    Weightless rod, horizontal (local z along global x), disks of mass m at s_g, small loads.
    """
    data = robot_file(1.0, 1.0, gravity=(0.0, 0.0, -9.81), density=0.0,
                      orientation=(0.0, 0.5 ** 0.5, 0.0, 0.5 ** 0.5))
    data['sections'][0]['disk_mass'] = 2e-5
    data['sections'][1]['disk_mass'] = 1e-5
    robot = make(data)
    tip = robot.solve_bvp().positions[-1]
    ei, ga = robot.c[0], robot.d[0]
    expected = 0.0
    for section in robot.sections:
        for s in section.guides:
            load = section.disk_mass * 9.81
            expected += load * (s ** 2 * (3.0 * LENGTH - s) / (6.0 * ei) + s / ga)
    assert -tip[2] == pytest.approx(expected, rel=1e-5)
    assert expected > 1e-4 * LENGTH  # not a negligible load


def test_disk_weights_enter_the_base_force():
    """Upright rod: the base carries the rod's and every disk's weight (eq. 10)."""
    data = robot_file(1.0, 1.0, gravity=(0.0, 0.0, -9.81))
    data['sections'][0]['disk_mass'] = 0.003
    data['sections'][1]['disk_mass'] = 0.001
    robot = make(data)
    shape = robot.solve_bvp()
    rod_weight = robot.rod.mass_per_length * LENGTH * 9.81
    disks = (3 * 0.003 + 3 * 0.001) * 9.81
    assert shape.n[0][2] == pytest.approx(-(rod_weight + disks), rel=1e-9)
    # and beyond the proximal section's end disk only the distal disks and rod remain
    beyond = shape.s > SPLIT + 1e-9
    first = np.argmax(beyond)
    expected = robot.rod.mass_per_length * (LENGTH - shape.s[first]) * 9.81 + 3 * 0.001 * 9.81
    assert shape.n[first][2] == pytest.approx(-expected, rel=1e-9)
