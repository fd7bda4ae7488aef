"""General (helical, per-guide) tendon routing, against truths the package does not compute.

- a SciPy shooting solution of Rucker & Webster's general-routing equations (rod-only
  formulation with the r' and r'' terms, ``reference_rucker_webster.py``), where the kernel uses
  the rod-plus-tendons cut formulation;
- the first-order torsion of a helical tendon on a straight rod, derived by hand;
- mirror symmetry: a left-handed helix gives the mirror image of the right-handed one;
- straight routing written three ways (``offset``, ``offsets``, ``helix`` with no turns) gives
  the same robot to round-off.
"""
import copy
import math

import numpy as np
import pytest
from reference_rucker_webster import solve_reference
import yaml

from continuum_statics.calibration.parameters import candidate_robot
from continuum_statics.calibration.robot_writer import write_robot_file
from continuum_statics.core.description.layout import BENDING
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

LENGTH, DIAMETER, YOUNGS, NU, DENSITY = 0.25, 1.4e-3, 54.0e9, 0.3, 6450.0
RADIUS = 0.008  # hole radius, m
GUIDES = [round(0.025 * (i + 1), 6) for i in range(10)]
HORIZONTAL = [0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5)]  # local z along global x: gravity bends


def _hole(angle):
    return [RADIUS * math.cos(angle), RADIUS * math.sin(angle), 0.0]


def robot_file(helix_turns=2.0, start_angle=0.5, gravity=(0.0, 0.0, -9.81), steps=300,
               orientation=HORIZONTAL, helix_entry=None):
    """Three straight cables at 0, 120, 240 degrees and one helical cable (the last)."""
    straight = [{'name': 'c%d' % k, 'offset': _hole(2.0 * math.pi * k / 3.0)}
                for k in range(3)]
    helix = helix_entry or {'name': 'helix', 'helix': {
        'radius': RADIUS, 'start_angle': start_angle, 'turns_per_metre': helix_turns}}
    return {
        'name': 'helical_test',
        'rod': {'length': LENGTH, 'diameter': DIAMETER, 'youngs_modulus': YOUNGS,
                'poisson_ratio': NU, 'density': DENSITY},
        'base': {'frame_id': 'base', 'position': [0.0, 0.0, 0.0], 'orientation': orientation},
        'gravity': list(gravity),
        'cable_model': 'distributed',
        'guides': GUIDES,
        'cables': straight + [helix],
        'solver': {'steps': steps},
    }


def make(data):
    return Robot(parse_robot_description(copy.deepcopy(data)))


def helix_route(turns, start_angle):
    """S -> (l, l', l'') of the helix, written out for the reference."""
    rate = 2.0 * math.pi * turns

    def route(s, inside=None):
        phi = start_angle + rate * s
        c, si = math.cos(phi), math.sin(phi)
        return (RADIUS * np.array([c, si, 0.0]), RADIUS * rate * np.array([-si, c, 0.0]),
                -RADIUS * rate ** 2 * np.array([c, si, 0.0]))
    return route


def straight_route(offset):
    zero = np.zeros(3)
    return lambda _s, inside=None: (np.array(offset, dtype=float), zero, zero)


def disk_route(disks, holes):
    """(s, inside) -> (l, l', l'') of holes straight in the local frame between disks."""
    disks, holes = np.asarray(disks, dtype=float), np.asarray(holes, dtype=float)

    def route(s, inside=None):
        inside = s if inside is None else inside
        k = int(np.clip(np.searchsorted(disks, inside, side='right') - 1, 0, len(disks) - 2))
        slope = (holes[k + 1] - holes[k]) / (disks[k + 1] - disks[k])
        return holes[k] + slope * (s - disks[k]), slope, np.zeros(3)
    return route


