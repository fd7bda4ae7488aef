"""Multi-section robots and both cable models against independent truths.

Truths: closed-form arcs (constant curvature per section, derived below), Euler-Bernoulli, and
the slow SciPy reference in ``reference_rucker_webster.py`` (Rucker & Webster 2011 differential
form, written without the package's core). Reference solutions are cached within the module.

Constant-curvature limit (no gravity, no tip load), derived from the rod-plus-tendons free body
beyond s: its only loads are internal, so N = n + sum_active t_j tau_j = 0 and
m + sum_active (R l_j) x t_j tau_j = 0. With straight routing, v = (0, 0, v3) and u = (u1, u2, 0)
the tendon tangents tau_j = R (v + u x l_j) / |.| are all R e3, which solves both with

    u_k = sum_{j in sections >= k} t_j (e3 x l_j) / (E I),   v3_k = 1 - sum_{j active} t_j / (E A)

constant in each section: each section is a circular arc in its own plane, its arc length
compressed by v3 (``distributed``). ``point_moment`` has no tendon force (v3 = 1); its end-disk
moments t_j R(s_k) (e3 x l_j) are fixed in space, but section k bends about the very axis
sum_{j in k} t_j (e3 x l_j) + (moments of the sections beyond), which the rotation leaves alone,
so by induction from the tip the same u_k holds: the two models differ only by the compression.

The ``distributed`` reference includes what R&W's piecewise integration leaves out: where the
strains jump at a disk (under gravity or tip loads), a cable running on through it kinks and
pushes on its hole. Without that load the rod-plus-cables body is out of balance (0.015 N in
test_reference_keeps_rod_and_cables_in_equilibrium) and the shape moves by up to ~1e-4 m.
"""
import copy
import functools

from conftest import REPO
import numpy as np
import pytest
from reference_rucker_webster import solve_reference
from scipy.spatial.transform import Rotation
import yaml

from continuum_statics import load_robot
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

TWO_SECTION = REPO / 'config' / 'two_section_robot.yaml'
THREE_SECTION = REPO / 'config' / 'three_section_robot.yaml'
ONE_SECTION = REPO / 'config' / 'tendon_robot.yaml'
E3 = np.array([0.0, 0.0, 1.0])
NODE_TOLERANCE = 1e-6  # m, model vs reference at every node
ARC_TOLERANCE = 1e-7  # m, model vs closed-form arcs at the default step count


# ---------------------------------------------------------------- robot files, read here alone

def read_yaml(path):
    """Return the robot file as a plain mapping."""
    with open(path) as stream:
        return yaml.safe_load(stream)


def variant(path, **changes):
    """Return (Robot, mapping) for the robot file with top-level keys replaced."""
    data = read_yaml(path)
    data.update(copy.deepcopy(changes))
    return Robot(parse_robot_description(copy.deepcopy(data))), data


