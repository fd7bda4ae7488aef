"""Displacement-driven statics with real tendons: ``robot.solve_lengths`` against other truths.

Truths used here, none of them the code under test's own formulation:
- shapes built from known tensions (``robot.solve_tensions``) whose cable lengths are then held
  (the equilibrium is known by construction);
- the closed-form arc of one cable on a weightless single-section point-moment rod, with the
  scalar tension balance solved by ``brentq``;
- ``reference_tendons.solve_reference``: tensions as the unknowns of a bound-constrained least
  squares over ``robot.solve_tensions`` with an active set deciding the slack cables;
- for friction, the capstan law evaluated from the solved shape's own holes (wrap angles and spans
  computed here) and the hysteresis of a pull-release replay.
"""
import copy

from conftest import REPO
import numpy as np
import pytest
import reference_tendons as ref
from scipy.optimize import brentq
import yaml

from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

CONFIG = REPO / 'config'
TWO = 'two_section_robot.yaml'      # distributed
THREE = 'three_section_robot.yaml'  # point_moment
ONE = 'tendon_robot.yaml'           # one section, four cables, point_moment

#: Agreement asked of solve_lengths (m at the tip, m at every node, relative tension, N).
TIP_TOL, NODE_TOL, TENSION_RTOL, TENSION_ATOL = 1e-7, 1e-6, 1e-6, 1e-9


def robot_data(name):
    with open(CONFIG / name, encoding='utf-8') as stream:
        return yaml.safe_load(stream)


def build(data):
    return Robot(parse_robot_description(copy.deepcopy(data)))


def variant(name, tendons=None, model=None, gravity=None, section_tendons=None, cables=None):
    """Robot file ``name`` with a top-level tendons block, per-section blocks, per-cable keys.

    ``section_tendons``: {section index: block}; ``cables``: {cable name: {key: value}}.
    """
    data = robot_data(name)
    if tendons is not None:
        data['tendons'] = dict(tendons)
    if model is not None:
        data['cable_model'] = model
    if gravity is not None:
        data['gravity'] = list(gravity)
    entries = data['cables'] if 'cables' in data else [
        cable for section in data['sections'] for cable in section['cables']]
    for index, block in (section_tendons or {}).items():
        data['sections'][index]['tendons'] = dict(block)
    for entry in entries:
        entry.update((cables or {}).get(entry['name'], {}))
    return build(data)


def t_ref(robot):
    """Tension (N) that bends the rod by about a radian: E I / (L r)."""
    radius = np.mean(np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1]))
    return robot.c[0] / (robot.length * radius)


def assert_same_shape(shape, expected, tip_tol=TIP_TOL, node_tol=NODE_TOL):
    tip = np.linalg.norm(shape.tip_position - expected.tip_position)
    nodes = np.max(np.linalg.norm(shape.positions - expected.positions, axis=1))
    assert tip <= tip_tol and nodes <= node_tol, (tip, nodes)
    return max(tip, nodes)


def assert_same_tensions(tensions, expected, robot=None):
    error = np.abs(np.asarray(tensions) - expected)
    allowed = np.maximum(TENSION_RTOL * np.abs(expected), TENSION_ATOL)
    assert np.all(error <= allowed), (tensions, expected, error)
    # relative error, tensions below 1 mN counted as 1 mN
    return float(np.max(error / np.maximum(np.abs(expected), 1e-3)))


# -- 1. inextensible limit -------------------------------------------------------------------

INEXTENSIBLE = {
    # one slack cable per section (p1; d0), the others taut
    'two_section': (TWO, [3.0, 0.0, 1.5, 0.0, 2.0, 4.0]),
    'three_section': (THREE, [3.0, 0.0, 1.5, 2.0, 4.0, 0.0, 0.0, 1.0, 2.5]),
    # one section, two antagonist pairs: cable_2 and cable_3 slack
    'one_section': (ONE, [3.0, 1.0, 0.0, 0.0]),
}

EA_1E9_ONE_SECTION = (
    'BUG: solve_lengths does not converge for EA = 1e9 N on the one-section four-cable robot '
    '(cable residual 4.45e-10 m > LENGTH_TOLERANCE 1e-10 m after ~200 Newton iterations and '
    'load continuation): the co-contraction of the antagonist pair cable_1/cable_3 is only '
    'seen through a stretch of ~3e-10 m/N, and the end tensions come back [3.0, 1.99, 3e-5, '
    '0.99] N instead of [3, 1, 0, 0] N (shape within 7e-9 m)')