@pytest.mark.parametrize('tensions, tip_force', [
    ([0.0, 0.0, 0.0, 3.0], [0.0, 0.0, 0.0]),
    ([0.5, 0.0, 0.2, 2.0], [0.0, 0.02, -0.01]),
])
def test_helical_cable_matches_the_rucker_webster_reference(tensions, tip_force):
    robot = make(robot_file())
    shape = robot.solve_tensions(tensions, tip_force=tip_force)
    routes = [straight_route(_hole(2.0 * math.pi * k / 3.0)) for k in range(3)]
    routes.append(helix_route(2.0, 0.5))
    nodes = np.linspace(0.0, LENGTH, 6)
    reference = solve_reference(
        LENGTH, DIAMETER, YOUNGS, NU, DENSITY, robot.base_position, robot.base_rotation,
        robot.gravity, section_ends=[LENGTH],
        cable_offsets=[route(0.0)[0] for route in routes], cable_sections=[0, 0, 0, 0],
        tensions=tensions, tip_force=tip_force, tip_moment=[0.0, 0.0, 0.0],
        model='distributed', s_eval=nodes, cable_routes=routes)
    ours = np.array([shape.positions[np.argmin(np.abs(shape.s - s))] for s in nodes])
    error = np.max(np.linalg.norm(ours - reference['positions'], axis=1))
    assert error <= 1e-6, error
    # the tip frame too (twist included): angle between the frames below 1e-5 rad
    turn = shape.rotations[-1].T @ reference['rotations'][-1]
    assert math.acos(min(1.0, (np.trace(turn) - 1.0) / 2.0)) <= 1e-5
    # and the helix bends the rod by centimetres: the comparison is not of two straight rods
    assert np.linalg.norm(shape.positions[-1] - robot.solve_ivp([0, 0, 0]).positions[-1]) > 0.01


def test_helical_tendon_twists_the_rod_as_first_order_statics_says():
    """A helical tendon on a free rod twists it by GJ u_z = -t r^2 phi' / k all along.

    Free rod, one helical tendon at small tension t: the rod-plus-tendon body beyond s is free,
    so the rod's moment balances the tendon's, C u = -t l x tau with tau = (e3 + l') / k,
    k = sqrt(1 + r^2 phi'^2).
    """
    tension, turns = 0.02, 2.0
    robot = make(robot_file(helix_turns=turns, gravity=(0.0, 0.0, 0.0)))
    shape = robot.solve_tensions([0.0, 0.0, 0.0, tension])
    rate = 2.0 * math.pi * turns
    k = math.sqrt(1.0 + (RADIUS * rate) ** 2)
    gj = robot.c[2]
    expected = -tension * RADIUS ** 2 * rate / (k * gj)
    twist = np.array(shape.states)[:, BENDING][:, 2]
    # first order in t: the bending it causes changes tau by O(t), so u_z by O(t^2)
    np.testing.assert_allclose(twist, expected, rtol=2e-3)
    # bending: |u_xy| = t r / (k E I), turning with the hole (half a turn over the rod)
    bend = np.linalg.norm(np.array(shape.states)[:, BENDING][:, :2], axis=1)
    np.testing.assert_allclose(bend, tension * RADIUS / (k * robot.c[0]), rtol=2e-3)


def test_left_handed_helix_gives_the_mirror_image():
    """Mirror in the plane through the axis and the base hole (y -> -y with the hole on +x)."""
    data = robot_file(helix_turns=2.0, start_angle=0.0, gravity=(0.0, 0.0, 0.0),
                      orientation=[0.0, 0.0, 0.0, 1.0])
    right = make(data).solve_tensions([0.0, 0.0, 0.0, 2.0])
    data['cables'][3]['helix']['turns_per_metre'] = -2.0
    left = make(data).solve_tensions([0.0, 0.0, 0.0, 2.0])
    mirror = np.diag([1.0, -1.0, 1.0])
    np.testing.assert_allclose(left.positions, right.positions @ mirror, atol=1e-12)
    # a half turn carries the hole to the other side: the rod curls out of the plane of its
    # base bending (R&W's helical example), and twists the other way when left-handed
    assert abs(right.positions[-1, 1]) > 0.2 * abs(right.positions[-1, 0])
    twist_right = np.array(right.states)[-1, BENDING][2]
    twist_left = np.array(left.states)[-1, BENDING][2]
    assert twist_right < 0.0 < twist_left
    assert twist_left == pytest.approx(-twist_right, rel=1e-9)