class Geometry:
    """What the tests need of a robot file, read from its YAML (not from the package)."""

    def __init__(self, data):
        rod = data['rod']
        self.length = float(rod['length'])
        self.diameter = float(rod['diameter'])
        self.youngs_modulus = float(rod['youngs_modulus'])
        self.poisson_ratio = float(rod['poisson_ratio'])
        self.density = float(rod['density'])
        self.ei = self.youngs_modulus * np.pi * self.diameter ** 4 / 64.0
        self.ea = self.youngs_modulus * np.pi * self.diameter ** 2 / 4.0
        base = data.get('base', {})
        self.base_position = np.asarray(base.get('position', [0.0, 0.0, 0.0]), float)
        self.base_rotation = Rotation.from_quat(
            base.get('orientation', [0.0, 0.0, 0.0, 1.0])).as_matrix()  # [x, y, z, w]
        self.gravity = np.asarray(data.get('gravity', [0.0, 0.0, -9.81]), float)
        self.model = data.get('cable_model', 'point_moment')
        sections = data.get('sections') or [
            {'name': 'section', 'guides': data['guides'], 'cables': data['cables']}]
        self.section_ends = [float(section['guides'][-1]) for section in sections]
        self.section_starts = [0.0] + self.section_ends[:-1]
        self.names, self.offsets, self.cable_sections = [], [], []
        for k, section in enumerate(sections):
            for cable in section['cables']:
                self.names.append(cable['name'])
                self.offsets.append(np.asarray(cable['offset'], float))
                self.cable_sections.append(k)
        self.offsets = np.array(self.offsets).reshape(-1, 3)
        assert np.all(self.offsets[:, 2] == 0.0), 'the arcs below assume holes in the xy plane'
        self.cable_sections = np.array(self.cable_sections, int)

    def cables_of(self, k):
        """Return the indices (file order) of section k's cables."""
        return np.flatnonzero(self.cable_sections == k)

    def section_length(self, k):
        """Return section k's length along the backbone, m."""
        return self.section_ends[k] - self.section_starts[k]

    def bend_tension(self, k, angle):
        """Return the tension on one cable of section k alone that bends it by angle (rad)."""
        radius = np.mean(np.linalg.norm(self.offsets[self.cables_of(k)], axis=1))
        return angle * self.ei / (radius * self.section_length(k))

    def cable_towards(self, k, direction):
        """Return the index of section k's cable whose hole points most along direction."""
        cables = self.cables_of(k)
        return cables[np.argmax(self.offsets[cables, :2] @ np.asarray(direction, float))]

    def in_robot_order(self, robot, tensions):
        """Reorder file-order tensions into robot.cable_names order (matched by name)."""
        assert sorted(robot.cable_names) == sorted(self.names)
        return np.array([tensions[self.names.index(name)] for name in robot.cable_names])


def reference(geometry, tensions, s, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
              model=None, gravity=None, disk_kinks=True):
    """Solve the reference for a robot file (tensions in file order) at arc lengths s.

    ``disk_kinks`` defaults to True: a cable running on through a disk where the strains jump
    pushes on its hole, which the rod-plus-cables equilibrium requires
    (test_reference_keeps_rod_and_cables_in_equilibrium).
    """
    return solve_reference(
        length=geometry.length, diameter=geometry.diameter,
        youngs_modulus=geometry.youngs_modulus, poisson_ratio=geometry.poisson_ratio,
        density=geometry.density, base_position=geometry.base_position,
        base_rotation=geometry.base_rotation,
        gravity=geometry.gravity if gravity is None else gravity,
        section_ends=geometry.section_ends, cable_offsets=geometry.offsets,
        cable_sections=geometry.cable_sections, tensions=tensions, tip_force=tip_force,
        tip_moment=tip_moment, model=model or geometry.model, s_eval=s, disk_kinks=disk_kinks)


# ---------------------------------------------------------------- closed-form arcs

def arc_segment(u, stretch, sigma):
    """Return local position and rotation after sigma of constant u, v = stretch e3."""
    kappa = np.linalg.norm(u)
    u_hat = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
    if kappa * sigma < 1e-12:
        left = sigma * np.eye(3)
    else:
        left = (sigma * np.eye(3) + (1.0 - np.cos(kappa * sigma)) / kappa ** 2 * u_hat
                + (kappa * sigma - np.sin(kappa * sigma)) / kappa ** 3 * u_hat @ u_hat)
    return stretch * left @ E3, Rotation.from_rotvec(u * sigma).as_matrix()