@pytest.mark.parametrize('case, stiffness', [
    ('two_section', None), ('two_section', 1e9),
    ('three_section', None), ('three_section', 1e9),
    ('one_section', None),
    pytest.param('one_section', 1e9, marks=pytest.mark.xfail(reason=EA_1E9_ONE_SECTION,
                                                             strict=True)),
])
def test_inextensible_limit_reproduces_the_tension_driven_shape(case, stiffness):
    name, tensions = INEXTENSIBLE[case]
    plain = variant(name)
    assert np.all(np.isinf(plain.tendons.stiffness))  # no tendons block: inextensible
    truth = plain.solve_tensions(tensions)
    lengths = plain.cable_lengths(truth)
    robot = plain if stiffness is None else variant(name, tendons={'stiffness': stiffness})
    sol = robot.solve_lengths(lengths)
    assert sol.converged, sol.message
    assert_same_shape(sol.shape, truth)
    # the tensions found are a load that holds this shape (they may differ from ``tensions``
    # where antagonists co-contract without a stretch to tell them apart)
    assert np.all(sol.end_tensions >= 0.0)
    again = robot.solve_tensions(sol.end_tensions)
    assert_same_shape(again, sol.shape, 1e-9, 1e-9)
    # the cables that pulled still pull
    assert not np.any(sol.slack[np.asarray(tensions) > 0.0])
    np.testing.assert_allclose(sol.free_lengths, ref.free_lengths(robot, lengths), atol=1e-15)


STIFF_CABLES = (
    'BUG: for very stiff (finite) cables the antagonists co-contract: the cable rows are '
    'converged to an absolute LENGTH_TOLERANCE of 1e-10 m, i.e. to EA * 1e-10 m / L of tension '
    '(0.3 N at EA = 1e9 N, 3 N at 1e10 N on a 0.3 m cable), so a pair whose co-contraction the '
    'rod cannot see (point_moment) keeps whatever tension Newton left in it; slack cables are '
    'reported taut')


@pytest.mark.parametrize('case, stiffness', [
    ('one_section', 1e5), ('one_section', 1e7), ('one_section', 1e8),
    pytest.param('one_section', 1e9, marks=pytest.mark.xfail(reason=STIFF_CABLES, strict=True)),
    pytest.param('one_section', 1e10, marks=pytest.mark.xfail(reason=STIFF_CABLES, strict=True)),
    ('three_section', 1e9),
    pytest.param('three_section', 1e10, marks=pytest.mark.xfail(reason=STIFF_CABLES,
                                                               strict=True)),
])
def test_stiff_cables_tensions_match_the_reference(case, stiffness):
    """Finite EA makes the tensions unique, however stiff: the reference resolves them."""
    name, tensions = INEXTENSIBLE[case]
    plain = variant(name)
    lengths = plain.cable_lengths(plain.solve_tensions(tensions))
    robot = variant(name, tendons={'stiffness': stiffness})
    reference = ref.solve_reference(robot, lengths)
    np.testing.assert_array_equal(reference.slack, np.asarray(tensions) == 0.0)
    sol = robot.solve_lengths(lengths)
    assert sol.converged, sol.message
    assert_same_shape(sol.shape, reference.shape)
    np.testing.assert_array_equal(sol.slack, reference.slack)
    assert_same_tensions(sol.tensions, reference.tensions, robot)


def test_straight_lengths_are_the_end_disk_arc_lengths():
    for name in (TWO, THREE, ONE, 'ftdcr_v6_robot.yaml'):
        robot = variant(name)
        np.testing.assert_allclose(robot.straight_cable_lengths, ref.straight_lengths(robot),
                                   atol=1e-12)


# -- 2. closed form: one cable, one section, no gravity, point moment -------------------------

def one_cable_robot(stiffness, pretension, zero_offset):
    """tendon_robot with cable_0 only (hole at +x, 10 mm), weightless, point_moment."""
    data = robot_data(ONE)
    data['gravity'] = [0.0, 0.0, 0.0]
    data['cable_model'] = 'point_moment'
    data['cables'] = [dict(data['cables'][0], stiffness=stiffness, pretension=pretension,
                           zero_offset=zero_offset)]
    return build(data), np.array(data['guides'], dtype=float)