def test_straight_routing_three_ways_is_one_robot():
    angle = 0.7
    offset = _hole(angle)
    plain = make(robot_file(helix_entry={'name': 'helix', 'offset': offset}))
    per_disk = make(robot_file(helix_entry={'name': 'helix', 'offsets': [offset] * 11}))
    per_guide = make(robot_file(helix_entry={'name': 'helix', 'offsets': [offset[:2]] * 10}))
    no_turns = make(robot_file(helix_entry={'name': 'helix', 'helix': {
        'radius': RADIUS, 'start_angle': angle, 'turns_per_metre': 0.0}}))
    tensions = [0.4, 0.0, 0.1, 1.5]
    robots = (plain, per_disk, per_guide, no_turns)
    shapes = [robot.solve_tensions(tensions, tip_force=[0.0, 0.01, 0.0]) for robot in robots]
    lengths = [robot.cable_lengths(shape) for robot, shape in zip(robots, shapes)]
    for other, other_lengths in zip(shapes[1:], lengths[1:]):
        np.testing.assert_allclose(other.positions, shapes[0].positions, atol=1e-12)
        np.testing.assert_allclose(other_lengths, lengths[0], atol=1e-12)
    assert plain.routing.straight and not per_disk.routing.straight


def test_per_disk_offsets_turn_the_cable_at_each_disk():
    """Holes stepping round the rod disk by disk: straight spans between them (eq. 11).

    The cable's length on the straight rod is the sum of the hole-to-hole spans, by hand here.
    """
    angles = np.linspace(0.0, math.pi / 2.0, 11)
    holes = [_hole(a) for a in angles]
    robot = make(robot_file(helix_entry={'name': 'helix', 'offsets': holes}))
    disks = np.concatenate([[0.0], GUIDES])
    points = np.column_stack([disks, np.zeros_like(disks), np.zeros_like(disks)])
    points = points[:, [1, 2, 0]]  # along local z
    points = points + np.array(holes)
    expected = np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1))
    assert robot.straight_cable_lengths[3] == pytest.approx(expected, rel=1e-12)
    # and it bends and twists the rod under tension like a coarse helix
    shape = robot.solve_tensions([0.0, 0.0, 0.0, 2.0])
    assert np.array(shape.states)[-1, BENDING][2] < 0.0


def test_lengths_of_a_helical_robot_give_its_shape_back():
    robot = make(robot_file(steps=60))
    truth = robot.solve_tensions([0.6, 0.0, 0.0, 2.5], tip_force=[0.0, 0.0, -0.01])
    lengths = robot.cable_lengths(truth)
    estimate = robot.estimate_shape(lengths, tip_force=[0.0, 0.0, -0.01])
    assert estimate.converged
    assert np.max(np.abs(robot.cable_lengths(estimate.shape) - lengths)) < 1e-9
    assert np.linalg.norm(estimate.shape.positions[-1] - truth.positions[-1]) < 1e-4


@pytest.mark.parametrize('change, message', [
    (lambda d: d['cables'][3].update(offsets=[[0.01, 0.0]] * 3), r'cables\[3\]: give one of'),
    (lambda d: d['cables'][3].update(helix={'radius': 0.01}), r'cables\[3\]\.helix\.turns_per'),
    (lambda d: d['cables'][3]['helix'].update(pitch=1.0), r'cables\[3\]\.helix has unknown'),
    (lambda d: d['cables'][3].update(helix=None, offsets=[[0.01, 0.0]] * 3) or
     d['cables'][3].pop('helix'), r'cables\[3\]\.offsets must list one \[x, y\] \(m\) per guide '
                                  r'disk of the cable, 10 up to its end disk'),
])
def test_routing_mistakes_name_the_field(change, message):
    data = robot_file()
    change(data)
    with pytest.raises(ValueError, match=message):
        parse_robot_description(data)