def piecewise_arcs(geometry, tensions, s, compressed):
    """Return positions and rotations of the constant-curvature solution at arc lengths s."""
    positions = np.empty((len(s), 3))
    rotations = np.empty((len(s), 3, 3))
    start_p, start_r = geometry.base_position, geometry.base_rotation
    for k, (start, end) in enumerate(zip(geometry.section_starts, geometry.section_ends)):
        active = geometry.cable_sections >= k
        u = np.cross(E3, tensions[active] @ geometry.offsets[active]) / geometry.ei
        stretch = 1.0 - np.sum(tensions[active]) / geometry.ea if compressed else 1.0
        inside = (s >= start - 1e-12) & (s <= end + 1e-12)
        for i in np.flatnonzero(inside):
            p, r = arc_segment(u, stretch, s[i] - start)
            positions[i] = start_p + start_r @ p
            rotations[i] = start_r @ r
        p, r = arc_segment(u, stretch, end - start)
        start_p, start_r = start_p + start_r @ p, start_r @ r
    assert s[-1] <= geometry.section_ends[-1] + 1e-12, 'rod beyond the last disk: not covered'
    return positions, rotations


def node_error(shape, positions):
    """Return the largest distance between the shape's nodes and positions, m."""
    return float(np.max(np.linalg.norm(shape.positions - positions, axis=1)))


# ---------------------------------------------------------------- the reference itself

def test_reference_matches_euler_bernoulli_and_arcs():
    geometry = Geometry(read_yaml(ONE_SECTION))
    s = np.linspace(0.0, geometry.length, 13)
    no_tension = np.zeros(len(geometry.names))
    # (a) small tip force, no cable load: F L^3 / (3 E I) within 1 %
    load = 1e-4 * 3.0 * geometry.ei / geometry.length ** 2
    sol = reference(geometry, no_tension, s, tip_force=(-load, 0.0, 0.0), gravity=np.zeros(3))
    local = np.linalg.solve(geometry.base_rotation, sol['positions'][-1] - geometry.base_position)
    assert -local[0] == pytest.approx(load * geometry.length ** 3 / (3.0 * geometry.ei), rel=1e-2)
    # (b), (c) one cable bending the rod by 1.5 rad: exact arcs, compressed for distributed
    tensions = np.zeros(len(geometry.names))
    tensions[0] = geometry.bend_tension(0, 1.5)
    for model, compressed in (('point_moment', False), ('distributed', True)):
        sol = reference(geometry, tensions, s, model=model, gravity=np.zeros(3))
        positions, rotations = piecewise_arcs(geometry, tensions, s, compressed)
        assert np.max(np.linalg.norm(sol['positions'] - positions, axis=1)) < 1e-9
        assert np.max(np.abs(sol['rotations'] - rotations)) < 1e-9
    # the compression is visible at this tolerance: t L / (E A) >> 1e-9 m
    assert tensions[0] * geometry.length / geometry.ea > 1e-6


def rod_and_cables_imbalance(geometry, tensions, s, solution, tip_force, tip_moment):
    """Return the largest force (N) and moment (N m) imbalance of the rod-plus-cables body.

    Everything beyond s (rod and the cables in it) carries only its weight and the tip load;
    cut there, it feels the rod's n, m and each running cable's pull t_j tau_j at its hole.
    """
    weight = geometry.density * np.pi * geometry.diameter ** 2 / 4.0 * geometry.gravity
    positions = solution['positions']
    shear = geometry.youngs_modulus / (2.0 * (1.0 + geometry.poisson_ratio))
    area = np.pi * geometry.diameter ** 2 / 4.0
    d = np.array([shear * area, shear * area, geometry.ea])
    c = np.array([geometry.ei, geometry.ei, 2.0 * shear * geometry.ei / geometry.youngs_modulus])
    force_error = moment_error = 0.0
    for i, s_i in enumerate(s[:-1]):
        if np.min(np.abs(np.array(geometry.section_ends) - s_i)) < 1e-9:
            continue  # strains jump at a disk
        rot = solution['rotations'][i]
        v = E3 + rot.T @ solution['n'][i] / d
        u = rot.T @ solution['m'][i] / c
        force, moment = solution['n'][i].copy(), solution['m'][i].copy()
        for j in np.flatnonzero(np.array(geometry.section_ends)[geometry.cable_sections] > s_i):
            tangent = v + np.cross(u, geometry.offsets[j])
            pull = tensions[j] * rot @ tangent / np.linalg.norm(tangent)
            force += pull
            moment += np.cross(rot @ geometry.offsets[j], pull)
        beyond = s >= s_i
        arms = positions[beyond] - positions[i]
        expected_force = tip_force + weight * (s[-1] - s_i)
        expected_moment = (tip_moment + np.cross(positions[-1] - positions[i], tip_force)
                           + np.trapezoid(np.cross(arms, weight), s[beyond], axis=0))
        force_error = max(force_error, np.linalg.norm(force - expected_force))
        moment_error = max(moment_error, np.linalg.norm(moment - expected_moment))
    return force_error, moment_error