def arc_solution(robot, guides, free_length, stiffness):
    """Tension (N) and curvature (1/m) of the one-cable arc, solved here by brentq.

    point_moment: the cable's pull is only the moment t (e3 x l) = t r e_y at the tip disk and no
    force, so with no gravity the rod carries a constant moment and no force (no stretch, no
    shear): a circular arc of curvature kappa = t r / (E I) about local y, bending towards the
    hole's side (+x). The holes lie on the arc of radius 1/kappa - r (inside of the bend), so the
    path through the disks (base disk at s = 0, then every guide) is the sum of the chords
    2 (1/kappa - r) sin(kappa ds / 2). A taut cable spans Lf (1 + t / EA).
    """
    radius = float(np.hypot(*robot.cable_offsets[0, :2]))
    ei = robot.c[0]
    spans = np.diff(np.concatenate([[0.0], guides]))

    def path(kappa):
        if kappa == 0.0:
            return float(np.sum(spans))
        return float(np.sum(2.0 * (1.0 / kappa - radius) * np.sin(kappa * spans / 2.0)))

    def balance(t):
        return path(t * radius / ei) - free_length * (1.0 + t / stiffness)

    if balance(0.0) <= 0.0:
        return 0.0, 0.0, path(0.0)
    t = brentq(balance, 0.0, 20.0 * t_ref(robot), xtol=1e-14, rtol=1e-15, maxiter=200)
    kappa = t * radius / ei
    return t, kappa, path(kappa)


def arc_positions(s, kappa):
    if kappa == 0.0:
        return np.stack([0.0 * s, 0.0 * s, s], axis=1)
    return np.stack([(1.0 - np.cos(kappa * s)) / kappa, 0.0 * s, np.sin(kappa * s) / kappa],
                    axis=1)


@pytest.mark.parametrize('pull, stiffness, pretension, zero_offset', [
    (0.004, 300.0, 0.0, 0.0),
    (0.002, 150.0, 2.0, 0.0005),
    (0.008, 2000.0, 0.5, -0.001),
    (0.0, 80.0, 3.0, 0.0),          # the pretension alone bends the homed rod
])
def test_single_cable_arc_matches_the_closed_form(pull, stiffness, pretension, zero_offset):
    robot, guides = one_cable_robot(stiffness, pretension, zero_offset)
    straight = guides[-1]
    lengths = robot.straight_cable_lengths - pull
    free = straight - pull + straight / (1.0 + pretension / stiffness) - straight + zero_offset
    t, kappa, path = arc_solution(robot, guides, free, stiffness)
    assert t > 0.1  # a real bend, not a near-straight rod
    sol = robot.solve_lengths(lengths)
    assert sol.converged, sol.message
    np.testing.assert_allclose(sol.free_lengths, [free], rtol=0, atol=1e-15)
    np.testing.assert_allclose(sol.tensions, [t], rtol=1e-6)
    np.testing.assert_allclose(sol.end_tensions, [t], rtol=1e-6)
    assert not sol.slack[0]
    assert sol.shape.tip_position[0] > 0.0  # towards the pulling cable's side
    expected = arc_positions(sol.shape.s, kappa)
    assert np.linalg.norm(sol.shape.tip_position - expected[-1]) <= 1e-7
    assert np.max(np.linalg.norm(sol.shape.positions - expected, axis=1)) <= 1e-7
    np.testing.assert_allclose(robot.cable_lengths(sol.shape), [path], atol=1e-9)
    np.testing.assert_allclose(sol.shape.u[:, 1], kappa, rtol=1e-6)


def test_single_cable_paid_out_is_slack_and_straight():
    robot, guides = one_cable_robot(300.0, 0.0, 0.0)
    sol = robot.solve_lengths(robot.straight_cable_lengths + 0.003)
    assert sol.converged, sol.message
    assert sol.slack[0] and sol.tensions[0] == 0.0 and sol.end_tensions[0] == 0.0
    expected = arc_positions(sol.shape.s, 0.0)
    assert np.max(np.linalg.norm(sol.shape.positions - expected, axis=1)) <= 1e-12