def test_calibration_turns_routes_and_writes_them_back(tmp_path):
    """A fitted cable angle turns a helix and per-disk holes alike; the file reads back."""
    robot = make(robot_file(helix_entry={'name': 'helix', 'offsets': [_hole(0.1 * i)
                                                                      for i in range(11)]}))
    turned = candidate_robot(robot, {'cable_angle': np.array([0.0, 0.0, 0.0, 0.3])})
    expected = [_hole(0.1 * i + 0.3) for i in range(11)]
    np.testing.assert_allclose(turned.hole_offsets[3], expected, atol=1e-15)
    np.testing.assert_allclose(turned.hole_offsets[:3], robot.hole_offsets[:3], atol=0.0)
    source = tmp_path / 'routed.yaml'
    source.write_text(yaml.safe_dump(robot_file(helix_entry={
        'name': 'helix', 'offsets': [_hole(0.1 * i) for i in range(11)]})))
    output = tmp_path / 'calibrated.yaml'
    write_robot_file(output, source, turned, ('cable_angle',), ())
    again = Robot(parse_robot_description(yaml.safe_load(output.read_text())))
    np.testing.assert_allclose(again.hole_offsets, turned.hole_offsets, atol=1e-7)

    helical = make(robot_file())
    turned = candidate_robot(helical, {'cable_angle': np.array([0.0, 0.0, 0.0, 0.3])})
    assert turned.description.cable_routes[3].start_angle == pytest.approx(0.8)
    with pytest.raises(ValueError, match='section_length'):
        candidate_robot(helical, {'section_length': np.array([0.26])})


def test_holes_stepping_round_the_rod_match_the_reference_with_a_kink_at_every_disk():
    """Per-disk offsets: the cable turns at every disk (l' jumps), pushing on each hole."""
    angles = np.linspace(0.0, 0.8 * math.pi, 11)
    holes = [_hole(a) for a in angles]
    robot = make(robot_file(helix_entry={'name': 'stepped', 'offsets': holes}))
    tensions, tip_force = [0.3, 0.0, 0.0, 2.5], [0.0, 0.01, 0.0]
    shape = robot.solve_tensions(tensions, tip_force=tip_force)
    disks = [0.0] + GUIDES
    routes = [straight_route(_hole(2.0 * math.pi * k / 3.0)) for k in range(3)]
    routes.append(disk_route(disks, holes))
    reference = solve_reference(
        LENGTH, DIAMETER, YOUNGS, NU, DENSITY, robot.base_position, robot.base_rotation,
        robot.gravity, section_ends=[LENGTH],
        cable_offsets=[route(0.0)[0] for route in routes], cable_sections=[0, 0, 0, 0],
        tensions=tensions, tip_force=tip_force, tip_moment=[0.0, 0.0, 0.0],
        model='distributed', s_eval=np.array([LENGTH]), cable_routes=routes,
        route_breaks=GUIDES)
    error = np.linalg.norm(shape.positions[-1] - reference['positions'][-1])
    assert error <= 1e-6, error
    # without the kinks (l' jumps ignored: a smooth route through the same holes) the tip
    # moves by more than the tolerance, so the comparison sees them
    smooth = make(robot_file(helix_entry={'name': 'helix', 'helix': {
        'radius': RADIUS, 'start_angle': 0.0, 'turns_per_metre': 0.4 / LENGTH}}))
    assert np.linalg.norm(smooth.solve_tensions(tensions, tip_force=tip_force).positions[-1]
                          - shape.positions[-1]) > 1e-5


