"""Contact statics and clearance goals (doc/obstacles.md).

Truths used here, none of them the package's own contact code: the contact-free solve (an open
gap must change nothing), the rod's global force balance (the base's internal force carries
every external load, the contact forces included), Signorini's conditions checked on the
published backbone with distances written out in the test, and the clearance of every answer
and of the path to it checked the same way. The comparison with an independent elastica of
another formulation is in test_contact_reference.py.
"""
from conftest import REPO
import numpy as np
from obstacle_scene import CLEARANCE, scene
import pytest
import yaml

from continuum_statics import load_robot
from continuum_statics.core.description.obstacles import parse_obstacles
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.statics import contact

CONFIG_DIR = REPO / 'config'


@pytest.fixture(scope='module')
def two_section():
    return load_robot(CONFIG_DIR / 'two_section_robot.yaml')


def _distance(entry, points):
    """Distance of points to an obstacle's surface, written out (sphere, capsule, box, plane)."""
    points = np.asarray(points)
    if 'plane' in entry:
        normal = np.asarray(entry['plane']['normal'], float)
        return (points @ normal - entry['plane']['offset']) / np.linalg.norm(normal)
    centre = np.asarray(entry['position'], float)  # the test's obstacles are not rotated
    if 'sphere' in entry:
        return np.linalg.norm(points - centre, axis=1) - entry['sphere']['radius']
    if 'capsule' in entry:
        half = entry['capsule']['length'] / 2
        z = np.clip(points[:, 2] - centre[2], -half, half)
        nearest = np.column_stack([np.full(len(points), centre[0]),
                                   np.full(len(points), centre[1]), centre[2] + z])
        return np.linalg.norm(points - nearest, axis=1) - entry['capsule']['radius']
    half = np.asarray(entry['box']['size']) / 2
    excess = np.abs(points - centre) - half
    outside = np.linalg.norm(np.maximum(excess, 0.0), axis=1)
    return np.where(outside > 0, outside, np.max(excess, axis=1))


def _body_gap(robot, entries, shape, count=601):
    """Smallest gap (m) of the published backbone (sampled, linear between nodes)."""
    _, points, _ = shape.sample(count)
    return min(float(np.min(_distance(e, points))) for e in entries) - robot.body_radius