@pytest.mark.parametrize('model', ['point_moment', 'distributed'])
def test_homed_pretension_matches_the_closed_form(model):
    """At the homed lengths four symmetric cables keep their pretension (less the rod's give).

    No gravity, cables at 90 degrees: the rod stays straight. point_moment: the cables do not load
    the rod axially, so the paths stay at the straight length and t = P. distributed: the four
    tensions compress the rod, v3 = 1 - 4 t / (E A_rod), the paths shrink to L v3, and
    L v3 = Lf (1 + t / EA) with Lf = L / (1 + P / EA) gives t = P / (1 + 4 (EA + P) / (E A_rod)).
    """
    ea, pretension = 250.0, 3.0
    robot = variant(ONE, tendons={'stiffness': ea, 'pretension': pretension}, model=model,
                    gravity=[0.0, 0.0, 0.0])
    sol = robot.solve_lengths(robot.straight_cable_lengths)
    assert sol.converged, sol.message
    rod_ea = robot.d[2]
    expected = pretension if model == 'point_moment' else (
        pretension / (1.0 + 4.0 * (ea + pretension) / rod_ea))
    np.testing.assert_allclose(sol.tensions, expected, rtol=1e-9)
    assert not sol.slack.any()
    squeeze = 0.0 if model == 'point_moment' else 4.0 * expected / rod_ea
    straight = arc_positions(sol.shape.s, 0.0) * np.array([1.0, 1.0, 1.0 - squeeze])
    assert np.max(np.linalg.norm(sol.shape.positions - straight, axis=1)) <= 1e-12
    if model == 'distributed':
        assert expected < pretension * (1.0 - 1e-5)  # the test sees the compression


# -- 3. slack detection built by hand ---------------------------------------------------------

SLACK_CASES = {
    # robot, cable model, tendons block, known tensions, the cable paid out
    'two_section_elastic': (TWO, 'distributed', {'stiffness': 500.0, 'pretension': 0.5},
                            [3.0, 0.0, 1.5, 1.0, 2.0, 4.0], 0),
    'two_section_distal': (TWO, 'distributed', {'stiffness': 500.0},
                           [3.0, 0.0, 1.5, 1.0, 2.0, 4.0], 5),
    'three_section_point_moment': (THREE, 'point_moment', {'stiffness': 800.0},
                                   [3.0, 0.0, 1.5, 2.0, 4.0, 0.0, 0.0, 1.0, 2.5], 4),
    # inextensible: distributed, where the cables' compression of the rod fixes every tension
    # (with point_moment and EA = inf this pay-out has no equilibrium: the distal cables'
    # co-contraction grows as EA, 1 N at 1e5 N, 25 N at 1e7 N, so none is asked of it)
    'three_section_inextensible': (THREE, 'distributed', None,
                                   [3.0, 0.0, 1.5, 2.0, 4.0, 0.0, 0.0, 1.0, 2.5], 4),
}


@pytest.mark.parametrize('case', sorted(SLACK_CASES))
def test_cable_paid_out_goes_slack_and_drops_its_tension(case):
    name, model, tendons, tensions, j = SLACK_CASES[case]
    robot = variant(name, tendons=tendons, model=model)
    tensions = np.asarray(tensions)
    # the known shape B: the tensions without cable j's, the unloaded cables 1 mm slack
    without = tensions.copy()
    without[j] = 0.0
    shape_b = robot.solve_tensions(without)
    paths_b = robot.cable_lengths(shape_b)
    lengths = ref.motor_lengths(robot, without, paths_b)
    lengths[without == 0.0] += 0.001
    lengths[j] += 0.004  # cable j: paid out by 5 mm from just taut
    sol = robot.solve_lengths(lengths)
    assert sol.converged, sol.message
    assert sol.slack[j] and sol.tensions[j] <= 1e-12 and sol.end_tensions[j] <= 1e-12
    free = ref.free_lengths(robot, lengths)
    path = robot.cable_lengths(sol.shape)[j]
    assert path < free[j]
    assert abs((free[j] - path) - 0.005) <= 1e-7
    assert_same_shape(sol.shape, shape_b, 1e-7, 1e-7)
    if tendons is not None:  # finite EA: the tensions and the slack set are unique
        assert_same_tensions(sol.tensions, without, robot)
        np.testing.assert_array_equal(sol.slack, without == 0.0)

    # the same pay-out from the shape A where cable j pulls, the other motors held
    shape_a = robot.solve_tensions(tensions)
    lengths_a = ref.motor_lengths(robot, tensions, robot.cable_lengths(shape_a))
    assert robot.solve_lengths(lengths_a).slack[j] == (tensions[j] == 0.0)
    lengths_a[j] += 0.005
    paid = robot.solve_lengths(lengths_a)
    assert paid.converged, paid.message
    assert paid.slack[j] and paid.tensions[j] <= 1e-12
    assert robot.cable_lengths(paid.shape)[j] < ref.free_lengths(robot, lengths_a)[j] - 1e-3
    # what holds the shape is the other cables' tensions alone
    held = robot.solve_tensions(paid.end_tensions)
    assert_same_shape(paid.shape, held, 1e-7, 1e-7)
    reference = ref.solve_reference(robot, lengths_a)
    assert reference.slack[j]
    assert_same_shape(paid.shape, reference.shape, 1e-7, 1e-7)
    if tendons is not None:
        assert_same_tensions(paid.tensions, reference.tensions, robot)