def test_two_sections_with_helices_match_the_reference():
    """A helix ending at the proximal section's end disk and one running to the tip."""
    split = 0.125
    data = robot_file()
    data.pop('guides')
    cables = data.pop('cables')
    data['sections'] = [
        {'name': 'proximal', 'guides': [g for g in GUIDES if g <= split],
         'cables': [cables[0], {'name': 'p_helix', 'helix': {
             'radius': RADIUS, 'start_angle': 1.0, 'turns_per_metre': 3.0}}]},
        {'name': 'distal', 'guides': [g for g in GUIDES if g > split],
         'cables': [cables[1], cables[3]]},
    ]
    robot = make(data)
    tensions, tip_force = [0.2, 1.5, 0.4, 2.0], [0.0, 0.0, 0.01]
    shape = robot.solve_tensions(tensions, tip_force=tip_force)
    routes = [straight_route(_hole(0.0)), helix_route(3.0, 1.0),
              straight_route(_hole(2.0 * math.pi / 3.0)), helix_route(2.0, 0.5)]
    reference = solve_reference(
        LENGTH, DIAMETER, YOUNGS, NU, DENSITY, robot.base_position, robot.base_rotation,
        robot.gravity, section_ends=[split, LENGTH],
        cable_offsets=[route(0.0)[0] for route in routes], cable_sections=[0, 0, 1, 1],
        tensions=tensions, tip_force=tip_force, tip_moment=[0.0, 0.0, 0.0],
        model='distributed', s_eval=np.array([split, LENGTH]), cable_routes=routes)
    for s, expected in zip((split, LENGTH), reference['positions']):
        ours = shape.positions[np.argmin(np.abs(shape.s - s))]
        assert np.linalg.norm(ours - expected) <= 1e-6, (s, np.linalg.norm(ours - expected))


def test_the_point_moment_model_takes_a_routed_cable_at_its_end_disk():
    """The paper's model takes a routed cable at its end disk; its length spans hole to hole.

    A cable acts only at its end disk, t R (e3 x l_end), and its length runs straight hole to
    hole through its routed holes (the discrete-guide model). So the shape equals that of a
    straight cable at the end-disk hole, and the straight rod's length is the sum of the chords
    between the helix's holes, by hand here.
    """
    helical = make(robot_file() | {'cable_model': 'point_moment'})
    end = helical.cable_offsets[3]
    straight = make(robot_file(helix_entry={'name': 'helix', 'offset': end.tolist()})
                    | {'cable_model': 'point_moment'})
    tensions = [0.2, 0.0, 0.0, 1.5]
    np.testing.assert_allclose(helical.solve_tensions(tensions).positions,
                               straight.solve_tensions(tensions).positions, atol=1e-12)
    disks = np.array([0.0] + GUIDES)
    phi = 0.5 + 2.0 * math.pi * 2.0 * disks
    holes = np.column_stack([RADIUS * np.cos(phi), RADIUS * np.sin(phi), disks])
    chords = np.sum(np.linalg.norm(np.diff(holes, axis=0), axis=1))
    assert helical.straight_cable_lengths[3] == pytest.approx(chords, rel=1e-12)
    assert chords > LENGTH + 1e-3  # the helix is longer than the rod
    # its lengths give its shape back (least squares on the section moments)
    shape = helical.solve_tensions(tensions)
    estimate = helical.estimate_shape(helical.cable_lengths(shape))
    assert np.linalg.norm(estimate.shape.positions[-1] - shape.positions[-1]) < 1e-6


@pytest.mark.parametrize('turns', [40.0, 20.0, -25.0])
def test_a_helix_with_more_turns_than_the_disks_can_carry_is_refused(turns):
    # issue 38: 40 turns/m at 25 mm disk spacing loaded silently and aliased to a straight cable
    with pytest.raises(ValueError, match='more than the disks can carry'):
        make(robot_file(helix_turns=turns))
    make(robot_file(helix_turns=19.0))  # under half a turn per 25 mm spacing: a helix
