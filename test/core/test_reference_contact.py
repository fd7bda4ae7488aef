"""The contact reference (``reference_contact.py``) against analytic truths, so it can be trusted.

Truths, written here independently of the reference's energy formulation:

- Euler-Bernoulli cantilever: tip load F at L deflects the tip F L^3 / (3 EI); a point load P at
  a deflects it P a^2 (3 L - a) / (6 EI); a uniform weight w, w L^4 / (8 EI).
- Large-deflection elastica, tip load P perpendicular to the clamp (Bisshopp & Drucker 1945),
  derived: EI psi'' + P cos psi = 0, psi(0) = 0, psi'(L) = 0 has the first integral
  psi'^2 = 2 P / EI (sin psi_L - sin psi); with 1 + sin psi = 2 k^2 sin^2 phi,
  k^2 = (1 + sin psi_L) / 2, ds = sqrt(EI / P) dphi / sqrt(1 - k^2 sin^2 phi), so
  sqrt(P L^2 / EI) = K(k) - F(phi_1, k) with sin phi_1 = 1 / (k sqrt 2); the tip deflection along
  P is L - 2 sqrt(EI / P) (E(k) - E(phi_1, k)), along the clamp sqrt(EI / P) sqrt(2 (2 k^2 - 1)).
- Planar elastica with weight, by ``solve_bvp``: theta from +z towards +x, EI theta' = m,
  m' = -(n_x cos theta - n_z sin theta) with n(s) = F_tip + w (L - s) the load beyond s.
- Propped cantilever (superposition, small deflections): clamp at 0, frictionless point support
  at a, load P at the tip L > a. The support must undo the tip load's deflection at a,
  P a^2 (3 L - a) / (6 EI), with its own R a^3 / (3 EI):  R = P (3 L - a) / (2 a).
- Tip pushed by P against a wall a gap g beyond its straight position: the rod's tip force is
  3 EI g / L^3 at that deflection, so the wall takes R = P - 3 EI g / L^3 (P > 3 EI g / L^3).
- A straight rod lying on a table under its own weight: no bending, so every node's weight goes
  straight into the table: R = rho A g (L - h / 2) (the base carries its half link).
"""
import functools

import numpy as np
import pytest
import reference_contact as ref
from scipy.integrate import solve_bvp
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation
from scipy.special import ellipe, ellipeinc, ellipk, ellipkinc

NO_GRAVITY = np.zeros(3)
TIP_TOLERANCE = 1e-4  # m, 0.1 mm at L = 0.3 m
EXTRAPOLATED_TOLERANCE = 1e-6  # m, Richardson from two refinements


def weightless(**fields):
    """Return the default Nitinol rod (L 0.3 m, d 2 mm) without gravity."""
    return ref.Rod.nitinol(gravity=NO_GRAVITY, **fields)


def elastica_tip(P, L, EI):
    """Return (deflection along P, position along the clamp) m for a perpendicular tip load."""
    alpha = np.sqrt(P * L ** 2 / EI)

    def phi1(m):
        return np.arcsin(1.0 / np.sqrt(2.0 * m))

    m = brentq(lambda m: ellipk(m) - ellipkinc(phi1(m), m) - alpha, 0.5 + 1e-15, 1.0 - 1e-15,
               xtol=1e-15)
    scale = np.sqrt(EI / P)
    return (L - 2.0 * scale * (ellipe(m) - ellipeinc(phi1(m), m)),
            scale * np.sqrt(2.0 * (2.0 * m - 1.0)))


def bvp_tip(rod):
    """Return the planar elastica tip (3,) m with weight and tip force, by ``solve_bvp``."""
    L, EI = rod.length, rod.EI
    w, F = rod.mass_per_length * rod.gravity, rod.tip_force
    theta0 = np.arctan2(rod.base_direction[0], rod.base_direction[2])

    def rhs(s, y):
        theta, m = y[0], y[1]
        nx, nz = F[0] + w[0] * (L - s), F[2] + w[2] * (L - s)
        return np.vstack([m / EI, -(nx * np.cos(theta) - nz * np.sin(theta)),
                          np.sin(theta), np.cos(theta)])

    def boundary(ya, yb):
        return np.array([ya[0] - theta0, yb[1], ya[2], ya[3]])

    s = np.linspace(0.0, L, 401)
    guess = np.vstack([np.full_like(s, theta0), 0.0 * s, s * np.sin(theta0), s * np.cos(theta0)])
    solution = solve_bvp(rhs, boundary, s, guess, tol=1e-10, max_nodes=100000)
    assert solution.status == 0, solution.message
    return rod.base + np.array([solution.y[2, -1], 0.0, solution.y[3, -1]])