# -- 4. the reference on 2- and 3-section robots ----------------------------------------------

MM = 1e-3
REFERENCE_CASES = {
    # robot, cable model, tendons (file, per section, per cable), motor displacements (m; < 0
    # pulls), tip force (N)
    'two_distributed': dict(
        name=TWO, model='distributed', tendons={'stiffness': 400.0, 'pretension': 2.0},
        section_tendons={1: {'stiffness': 900.0}},
        cables={'p1': {'zero_offset': 0.2 * MM}, 'd2': {'stiffness': 250.0,
                                                        'pretension': 1.0}},
        pull=[-4.0, 3.0, 1.0, -3.0, 2.0, 0.0], force=[0.05, -0.03, 0.0]),
    'two_point_moment': dict(
        name=TWO, model='point_moment', tendons={'stiffness': 400.0, 'pretension': 2.0},
        section_tendons=None, cables={'d0': {'zero_offset': -0.3 * MM}},
        pull=[-3.0, 4.0, -1.0, 1.0, 5.0, -4.0], force=[0.0, 0.04, -0.02]),
    'three_point_moment': dict(
        name=THREE, model='point_moment', tendons={'stiffness': 600.0, 'pretension': 1.5},
        section_tendons={2: {'stiffness': 300.0, 'pretension': 0.5}},
        cables={'b1': {'zero_offset': 0.5 * MM}},
        pull=[-3.0, 2.0, 0.5, 1.0, -2.5, 3.0, -2.0, 4.0, 0.0], force=[0.03, 0.0, 0.02]),
    'three_distributed': dict(
        name=THREE, model='distributed', tendons={'stiffness': 600.0, 'pretension': 1.5},
        section_tendons=None, cables={'a2': {'stiffness': 200.0}, 'c0': {'pretension': 3.0}},
        pull=[-2.0, 1.5, 2.0, -2.5, 2.0, 0.5, 3.0, -3.0, -1.0], force=[-0.02, 0.03, 0.0]),
}

#: Largest disagreement with the reference seen by the tests (filled as they run; printed -s).
LARGEST = {}


def _record(key, value):
    LARGEST[key] = max(LARGEST.get(key, 0.0), float(value))


@pytest.mark.parametrize('case', sorted(REFERENCE_CASES))
def test_solve_lengths_matches_the_reference(case):
    spec = REFERENCE_CASES[case]
    robot = variant(spec['name'], tendons=spec['tendons'], model=spec['model'],
                    section_tendons=spec['section_tendons'], cables=spec['cables'])
    lengths = robot.straight_cable_lengths + np.asarray(spec['pull']) * MM
    force = np.asarray(spec['force'])
    reference = ref.solve_reference(robot, lengths, tip_force=force)
    # the case exercises what it is meant to: slack and taut cables, every section loaded
    assert reference.slack.any() and (~reference.slack).any()
    for section in robot.sections:
        assert (~reference.slack[list(section.cable_indices)]).any()
    sol = robot.solve_lengths(lengths, tip_force=force)
    assert sol.converged, sol.message
    np.testing.assert_allclose(sol.free_lengths, reference.free_lengths, rtol=0, atol=1e-15)
    shape_error = assert_same_shape(sol.shape, reference.shape, 1e-6, 1e-6)
    tension_error = assert_same_tensions(sol.tensions, reference.tensions, robot)
    np.testing.assert_array_equal(sol.tensions, sol.end_tensions)  # frictionless
    np.testing.assert_array_equal(sol.slack, reference.slack)
    _record('reference cases: shape (m)', shape_error)
    _record('reference cases: tension (relative)', tension_error)
    # a warm start from a neighbouring solution lands on the same equilibrium
    near = robot.solve_lengths(lengths + 0.5 * MM, tip_force=force)
    warm = robot.solve_lengths(lengths, tip_force=force, warm_start=near)
    assert warm.converged, warm.message
    assert_same_shape(warm.shape, reference.shape, 1e-6, 1e-6)
    assert_same_tensions(warm.tensions, reference.tensions, robot)