def test_reference_keeps_rod_and_cables_in_equilibrium():
    geometry = Geometry(read_yaml(TWO_SECTION))
    tensions = np.zeros(len(geometry.names))
    tensions[[0, 2, 4]] = np.array([0.5, 0.3, 0.4]) * geometry.bend_tension(0, np.pi / 2)
    force = np.array([0.4, -0.3, -0.5]) * geometry.ei / geometry.length ** 2
    moment = np.array([0.0, 0.05, 0.1]) * geometry.ei / geometry.length
    s = np.linspace(0.0, geometry.length, 601)
    kinked = reference(geometry, tensions, s, force, moment, model='distributed')
    plain = reference(geometry, tensions, s, force, moment, model='distributed',
                      disk_kinks=False)
    force_error, moment_error = rod_and_cables_imbalance(geometry, tensions, s, kinked, force,
                                                         moment)
    assert force_error < 1e-9 and moment_error < 1e-7  # trapezoid rule on the weight's moment
    # without the cables' kink loads at the disk the body beyond it is out of balance
    force_error, _ = rod_and_cables_imbalance(geometry, tensions, s, plain, force, moment)
    assert force_error > 1e-3  # 0.015 N here


# ---------------------------------------------------------------- constant-curvature limits

@pytest.mark.parametrize('path', [TWO_SECTION, THREE_SECTION])
def test_distributed_sections_are_compressed_circular_arcs(path):
    robot, data = variant(path, gravity=[0.0, 0.0, 0.0], cable_model='distributed')
    geometry = Geometry(data)
    rng = np.random.default_rng(8)
    for _ in range(3):
        # antagonistic pairs included: they compress without bending
        tensions = np.zeros(len(geometry.names))
        for k in range(len(geometry.section_ends)):
            cables = geometry.cables_of(k)
            tensions[cables] = rng.uniform(0.0, 0.6, len(cables)) * geometry.bend_tension(
                k, np.pi / 2)
        shape = robot.solve_tensions(geometry.in_robot_order(robot, tensions))
        positions, rotations = piecewise_arcs(geometry, tensions, shape.s, compressed=True)
        uncompressed, _ = piecewise_arcs(geometry, tensions, shape.s, compressed=False)
        assert node_error(shape, positions) < ARC_TOLERANCE
        assert np.max(np.abs(shape.rotations - rotations)) < 1e-6
        # the test sees the compression: leaving it out would fail by far
        assert node_error(shape, uncompressed) > 10 * ARC_TOLERANCE


@pytest.mark.parametrize('path', [ONE_SECTION, TWO_SECTION, THREE_SECTION])
def test_point_moment_sections_are_circular_arcs(path):
    robot, data = variant(path, gravity=[0.0, 0.0, 0.0], cable_model='point_moment')
    geometry = Geometry(data)
    rng = np.random.default_rng(9)
    for _ in range(3):
        tensions = np.zeros(len(geometry.names))
        for k in range(len(geometry.section_ends)):
            cables = geometry.cables_of(k)
            tensions[cables] = rng.uniform(0.0, 0.6, len(cables)) * geometry.bend_tension(
                k, np.pi / 2)
        shape = robot.solve_tensions(geometry.in_robot_order(robot, tensions))
        positions, rotations = piecewise_arcs(geometry, tensions, shape.s, compressed=False)
        assert node_error(shape, positions) < ARC_TOLERANCE
        assert np.max(np.abs(shape.rotations - rotations)) < 1e-6