def richardson(solve, quantity, ns):
    return ref.refinement_study(solve, ns=ns, quantity=quantity)['richardson']


# ---------------------------------------------------------------- no obstacle

def test_small_tip_load_matches_euler_bernoulli():
    F = 0.01  # N: tip deflection 2 mm, nonlinear terms ~1e-4 of it
    rod = weightless(tip_force=[F, 0.0, 0.0])
    expected = F * rod.length ** 3 / (3.0 * rod.EI)
    assert ref.solve_planar(rod, n=100).tip[0] == pytest.approx(expected, rel=0.01)
    # 3-D, the force at 30 degrees about z: the tip moves along it
    direction = np.array([np.cos(np.pi / 6.0), np.sin(np.pi / 6.0), 0.0])
    tip = ref.solve_3d(weightless(tip_force=F * direction), n=40).tip
    assert tip[:2] @ direction[:2] == pytest.approx(expected, rel=0.01)
    assert abs(tip[0] * direction[1] - tip[1] * direction[0]) < 1e-9


@pytest.mark.parametrize('load', ['disk', 'weight'])
def test_disk_and_weight_match_euler_bernoulli(load):
    """Horizontal cantilever (+x, gravity -z): a 1 g disk at 0.2 m, or the rod's own weight."""
    L, a, mass = 0.3, 0.2, 1e-3
    if load == 'disk':
        rod = ref.Rod.nitinol(base_direction=[1.0, 0.0, 0.0], mass_per_length=0.0,
                              disks=((a, mass),))
        expected = mass * 9.81 * a ** 2 * (3.0 * L - a) / (6.0 * rod.EI)
    else:
        rod = ref.Rod.nitinol(base_direction=[1.0, 0.0, 0.0])
        expected = rod.mass_per_length * 9.81 * L ** 4 / (8.0 * rod.EI)
    assert -ref.solve_planar(rod, n=100).tip[2] == pytest.approx(expected, rel=0.01)
    assert -ref.solve_3d(rod, n=40).tip[2] == pytest.approx(expected, rel=0.01)


def test_large_tip_load_matches_elliptic_integrals():
    P = 1.0  # N: P L^2 / EI ~ 2, the tip swings ~30 degrees
    rod = weightless(tip_force=[P, 0.0, 0.0])
    deflection, along = elastica_tip(P, rod.length, rod.EI)
    exact = np.array([deflection, 0.0, along])
    assert np.linalg.norm(ref.solve_planar(rod, n=200).tip - exact) < TIP_TOLERANCE
    extrapolated = richardson(functools.partial(ref.solve_planar, rod), lambda s: s.tip,
                              (100, 200))
    assert np.linalg.norm(extrapolated - exact) < EXTRAPOLATED_TOLERANCE
    # 3-D, bending in a plane turned 30 degrees about the clamp axis z
    turn = Rotation.from_euler('z', 30.0, degrees=True).as_matrix()
    tip = ref.solve_3d(weightless(tip_force=turn @ [P, 0.0, 0.0]), n=60).tip
    assert np.linalg.norm(tip - turn @ exact) < TIP_TOLERANCE


@pytest.mark.parametrize('case', ['upright', 'horizontal'])
def test_large_loads_with_weight_match_boundary_value_problem(case):
    if case == 'upright':  # standing up along +z, pushed sideways and down
        rod = ref.Rod.nitinol(tip_force=[0.5, 0.0, -0.2])
    else:  # along +x under gravity, pulled down at the tip: ~20 degrees of droop
        rod = ref.Rod.nitinol(base_direction=[1.0, 0.0, 0.0], tip_force=[0.0, 0.0, -0.5])
    exact = bvp_tip(rod)
    assert np.linalg.norm(ref.solve_planar(rod, n=200).tip - exact) < TIP_TOLERANCE
    extrapolated = richardson(functools.partial(ref.solve_planar, rod), lambda s: s.tip,
                              (100, 200))
    assert np.linalg.norm(extrapolated - exact) < EXTRAPOLATED_TOLERANCE