# -- 5. friction: hysteresis of a pull-release replay ------------------------------------------

def capstan_profile(robot, shape, cable):
    """Spans (m) between the cable's holes and the wrap angle (rad) at each hole but the last.

    Computed from the shape's nodes at the base disk and every guide up to the cable's end disk;
    the cable reaches the base disk along the base axis (from its motor).
    """
    end = next(section.end for section in robot.sections if cable in section.cable_indices)
    stations = np.concatenate([[0.0], robot.guides[robot.guides <= end + 1e-12]])
    nodes = [int(np.argmin(np.abs(shape.s - s))) for s in stations]
    holes = shape.positions[nodes] + shape.rotations[nodes] @ robot.cable_offsets[cable]
    chords = np.diff(holes, axis=0)
    spans = np.linalg.norm(chords, axis=1)
    tangents = np.vstack([shape.rotations[0][:, 2], chords / spans[:, None]])
    wraps = np.arccos(np.clip(np.sum(tangents[:-1] * tangents[1:], axis=1), -1.0, 1.0))
    return spans, wraps


def check_capstan(robot, sol, cable, mu, sign):
    """Motor tension = end tension exp(sign mu total wrap); the cable's free length is used up."""
    spans, wraps = capstan_profile(robot, sol.shape, cable)
    t_end = sol.end_tensions[cable]
    np.testing.assert_allclose(sol.tensions[cable], t_end * np.exp(sign * mu * np.sum(wraps)),
                               rtol=1e-9)
    # span i carries the end tension grown by the wraps between it and the end disk
    beyond = np.array([np.sum(wraps[i + 1:]) for i in range(len(spans))])
    carried = t_end * np.exp(sign * mu * beyond)
    unstretched = np.sum(spans / (1.0 + carried / robot.tendons.stiffness[cable]))
    assert abs(unstretched - sol.free_lengths[cable]) <= 1e-9
    # the point-moment rod sees only the end tensions
    assert_same_shape(sol.shape, robot.solve_tensions(sol.end_tensions), 1e-8, 1e-8)


FRICTIONS = (0.0, 0.05, 0.1, 0.2)
PULL = np.round(np.arange(0, 11) * MM, 12)      # 0 .. 10 mm
RELEASE = np.round(np.arange(9, 3, -1) * MM, 12)  # back to 4 mm
SAME = 4 * MM


def replay(mu):
    robot = variant(ONE, tendons={'stiffness': 300.0, 'friction': mu})
    straight = robot.straight_cable_lengths
    results, previous = [], None
    for pull in np.concatenate([PULL, RELEASE]):
        # cable_0 pulled; the others paid out 5 mm, slack
        lengths = straight + np.array([-pull, 5 * MM, 5 * MM, 5 * MM])
        previous = robot.solve_lengths(lengths, warm_start=previous)
        assert previous.converged, previous.message
        results.append(previous)
    pulled = results[int(np.flatnonzero(np.isclose(PULL, SAME))[0])]
    released = results[-1]
    return robot, results, pulled, released


@pytest.fixture(scope='module')
def replays():
    return {mu: replay(mu) for mu in FRICTIONS}


def test_friction_hysteresis_grows_with_mu(replays):
    gaps = {}
    for mu in FRICTIONS:
        _, _, pulled, released = replays[mu]
        np.testing.assert_array_equal(pulled.free_lengths, released.free_lengths)
        gaps[mu] = np.linalg.norm(pulled.shape.tip_position - released.shape.tip_position)
        nodes = np.max(np.linalg.norm(pulled.shape.positions - released.shape.positions, axis=1))
        if mu == 0.0:
            assert gaps[mu] < 1e-9 and nodes < 1e-9, (gaps[mu], nodes)
        else:
            # pulling stretches the cable more (tension rises towards the motor), so at the same
            # motor position the rod bends less on the way in than on the way back
            assert pulled.end_tensions[0] < released.end_tensions[0]
            assert (np.linalg.norm(pulled.shape.tip_position[:2])
                    < np.linalg.norm(released.shape.tip_position[:2]))
    _record('friction gap mu=0 (m)', gaps[0.0])
    for mu in FRICTIONS[1:]:
        _record('friction gap mu=%g (m)' % mu, gaps[mu])
    values = [gaps[mu] for mu in FRICTIONS]
    assert values[1] > 1e-5, gaps
    assert all(b > 1.5 * a for a, b in zip(values[1:], values[2:])), gaps