@pytest.mark.parametrize('degrees', [45.0, 90.0, 180.0, 270.0, 315.0])
def test_pure_moment_arc_is_exact_at_default_steps(degrees):
    robot, data = variant(ONE_SECTION, gravity=[0.0, 0.0, 0.0], cable_model='point_moment')
    geometry = Geometry(data)
    angle = np.radians(degrees)
    tensions = np.zeros(len(geometry.names))
    tensions[0] = geometry.bend_tension(0, angle)
    shape = robot.solve_tensions(geometry.in_robot_order(robot, tensions))
    positions, _ = piecewise_arcs(geometry, tensions, shape.s, compressed=False)
    assert node_error(shape, positions) < ARC_TOLERANCE
    # the same arc from the paper's IVP with that base curvature
    u0 = np.cross(E3, tensions[0] * geometry.offsets[0]) / geometry.ei
    ivp = robot.solve_ivp(u0)
    positions, _ = piecewise_arcs(geometry, tensions, ivp.s, compressed=False)
    assert node_error(ivp, positions) < ARC_TOLERANCE


# ---------------------------------------------------------------- the two models together

def test_models_agree_when_no_cable_pulls():
    distributed, data = variant(TWO_SECTION, cable_model='distributed')
    point_moment, _ = variant(TWO_SECTION, cable_model='point_moment')
    geometry = Geometry(data)
    assert np.linalg.norm(geometry.gravity) > 0.0
    force = np.array([0.3, -0.2, -0.4]) * geometry.ei / geometry.length ** 2
    moment = np.array([0.1, 0.05, -0.1]) * geometry.ei / geometry.length
    zeros = np.zeros(len(geometry.names))
    a = distributed.solve_tensions(zeros, tip_force=force, tip_moment=moment)
    b = point_moment.solve_tensions(zeros, tip_force=force, tip_moment=moment)
    assert np.allclose(a.s, b.s)
    assert node_error(a, b.positions) < 1e-10
    # and the load did bend the rod (the comparison is not between two straight rods)
    straight = geometry.base_position + np.outer(a.s, geometry.base_rotation @ E3)
    assert node_error(a, straight) > 1e-3


# ---------------------------------------------------------------- against the reference

def reference_cases():
    """Return {name: (path, model, tensions, tip force, tip moment)}, loads in E I units."""
    def s_shape(g):
        t = np.zeros(len(g.names))
        direction = g.offsets[g.cables_of(0)[0], :2]
        t[g.cable_towards(0, direction)] = g.bend_tension(0, 1.2)
        t[g.cable_towards(1, -direction)] = g.bend_tension(1, 1.6)
        return t

    def out_of_plane(g):
        t = np.zeros(len(g.names))
        direction = g.offsets[g.cables_of(0)[0], :2]
        t[g.cable_towards(0, direction)] = g.bend_tension(0, 1.0)
        t[g.cable_towards(1, [-direction[1], direction[0]])] = g.bend_tension(1, 1.4)
        return t

    def mixed(g):
        rng = np.random.default_rng(11)
        t = np.zeros(len(g.names))
        for k in range(len(g.section_ends)):
            cables = g.cables_of(k)
            t[cables] = rng.uniform(0.0, 0.5, len(cables)) * g.bend_tension(k, np.pi / 2)
        return t

    return {
        'distributed S-shape': (TWO_SECTION, 'distributed', s_shape, None, None),
        'distributed out of plane': (TWO_SECTION, 'distributed', out_of_plane, None, None),
        'distributed tip force': (TWO_SECTION, 'distributed', mixed, (0.4, -0.3, -0.5), None),
        'distributed 3 sections sideways gravity': (THREE_SECTION, 'distributed', mixed,
                                                    (0.2, -0.1, 0.2), (0.05, 0.1, -0.1)),
        'point_moment 2 sections': (TWO_SECTION, 'point_moment', out_of_plane,
                                    (0.2, 0.3, -0.3), None),
        'point_moment 3 sections': (THREE_SECTION, 'point_moment', mixed, (-0.2, 0.1, -0.3),
                                    (0.05, -0.05, 0.1)),
    }