# ---------------------------------------------------------------- contact

def propped(a, P=0.01, support='cylinder'):
    """Return (rod, [support]): cantilever along +x, tip load -P z, support touching at s = a."""
    rod = weightless(base_direction=[1.0, 0.0, 0.0], tip_force=[0.0, 0.0, -P])
    radius = 1e-3  # the support's; it touches the straight rod's underside at x = a
    centre = [a, 0.0, -rod.body_radius - radius]
    if support == 'cylinder':
        return rod, [ref.Cylinder('support', centre, [0.0, 1.0, 0.0], radius)]
    return rod, [ref.Sphere('support', centre, radius)]


@pytest.mark.parametrize('a', [0.1, 0.2])
def test_propped_cantilever_reaction(a):
    P, L = 0.01, 0.3
    expected = P * (3.0 * L - a) / (2.0 * a)
    for solution in (ref.solve_planar(*propped(a), n=100),
                     ref.solve_3d(*propped(a, support='sphere'), n=40)):
        contact = solution.contacts['support']
        assert contact.magnitude == pytest.approx(expected, rel=0.02)
        assert contact.force[2] > 0.99 * contact.magnitude  # pushes the rod up
        assert contact.s == pytest.approx(a, abs=1e-4)
        assert solution.min_gap > -1e-9


def test_tip_pushed_against_wall():
    P, gap = 0.02, 2e-3  # N, m: the wall takes about half of P
    rod = weightless(tip_force=[P, 0.0, 0.0])
    wall = ref.Plane('wall', [-1.0, 0.0, 0.0], -(gap + rod.body_radius))
    expected = P - 3.0 * rod.EI * gap / rod.length ** 3
    for solution in (ref.solve_planar(rod, [wall], n=100), ref.solve_3d(rod, [wall], n=40)):
        contact = solution.contacts['wall']
        assert contact.magnitude == pytest.approx(expected, rel=0.02)
        assert contact.force @ wall.normal == pytest.approx(contact.magnitude)
        assert contact.s == pytest.approx(rod.length)
        assert solution.tip[0] == pytest.approx(gap, abs=1e-9)


def test_rod_lying_on_table_rests_its_weight_on_it():
    """Line contact: every node active; the multipliers must be the node weights."""
    rod = ref.Rod.nitinol(base_direction=[1.0, 0.0, 0.0])
    table = ref.Plane('table', [0.0, 0.0, 1.0], -rod.body_radius)
    for solution, n in ((ref.solve_planar(rod, [table], n=50), 50),
                        (ref.solve_3d(rod, [table], n=20), 20)):
        h = rod.length / n
        contact = solution.contacts['table']
        weight = rod.mass_per_length * 9.81 * (rod.length - h / 2)
        assert contact.magnitude == pytest.approx(weight)
        assert len(contact.s_each) == n
        assert np.allclose(solution.positions[:, 2], 0.0, atol=1e-12)
        assert solution.kkt_residual < 1e-9


def post_case(turn_degrees=0.0):
    """Return (rod, [post]): a hard contact, in a vertical plane turned about z.

    The upright rod with two 5 g disks is pushed by 1 N at the tip onto a 10 mm post at
    mid-height: 2.3 N of contact, the rod bending around the post.
    """
    turn = Rotation.from_euler('z', turn_degrees, degrees=True).as_matrix()
    rod = ref.Rod.nitinol(tip_force=turn @ [1.0, 0.0, 0.0], disks=((0.1, 0.005), (0.2, 0.005)))
    return rod, [ref.Cylinder('post', turn @ [0.02, 0.0, 0.12], turn @ [0.0, 1.0, 0.0], 0.01)]


def tip_force_and_s(turn):
    """Return the quantity compared: tip (in the unturned frame), contact force and place."""
    def quantity(solution):
        contact = solution.contacts['post']
        return np.concatenate([turn.T @ solution.tip, [contact.magnitude, contact.s]])
    return quantity