def test_friction_motor_tension_above_end_tension_while_pulling_below_while_releasing(replays):
    for mu in FRICTIONS:
        robot, results, _, _ = replays[mu]
        for k, sol in enumerate(results):
            if k == 0:  # the straight start, cold: no motion known, no tension
                assert sol.motion[0] == 0.0 and sol.tensions[0] == sol.end_tensions[0]
                continue
            pulling = k < len(PULL)
            assert sol.motion[0] == (1.0 if pulling else -1.0)
            assert not sol.slack[0] and np.all(sol.slack[1:])
            if mu == 0.0:
                assert sol.tensions[0] == sol.end_tensions[0]
            elif pulling:
                assert sol.tensions[0] > sol.end_tensions[0]
            else:
                assert sol.tensions[0] < sol.end_tensions[0]
            check_capstan(robot, sol, 0, mu, 1.0 if pulling else -1.0)


def test_friction_keeps_the_last_direction_while_the_motor_stands(replays):
    robot, results, _, released = replays[0.2]
    lengths = robot.straight_cable_lengths + np.array([-SAME, 5 * MM, 5 * MM, 5 * MM])
    again = robot.solve_lengths(lengths, warm_start=released)
    assert again.converged and again.motion[0] == -1.0
    assert_same_shape(again.shape, released.shape, 1e-12, 1e-12)
    # a cold start knows no direction: frictionless, between the two branches
    cold = robot.solve_lengths(lengths)
    _, _, pulled, _ = replays[0.2]
    frictionless = replays[0.0][3]
    assert cold.motion[0] == 0.0
    assert_same_shape(cold.shape, frictionless.shape, 1e-9, 1e-9)
    assert pulled.end_tensions[0] < cold.end_tensions[0] < released.end_tensions[0]


def test_friction_on_the_distributed_model():
    """Two sections, distributed: the rod takes the end tension along the whole cable."""
    mu = 0.15
    robot = variant(TWO, tendons={'stiffness': 400.0, 'friction': mu})
    straight = robot.straight_cable_lengths
    previous = None
    for pull in (1 * MM, 2 * MM, 3 * MM, 2 * MM):
        # p0 and d1 pulled, the others paid out 4 mm
        lengths = straight + np.array([-pull, 4 * MM, 4 * MM, 4 * MM, -pull, 4 * MM])
        previous = robot.solve_lengths(lengths, warm_start=previous)
        assert previous.converged, previous.message
    sol = previous
    for cable in (0, 4):
        assert sol.motion[cable] == -1.0 and not sol.slack[cable]
        spans, wraps = capstan_profile(robot, sol.shape, cable)
        t_end = sol.end_tensions[cable]
        np.testing.assert_allclose(sol.tensions[cable], t_end * np.exp(-mu * np.sum(wraps)),
                                   rtol=1e-9)
        beyond = np.array([np.sum(wraps[i + 1:]) for i in range(len(spans))])
        carried = t_end * np.exp(-mu * beyond)
        assert abs(np.sum(spans / (1.0 + carried / 400.0)) - sol.free_lengths[cable]) <= 1e-9
    assert_same_shape(sol.shape, robot.solve_tensions(sol.end_tensions), 1e-8, 1e-8)


def test_frictionless_replay_matches_the_reference(replays):
    robot, results, _, released = replays[0.0]
    lengths = robot.straight_cable_lengths + np.array([-SAME, 5 * MM, 5 * MM, 5 * MM])
    reference = ref.solve_reference(robot, lengths)
    assert_same_shape(released.shape, reference.shape, 1e-7, 1e-7)
    assert_same_tensions(released.tensions, reference.tensions, robot)


def test_tension_above_its_limit_is_reported():
    lengths_pull = np.array([-4 * MM, 5 * MM, 5 * MM, 5 * MM])
    free = variant(ONE, tendons={'stiffness': 300.0})
    tension = free.solve_lengths(free.straight_cable_lengths + lengths_pull).tensions[0]
    for limit, reported in ((0.99 * tension, True), (1.01 * tension, False)):
        robot = variant(ONE, tendons={'stiffness': 300.0},
                        cables={'cable_0': {'tension_limits': [0.0, float(limit)]}})
        sol = robot.solve_lengths(robot.straight_cable_lengths + lengths_pull)
        assert sol.converged  # a limit is reported, the equilibrium is still the answer
        assert sol.tensions[0] == pytest.approx(tension, rel=1e-9)
        assert (('tension_limits' in sol.message and 'cable_0' in sol.message)
                == reported), sol.message
        assert 'cable_1' not in sol.message