@functools.lru_cache(maxsize=None)
def solved_case(name, disk_kinks=True):
    """Return (shape, reference solution, geometry) of a named case, cached."""
    path, model, build, force, moment = reference_cases()[name]
    changes = {'cable_model': model}
    if 'sideways' in name:  # the rod's base turned so gravity acts across it
        changes['gravity'] = [9.81 * 0.6, 0.0, -9.81 * 0.8]
    robot, data = variant(path, **changes)
    geometry = Geometry(data)
    tensions = build(geometry)
    force = np.zeros(3) if force is None else (
        np.asarray(force) * geometry.ei / geometry.length ** 2)
    moment = np.zeros(3) if moment is None else (
        np.asarray(moment) * geometry.ei / geometry.length)
    shape = robot.solve_tensions(geometry.in_robot_order(robot, tensions), tip_force=force,
                                 tip_moment=moment)
    truth = reference(geometry, tensions, np.asarray(shape.s, float), tip_force=force,
                      tip_moment=moment, model=model, disk_kinks=disk_kinks)
    return shape, truth, geometry


@pytest.mark.parametrize('name', list(reference_cases()))
def test_tension_solve_matches_reference(name):
    shape, truth, geometry = solved_case(name)
    error = node_error(shape, truth['positions'])
    message = f'{name}: {error:.3e} m from the reference'
    if error >= NODE_TOLERANCE and 'distributed' in name:  # diagnose: a different model?
        plain = node_error(shape, solved_case(name, disk_kinks=False)[1]['positions'])
        message += f', {plain:.3e} m from the reference without cable kinks at disks'
    assert error < NODE_TOLERANCE, message
    assert np.max(np.abs(shape.rotations - truth['rotations'])) < 10 * NODE_TOLERANCE / (
        geometry.length)
    # the case is not trivial: its tip is far from the straight rod's
    straight = geometry.base_position + geometry.length * geometry.base_rotation @ E3
    assert np.linalg.norm(shape.tip_position - straight) > 0.05 * geometry.length


# ---------------------------------------------------------------- estimation and tip goals

def minimal_tensions(geometry, rng, scale=0.6):
    """Return file-order tensions on at most two neighbouring cables per section.

    That is the least-tension way to make each section's bending moment, so the lengths alone
    determine it (no co-contraction an estimator could not see).
    """
    tensions = np.zeros(len(geometry.names))
    for k in range(len(geometry.section_ends)):
        cables = geometry.cables_of(k)
        moment_direction = rng.normal(size=2)
        # nonnegative t on cable pairs with sum t_j l_j = magnitude * direction
        target = moment_direction / np.linalg.norm(moment_direction)
        best = None
        for i in cables:
            for j in cables:
                if i >= j:
                    continue
                pair = np.column_stack([geometry.offsets[i, :2], geometry.offsets[j, :2]])
                if abs(np.linalg.det(pair)) < 1e-12:
                    continue
                weights = np.linalg.solve(pair, target)
                if np.all(weights >= -1e-12) and (best is None or weights.sum() < best[2].sum()):
                    best = (i, j, weights)
        i, j, weights = best
        magnitude = rng.uniform(0.2, scale) * geometry.bend_tension(k, np.pi / 2) * np.linalg.norm(
            geometry.offsets[i])
        tensions[[i, j]] = magnitude * np.maximum(weights, 0.0)
    return tensions


