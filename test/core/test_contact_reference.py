"""Contact statics against an elastica of another kind (test/reference_contact.py).

The reference minimises the energy of a fine inextensible chain with non-penetration as
inequality constraints (SLSQP) and reads the contact forces off its KKT multipliers; the package
shoots an extensible Cosserat rod with point contact forces (complementarity by Newton). The
reference is extrapolated (Richardson, second order) from two refinements; the package is solved
at several step counts and must converge to it.
"""
from conftest import REPO
import numpy as np
import pytest
from reference_contact import Cylinder, Plane, Rod, Sphere, solve_3d, solve_planar

from continuum_statics import load_robot
from continuum_statics.core.description.obstacles import parse_obstacles
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

HORIZONTAL = [0.0, 0.7071067811865476, 0.0, 0.7071067811865476]  # the rod along +x


def _cantilever(steps):
    """Return a 0.3 m, 2 mm Nitinol rod clamped along +x under gravity (-z), one slack cable."""
    return Robot(parse_robot_description({
        'name': 'cantilever',
        'rod': {'length': 0.3, 'diameter': 0.002, 'youngs_modulus': 58e9, 'poisson_ratio': 0.33,
                'density': 6450.0},
        'base': {'frame_id': 'base_link', 'position': [0, 0, 0], 'orientation': HORIZONTAL},
        'gravity': [0, 0, -9.81],
        'sections': [{'name': 's', 'guides': [0.3], 'cables': [
            {'name': 'c', 'offset': [0.001, 0, 0], 'length_limits': [0.2, 0.4]}]}],
        'solver': {'steps': steps, 'max_iterations': 50, 'bvp_tolerance': 1e-12,
                   'estimate_tolerance': 1e-9, 'goal_tolerance': 1e-4},
        'body_radius': 0.001}))


def _extrapolated(coarse, fine, ratio):
    """Richardson's value of a second-order quantity from refinements ``ratio`` apart."""
    return fine + (fine - coarse) / (ratio ** 2 - 1.0)


def _compare(package, reference, name):
    """(tip error m, relative force error, contact s error m) of package shapes vs a reference."""
    (contact,) = [c for c in package.contacts if c.obstacle == name]
    return (float(np.linalg.norm(package.tip_position - reference['tip'])),
            abs(contact.force - reference['force']) / reference['force'],
            abs(contact.s - reference['s']))


def _planar_reference(obstacle, tip_force):
    rod = Rod.nitinol(tip_force=np.asarray(tip_force), base_direction=np.array([1.0, 0, 0]),
                      body_radius=0.001)
    coarse, fine = (solve_planar(rod, [obstacle], n=n) for n in (200, 400))
    assert coarse.success and fine.success
    name = obstacle.name
    return {'tip': _extrapolated(coarse.tip, fine.tip, 2.0),
            'force': _extrapolated(coarse.contacts[name].magnitude,
                                   fine.contacts[name].magnitude, 2.0),
            's': _extrapolated(coarse.contacts[name].s, fine.contacts[name].s, 2.0)}


@pytest.mark.parametrize('case', ['cylinder', 'plane'])
def test_a_planar_cantilever_on_a_cylinder_or_a_plane_matches_the_reference(case):
    """Weight and a tip load press the rod on a bar across it, or its tip on a floor."""
    if case == 'cylinder':
        reference = _planar_reference(Cylinder('bar', np.array([0.15, 0, -0.014]),
                                               np.array([0, 1.0, 0]), 0.01), (0, 0, -0.2))
        entry = {'name': 'bar', 'capsule': {'radius': 0.01, 'length': 2.0},
                 'position': [0.15, 0, -0.014], 'orientation': [0.7071067811865476, 0, 0,
                                                                0.7071067811865476]}
        tip_force = (0, 0, -0.2)
    else:
        reference = _planar_reference(Plane('floor', np.array([0, 0, 1.0]), -0.012),
                                      (0.05, 0, -0.1))
        entry = {'name': 'floor', 'plane': {'normal': [0, 0, 1], 'offset': -0.012}}
        tip_force = (0.05, 0, -0.1)
    obstacles = parse_obstacles([entry])
    errors = [_compare(_cantilever(steps).solve_tensions([0.0], tip_force=tip_force,
                                                         obstacles=obstacles),
                       reference, entry['name']) for steps in (25, 100, 200)]
    print('%s: tip, force, s errors at 25/100/200 steps: %s' % (case, errors))
    tip, force, where = errors[-1]
    assert tip < 1e-5 and force < 1e-3 and where < 1e-5  # targets: 0.1 mm, 2 %
    if case == 'cylinder':  # converging as the steps are refined (at the tip: exact at any)
        assert errors[0][0] > 10 * errors[1][0]


def test_a_two_section_robot_resting_on_a_sphere_matches_the_3d_reference():
    """The robot's own rod, slack cables, a sideways tip load onto a ball off its plane."""
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    tip_force = np.array([0.3, 0.1, 0.0])
    rod = Rod.nitinol(tip_force=tip_force, body_radius=robot.body_radius)
    ball = Sphere('ball', np.array([0.035, 0.012, 0.2]), 0.02)
    coarse, fine = (solve_3d(rod, [ball], n=n) for n in (80, 120))
    assert coarse.success and fine.success
    reference = {'tip': _extrapolated(coarse.tip, fine.tip, 1.5),
                 'force': _extrapolated(coarse.contacts['ball'].magnitude,
                                        fine.contacts['ball'].magnitude, 1.5),
                 's': _extrapolated(coarse.contacts['ball'].s, fine.contacts['ball'].s, 1.5)}
    obstacles = parse_obstacles([{'name': 'ball', 'sphere': {'radius': 0.02},
                                  'position': [0.035, 0.012, 0.2]}])
    errors = [_compare(robot.with_solver(steps=steps).solve_tensions(
        np.zeros(6), tip_force=tip_force, obstacles=obstacles), reference, 'ball')
        for steps in (24, 96)]
    print('sphere: tip, force, s errors at 24/96 steps: %s' % errors)
    tip, force, where = errors[-1]
    assert tip < 5e-6 and force < 1e-3 and where < 1e-5
    assert errors[0][0] > errors[1][0]