# -- 6. cold starts on random reachable cases -------------------------------------------------

def random_case(rng, name, model):
    """Return a robot with random per-cable tendons, and lengths and tip force of a known shape."""
    n = len(robot_data_cables(name))
    stiffness = np.exp(rng.uniform(np.log(200.0), np.log(5000.0), n))
    pretension = rng.uniform(0.0, 2.0, n)
    names = robot_data_cables(name)
    robot = variant(name, model=model, cables={
        cable: {'stiffness': float(ea), 'pretension': float(p)}
        for cable, ea, p in zip(names, stiffness, pretension)})
    scale = t_ref(robot)
    while True:
        tensions = rng.uniform(0.0, 3.0 * scale, n) / len(robot.sections)
        slack = rng.random(n) < 0.35
        tensions[slack] = 0.0
        if slack.all():
            continue
        force = rng.normal(0.0, 0.03, 3)
        try:
            truth = robot.solve_tensions(tensions, tip_force=force)
        except RuntimeError:
            continue
        break
    lengths = ref.motor_lengths(robot, tensions, robot.cable_lengths(truth))
    lengths[slack] += rng.uniform(0.5, 5.0, np.sum(slack)) * MM
    return robot, lengths, force, tensions, truth


def robot_data_cables(name):
    data = robot_data(name)
    entries = data['cables'] if 'cables' in data else [
        cable for section in data['sections'] for cable in section['cables']]
    return [cable['name'] for cable in entries]


@pytest.mark.parametrize('name, seed', [(TWO, 2024), (THREE, 7)])
def test_cold_start_random_cases_converge_and_match(name, seed):
    rng = np.random.default_rng(seed)
    for k in range(10):
        model = ('distributed', 'point_moment')[k % 2]
        robot, lengths, force, tensions, truth = random_case(rng, name, model)
        sol = robot.solve_lengths(lengths, tip_force=force)
        assert sol.converged, (k, sol.message)
        # the known equilibrium the lengths were built from
        _record('random cases vs truth: shape (m)', assert_same_shape(sol.shape, truth, 1e-6,
                                                                     1e-6))
        _record('random cases vs truth: tension (relative)',
                assert_same_tensions(sol.tensions, tensions, robot))
        np.testing.assert_array_equal(sol.slack, tensions == 0.0)
        # and the reference from its own cold start
        reference = ref.solve_reference(robot, lengths, tip_force=force)
        _record('random cases vs reference: shape (m)',
                assert_same_shape(sol.shape, reference.shape, 1e-6, 1e-6))
        _record('random cases vs reference: tension (relative)',
                assert_same_tensions(sol.tensions, reference.tensions, robot))


# -- 7. bad input ------------------------------------------------------------------------------

@pytest.mark.parametrize('lengths, word', [
    ([np.nan, 0.15, 0.15, 0.3, 0.3, 0.3], 'lengths'),
    ([0.15, 0.15, 0.15, 0.3, 0.3], 'lengths'),
    ([0.15, 0.15, 0.15, 0.3, 0.3, 0.3, 0.3], 'lengths'),
    ([0.15, 0.15, 0.15, 0.3, np.inf, 0.3], 'lengths'),
    ('long', 'lengths'),
    ([-0.2, 0.15, 0.15, 0.3, 0.3, 0.3], 'lengths'),  # a non-positive free length
])
def test_bad_lengths_raise_value_error_naming_the_argument(lengths, word):
    robot = variant(TWO, tendons={'stiffness': 400.0})
    with pytest.raises(ValueError, match=word):
        robot.solve_lengths(lengths)


def test_bad_tip_load_raises_value_error_naming_the_argument():
    robot = variant(TWO)
    lengths = robot.straight_cable_lengths
    with pytest.raises(ValueError, match='tip_force'):
        robot.solve_lengths(lengths, tip_force=[0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match='tip_moment'):
        robot.solve_lengths(lengths, tip_moment=[0.0, 0.0])


def test_report_largest_disagreements():
    """Print what the tests above measured (run with -s to see it)."""
    for key in sorted(LARGEST):
        print('%s: %.3g' % (key, LARGEST[key]))