def test_three_d_matches_planar_in_turned_plane_with_contact():
    """Two discretisations (link angles vs nodes with DER bending) extrapolate to one answer."""
    turn = Rotation.from_euler('z', 30.0, degrees=True).as_matrix()
    planar = richardson(functools.partial(ref.solve_planar, *post_case()),
                        tip_force_and_s(np.eye(3)), (50, 100))
    spatial = richardson(functools.partial(ref.solve_3d, *post_case(30.0)),
                         tip_force_and_s(turn), (25, 50))
    assert np.linalg.norm(spatial[:3] - planar[:3]) < 2e-6
    assert spatial[3] == pytest.approx(planar[3], rel=1e-4)
    assert spatial[4] == pytest.approx(planar[4], abs=1e-5)


@pytest.mark.parametrize('case', ['propped', 'post'])
def test_planar_convergence_is_second_order(case):
    """Successive differences of tip and contact force shrink 4x per doubling of n."""
    problem = propped(0.15) if case == 'propped' else post_case()
    name = 'support' if case == 'propped' else 'post'
    study = ref.refinement_study(
        functools.partial(ref.solve_planar, *problem), ns=(50, 100, 200, 400),
        quantity=lambda s: np.concatenate([s.tip, [s.contacts[name].magnitude]]))
    differences = np.abs(study['differences'])
    tip_ratios = np.linalg.norm(differences[:-1, :3], axis=1) / np.linalg.norm(
        differences[1:, :3], axis=1)
    force_ratios = differences[:-1, 3] / differences[1:, 3]
    assert np.all((tip_ratios > 3.5) & (tip_ratios < 4.5)), tip_ratios
    assert np.all((force_ratios > 3.5) & (force_ratios < 4.5)), force_ratios


# ---------------------------------------------------------------- obstacle geometry

OBSTACLES = [
    ref.Plane('plane', [0.3, -0.2, 1.0], 0.01),
    ref.Sphere('sphere', [0.01, 0.02, 0.1], 0.02),
    ref.Cylinder('cylinder', [0.0, 0.03, 0.0], [0.2, 0.1, 1.0], 0.01),
    ref.Capsule('capsule', [0.0, 0.0, 0.05], [0.02, 0.01, 0.09], 0.008),
    ref.Box('box', [0.01, -0.01, 0.1], Rotation.from_euler('xyz', [10, 20, 30],
                                                           degrees=True).as_matrix(),
            [0.01, 0.02, 0.015]),
]


@pytest.mark.parametrize('obstacle', OBSTACLES, ids=lambda o: o.name)
def test_obstacle_normal_is_distance_gradient_and_curves_find_their_minimum(obstacle):
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.05, 0.15, (200, 3)) * [1.0, 1.0, 1.5]
    d, normal = obstacle.distance(points)
    points, normal = points[d > 1e-3], normal[d > 1e-3]  # the box is C1 outside only
    step = 1e-7
    numeric = np.stack([(obstacle.distance(points + step * e)[0]
                         - obstacle.distance(points - step * e)[0]) / (2 * step)
                        for e in np.eye(3)], axis=1)
    assert np.allclose(numeric, normal, atol=1e-6)
    # curved links (a sagitta of 1 mm on 10 mm), against dense sampling
    start = points[:50]
    chord = rng.normal(size=(50, 3)) * 0.01
    bulge = np.cross(chord, rng.normal(size=(50, 3))) * 0.4
    found, _, t = obstacle.curve_distance(start, chord, bulge)
    samples = np.linspace(0.0, 1.0, 2001)[:, None, None]
    curve = start + samples * chord + samples * (1.0 - samples) * bulge
    sampled = np.min([obstacle.distance(c)[0] for c in curve], axis=0)
    assert np.all(found <= sampled + 1e-12)
    assert np.all(found >= sampled - 1e-8)  # a sample lies within 2.5e-4 of the true t


def test_planar_refuses_out_of_plane_loads():
    with pytest.raises(ValueError):
        ref.solve_planar(weightless(tip_force=[0.0, 0.1, 0.0]), n=10)