@pytest.mark.parametrize('path', [TWO_SECTION, THREE_SECTION])
@pytest.mark.parametrize('with_tensions', [False, True])
def test_estimation_round_trip(path, with_tensions):
    robot = load_robot(path)
    geometry = Geometry(read_yaml(path))
    rng = np.random.default_rng(3)
    force = np.array([0.1, -0.2, -0.1]) * geometry.ei / geometry.length ** 2
    previous = None
    for trial in range(3):
        if with_tensions:  # co-contraction too: the measured tensions tell
            tensions = rng.uniform(0.0, 0.5, len(geometry.names)) * geometry.bend_tension(
                0, np.pi / 2)
        else:
            tensions = geometry.in_robot_order(robot, minimal_tensions(geometry, rng))
        truth = robot.solve_tensions(tensions, tip_force=force)
        lengths = robot.cable_lengths(truth)
        est = robot.estimate_shape(lengths, tip_force=force,
                                   tensions=tensions if with_tensions else None,
                                   warm_start=previous, exact=True)  # far apart: to the end
        assert est.converged, (trial, est.residual)
        assert np.linalg.norm(est.shape.tip_position - truth.tip_position) < 1e-6, trial
        assert np.max(np.abs(robot.cable_lengths(est.shape) - lengths)) < 1e-6, trial
        previous = est


def workspace_goals(robot, geometry, count, rng):
    """Return tip positions of tension solves whose cable lengths are inside the limits."""
    limits = np.asarray(robot.cable_length_limits, float)
    goals = []
    for _ in range(20 * count):
        tensions = geometry.in_robot_order(robot, minimal_tensions(geometry, rng, scale=1.0))
        shape = robot.solve_tensions(tensions)
        lengths = robot.cable_lengths(shape)
        if np.all(lengths > limits[:, 0] + 1e-4) and np.all(lengths < limits[:, 1] - 1e-4):
            goals.append(shape.tip_position)
            if len(goals) == count:
                return goals
    raise AssertionError(f'only {len(goals)} goals inside the length limits')


def test_tip_goals_across_the_two_section_workspace():
    robot = load_robot(TWO_SECTION)
    geometry = Geometry(read_yaml(TWO_SECTION))
    limits = np.asarray(robot.cable_length_limits, float)
    tolerance = 1e-4
    goals = workspace_goals(robot, geometry, 20, np.random.default_rng(5))
    spread = np.ptp(np.array(goals), axis=0)
    assert np.max(spread) > 0.1 * geometry.length  # goals across the workspace, not one spot
    failures = []
    previous = None
    for index, goal in enumerate(goals):
        for start, warm in (('cold', None), ('warm', previous)):
            if start == 'warm' and warm is None:
                continue
            sol = robot.solve_tip_goal(goal, tolerance=tolerance, warm_start=warm)
            lengths = np.asarray(sol.cable_lengths, float)
            label = f'goal {index} {np.round(goal, 4)} {start}'
            # lengths inside the limits and those of the shape returned, always
            outside = max(np.max(limits[:, 0] - lengths), np.max(lengths - limits[:, 1]))
            if outside > 1e-12:
                failures.append(f'{label}: lengths {outside:.3g} m outside the limits')
            assert np.max(np.abs(robot.cable_lengths(sol.shape) - lengths)) < 1e-6, label
            miss = np.linalg.norm(sol.shape.tip_position - goal)
            if not (sol.converged and miss <= tolerance):
                failures.append(f'{label}: tip {miss:.3g} m away, converged={sol.converged}')
            if start == 'cold':
                cold = sol
        previous = cold
    assert not failures, f'{2 * len(goals) - 1} solves: ' + '; '.join(failures)


# ---------------------------------------------------------------- bad input

@pytest.mark.parametrize('bad', [-1e-3, np.nan, np.inf, -np.inf])
def test_solve_tensions_rejects_negative_or_non_finite(bad):
    robot = load_robot(TWO_SECTION)
    tensions = np.ones(len(robot.cable_names))
    tensions[-1] = bad
    with pytest.raises(ValueError):
        robot.solve_tensions(tensions)