BALL = {'name': 'ball', 'sphere': {'radius': 0.02}, 'position': [0.035, 0.0, 0.2]}
PULL = np.array([3.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # p0 bends the rod towards +x


def test_an_open_gap_changes_nothing(two_section):
    far = parse_obstacles([{**BALL, 'position': [0.2, 0.0, 0.2]}])
    free = two_section.solve_tensions(PULL, obstacles=())
    shape = two_section.solve_tensions(PULL, obstacles=far)
    assert shape.contacts == ()
    np.testing.assert_array_equal(shape.positions, free.positions)
    lengths = two_section.cable_lengths(free) + 1e-3 * np.array([-3, 1, 1, 0, 0, 0])
    free = two_section.solve_lengths(lengths, obstacles=())
    solution = two_section.solve_lengths(lengths, obstacles=far)
    np.testing.assert_array_equal(solution.shape.positions, free.shape.positions)


def test_the_body_rests_on_a_sphere_with_signorini_conditions(two_section):
    obstacles = parse_obstacles([BALL])
    free = two_section.solve_tensions(PULL, obstacles=())
    assert _body_gap(two_section, [BALL], free) < -5e-3  # free, it would pass through
    shape = two_section.solve_tensions(PULL, obstacles=obstacles)
    (touch,) = shape.contacts
    assert touch.obstacle == 'ball' and touch.force > 0.0
    # gap >= 0 along the whole published backbone (linear between nodes: a chord lies a
    # hair inside the curve), = 0 where it touches
    assert _body_gap(two_section, [BALL], shape) > -2e-5
    centre_line = shape.positions[np.argmin(np.abs(shape.s - touch.s))]
    assert abs(np.linalg.norm(touch.point - np.array(BALL['position'])) - 0.02) < 1e-9
    assert np.linalg.norm(centre_line - touch.point) == pytest.approx(two_section.body_radius,
                                                                     abs=2e-3)
    # the normal points from the ball's centre to the touching point
    radial = touch.point - np.array(BALL['position'])
    np.testing.assert_allclose(touch.normal, radial / np.linalg.norm(radial), atol=1e-9)


def test_the_base_carries_every_load_the_contact_force_included(two_section):
    """n(0) = F + f L + the disks' weight + the contact forces (eq. 3 integrated).

    Slack cables (a tip force pushes the rod onto the ball): nothing else loads it.
    """
    robot = two_section
    force = np.array([0.3, 0.02, 0.0])
    shape = robot.solve_tensions(np.zeros(6), tip_force=force, obstacles=parse_obstacles([BALL]))
    (touch,) = shape.contacts
    expected = force + robot.body_force * robot.length + touch.force * touch.normal
    if robot.interval_weight is not None:
        expected += robot.interval_weight[0]
    # to the contact solve's own tolerance: the force along its normal within 1e-6 rad
    np.testing.assert_allclose(shape.n[0], expected, atol=1e-6)
    assert touch.force > 0.1


def test_a_warm_start_keeps_the_contact_and_agrees_with_a_cold_solve(two_section):
    obstacles = parse_obstacles([BALL])
    cold = two_section.solve_tensions(PULL, obstacles=obstacles)
    warm = two_section.solve_tensions(PULL * 1.01, obstacles=obstacles, warm_start=cold)
    again = two_section.solve_tensions(PULL * 1.01, obstacles=obstacles)
    np.testing.assert_allclose(warm.tip_position, again.tip_position, atol=1e-7)
    assert warm.contacts[0].force == pytest.approx(again.contacts[0].force, rel=1e-5)
    assert warm.contacts[0].force > cold.contacts[0].force  # pulled harder into it


def test_solve_lengths_finds_the_shape_resting_on_the_ball_again(two_section):
    """Tensions -> shape in contact -> its cable lengths -> solve_lengths: the same shape."""
    obstacles = parse_obstacles([BALL])
    rested = two_section.solve_tensions(PULL, obstacles=obstacles)
    lengths = two_section.cable_lengths(rested)
    solution = two_section.solve_lengths(lengths, obstacles=obstacles)
    assert [c.obstacle for c in solution.shape.contacts] == ['ball']
    np.testing.assert_allclose(solution.shape.positions, rested.positions, atol=1e-8)
    assert solution.shape.contacts[0].force == pytest.approx(rested.contacts[0].force,
                                                             rel=1e-4)


def test_estimate_shape_reports_when_the_lengths_pin_the_shape(two_section):
    """Ideal cables' lengths fix the shape: no contact force can move it, and it says so."""
    obstacles = parse_obstacles([BALL])
    lengths = two_section.cable_lengths(two_section.solve_tensions(PULL, obstacles=obstacles))
    estimate = two_section.estimate_shape(lengths, obstacles=obstacles, exact=True)
    free = two_section.estimate_shape(lengths, obstacles=(), exact=True)
    np.testing.assert_array_equal(estimate.shape.positions, free.shape.positions)
    assert 'contact not resolved' in estimate.message and "['ball']" in estimate.message


def test_robot_file_obstacles_are_validated_by_name(two_section):
    with open(CONFIG_DIR / 'two_section_robot.yaml', encoding='utf-8') as stream:
        data = yaml.safe_load(stream)
    described = parse_robot_description({**data, 'obstacles': [BALL], 'clearance': 0.004})
    assert described.obstacles[0].name == 'ball' and described.clearance == 0.004
    for bad, words in (([BALL, BALL], 'used twice'),
                       ([{'name': 'x', 'sphere': {'radius': -1.0}}], 'sizes must be'),
                       ([{'name': 'x', 'sphere': {'radius': 0.1}, 'box': {'size': [1, 1, 1]}}],
                        'exactly one'),
                       ([{'name': 'x', 'cone': {}}], 'unknown keys')):
        with pytest.raises(ValueError, match=words):
            parse_robot_description({**data, 'obstacles': bad})
    with pytest.raises(ValueError, match="obstacle 'ball' is in frame 'world'"):
        two_section.solve_tensions(PULL, obstacles=parse_obstacles(
            [{**BALL, 'frame_id': 'world'}]))


def test_distances_of_each_primitive_against_the_written_out_ones():
    rng = np.random.default_rng(3)
    points = rng.uniform(-0.3, 0.3, (400, 3))
    entries = [BALL, {'name': 'post', 'capsule': {'radius': 0.01, 'length': 0.3},
                      'position': [0.05, 0.02, 0.1]},
               {'name': 'shelf', 'box': {'size': [0.2, 0.3, 0.01]}, 'position': [0.1, 0, 0.25]},
               {'name': 'floor', 'plane': {'normal': [0, 0, 2], 'offset': -0.02}}]
    for entry, obstacle in zip(entries, parse_obstacles(entries)):
        distance, normal = obstacle.distance(points)
        np.testing.assert_allclose(distance, _distance(entry, points), atol=1e-12)
        # the normal is the distance's gradient (central differences)
        h = 1e-7
        for axis in range(3):
            step = np.zeros(3)
            step[axis] = h
            slope = (_distance(entry, points + step) - _distance(entry, points - step)) / (2 * h)
            outside = distance > 1e-4  # the box's inside distance has kinks
            np.testing.assert_allclose(normal[outside, axis], slope[outside], atol=1e-5)


@pytest.mark.parametrize('robot_file, count, reached', [('two_section_robot.yaml', 10, 0.8),
                                                        ('three_section_robot.yaml', 10, 0.8)])
def test_clearance_goals_keep_the_body_and_the_way_clear(robot_file, count, reached):
    """Random goals reachable with clearance, sent in sequence as a controller sends them.

    A goal is the tip of random tensions whose whole body clears a shelf, a post and a wall;
    every answer and every equilibrium on its way clears (or the goal is refused naming
    where). ``benchmarks/bench_obstacles.py`` runs 100 a robot.
    """
    robot = load_robot(CONFIG_DIR / robot_file)
    entries = scene(robot.length)
    obstacles = parse_obstacles(entries)
    clearance = CLEARANCE
    rng = np.random.default_rng(2)
    limits = robot.cable_length_limits
    previous, answered = None, 0
    for _ in range(count):
        while True:
            tensions = rng.uniform(0, 20, len(robot.cable_names)) * (
                rng.uniform(size=len(robot.cable_names)) < 0.4)
            shape = robot.solve_tensions(tensions, obstacles=())
            lengths = robot.cable_lengths(shape)
            if (np.all(lengths >= limits[:, 0]) and np.all(lengths <= limits[:, 1])
                    and _body_gap(robot, entries, shape) >= clearance + 1e-3):
                break
        solution = robot.solve_tip_goal(shape.tip_position, obstacles=obstacles,
                                        clearance=clearance, warm_start=previous)
        if not solution.converged:
            assert 'from obstacle' in solution.message  # refused, naming where
            continue
        answered += 1
        assert _body_gap(robot, entries, solution.shape) >= clearance - 2e-5
        begin = previous.shape if previous is not None else robot.solve_tensions(
            np.zeros(len(robot.cable_names)), obstacles=())
        for leg in (*solution.waypoints, solution):  # the way, at 64 steps a leg
            for fraction in np.linspace(0.0, 1.0, 65)[1:]:
                step = robot.equilibrium_between(begin, leg.shape, fraction)
                assert _body_gap(robot, entries, step.shape) >= min(
                    clearance, _body_gap(robot, entries, begin)) - 5e-4
            begin = leg.shape
        previous = solution
    assert answered >= reached * count


def test_a_goal_inside_the_clearance_is_refused_naming_the_obstacle(two_section):
    obstacles = parse_obstacles([{'name': 'floor', 'plane': {'normal': [0, 0, 1],
                                                             'offset': 0.29}}])
    solution = two_section.solve_tip_goal((0.02, 0.0, 0.285), obstacles=obstacles,
                                          clearance=0.002)
    assert not solution.converged
    assert "from obstacle 'floor'" in solution.message


def test_nearest_names_the_closest_obstacle(two_section):
    shape = two_section.solve_tensions(np.zeros(6), obstacles=())
    obstacles = parse_obstacles([BALL, {'name': 'far', 'sphere': {'radius': 0.01},
                                        'position': [1.0, 0, 0]}])
    gap, index, s = contact.nearest(obstacles, two_section.body_radius, shape)
    assert index == 0 and gap == pytest.approx(0.035 - 0.02 - two_section.body_radius, abs=1e-6)
    assert s == pytest.approx(0.2, abs=1e-4)
