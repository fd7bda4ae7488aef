"""Slow, independent reference for an elastic rod resting on rigid frictionless obstacles (SciPy).

Written without the package's core, in a different formulation from a shooting solver: the
discretised elastica found by ENERGY MINIMISATION (``scipy.optimize.minimize``, SLSQP, analytic
gradients) with non-penetration as inequality constraints; the contact forces are the KKT
multipliers, recovered at the optimum by nonnegative least squares.

Rod: inextensible, unshearable, isotropic bending stiffness EI, no twist. That is exact for an
isotropic rod without torsional load: frictionless normal contact forces, weights and a tip
force all act on the centerline and put no twist in it. Clamped at ``base`` along
``base_direction``; loaded by its weight (``mass_per_length`` times ``gravity``), a tip force
fixed in space and point masses (disks) at given arc lengths.

Discretisation (both versions): n links of length h = L / n, nodes r_0 (the base) .. r_n (the
tip) at s_k = k h.

- Bending: the turning angle phi_k between links k and k+1 at interior node k costs
  EI / (2 h) phi_k^2 (the midpoint rule for int EI / 2 kappa^2 ds over [s_k - h/2, s_k + h/2]).
  The clamp turns from the base direction (at s = 0) to link 1 (whose midpoint is at h / 2): a
  half step, so EI / h phi_0^2. Together a midpoint rule over [0, L - h/2]; kappa = 0 at the free
  tip makes the last half link O(h^3): second order overall. (EI / (2 h) phi_0^2 would put the
  clamp half a link before the base: first order only.)
- Loads lumped on the nodes, potential -sum_k f_k . r_k: the weight by the trapezoid rule (h at
  interior nodes, h / 2 at the tip; the same as each link's weight at its midpoint, which for a
  straight link is the mean of its ends), a disk between two nodes by linear interpolation, the
  tip force on r_n. Second order.
- Non-penetration, for every obstacle and every LINK k: the smallest signed distance from the
  link's contact curve p_k(t) = r_(k-1) + t e_k - t (1 - t) h^2 / 2 c_k, t in [0, 1], to the
  obstacle is >= ``body_radius``. e_k is the link vector and c_k the curvature vector r'' from a
  centred difference of the neighbouring link directions (one-sided at the ends): the quadratic
  that the smooth rod follows between the two nodes. (On the bare polygon, the chord of a link
  curving around an obstacle sits h^2 kappa / 8 inside the rod: an O(h^2) gap error that
  oscillates with where the contact falls within its link, so successive refinements did not
  converge smoothly; the quadratic leaves O(h^3).) The minimum over t is a golden-section search
  plus both ends (the signed distance to a convex obstacle is convex, so unimodal along a
  nearly straight link). Smooth enough for SLSQP wherever the closest point is unique.
- Contact forces: at the optimum, grad E = sum lambda_i grad g_i over the active gaps g_i
  (metres), lambda_i >= 0, by ``scipy.optimize.nnls`` (equality constraints, 3-D only, projected
  out first). With E in joules and g in metres, lambda_i is the contact force (N) on the rod at
  p_k(t*), along the obstacle's outward normal there.

Planar (``solve_planar``): the rod in the x-z plane through the base; unknowns the n link angles
theta_i from +z towards +x, written as scaled turning angles u_k = phi_k sqrt(c_k L / h) (c = 2 at
the clamp, 1 elsewhere), so that the bending energy is (EI / L) |u|^2 / 2: the identity Hessian
SLSQP's BFGS starts from is then the exact bending Hessian, and the iteration count does not
grow with n. Loads out of the plane are refused; contact normals out of the plane are carried
by the plane (ignored): use obstacles symmetric about it.

3-D (``solve_3d``): unknowns the node positions r_1 .. r_n (r_0 fixed) with n equality
constraints |r_k - r_(k-1)|^2 = h^2. The clamp enters only through the bending energy of the
turn from ``base_direction`` to link 1 (no other node fixed, no penalty). Bending as in discrete
elastic rods (Bergou et al., SIGGRAPH 2008): curvature binormal
kb_k = 2 e_(k-1) x e_k / (|e_(k-1)| |e_k| + e_(k-1) . e_k), |kb| = 2 tan(phi / 2), energy
EI |kb_k|^2 / l_k with the rest Voronoi length l_k = 2 h (h at the clamp, as above). The
positions are written through their scaled second differences (a fixed linear change of
variables, for the same conditioning as the planar u).

Both converge at second order in h, with clean ratios of 4 between successive differences, also
with contact (test_reference_contact.py), so ``refinement_study``'s Richardson value is sound.
SLSQP finds a local minimum reached from the straight rod: a rod that must slide around an
obstacle, or whose first iterate would jump through it, may land on another equilibrium than the
quasi-static one; ``load_steps`` ramps the loads up (compare the results of two step counts).
"""
import contextlib
import ctypes
from dataclasses import dataclass, field
import functools

import numpy as np
from scipy.optimize import minimize, nnls

GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
ACTIVE_GAP = 1e-7  # m, a gap below this may carry a contact force
TIE = 1e-14  # m, distances closer than this are a tie


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _normalise_rows(v):
    """Return (unit rows, norms); a zero row keeps a zero direction."""
    norm = np.linalg.norm(v, axis=-1)
    return v / np.where(norm > 0.0, norm, 1.0)[..., None], norm


def _dot(a, b):
    return np.einsum('...i,...i->...', a, b)


# ---------------------------------------------------------------- obstacles

class Obstacle:
    """A convex rigid obstacle with a ``name``; ``distance`` is its signed distance (m)."""

    def distance(self, points):
        """Return (signed distance (m,) m, outward unit normal (m, 3)) at points (m, 3)."""
        raise NotImplementedError

    def curve_distance(self, start, chord, bulge):
        """Return (distance, normal, t) at the closest point of each curve (rows of the arrays).

        The curves are start + t chord + t (1 - t) bulge, t in [0, 1]; golden-section search over
        t, then the best of it and both ends.
        """
        def at(t):
            return start + t[:, None] * chord + (t * (1.0 - t))[:, None] * bulge

        lo, hi = np.zeros(len(start)), np.ones(len(start))
        for _ in range(48):  # 0.618^48 ~ 1e-10 of a link; the distance is flat at its minimum
            t1, t2 = hi - GOLDEN * (hi - lo), lo + GOLDEN * (hi - lo)
            left = self.distance(at(t1))[0] <= self.distance(at(t2))[0]
            hi, lo = np.where(left, t2, hi), np.where(left, lo, t1)
        # ties (a straight link along a plane) go to the far end: the near end is the previous
        # link's far end, and t = 0 on the first link is the fixed base, which nothing can push
        candidates = np.stack([np.ones(len(start)), (lo + hi) / 2.0, np.zeros(len(start))])
        values = np.stack([self.distance(at(t))[0] for t in candidates])
        values += np.array([0.0, 1.0, 2.0])[:, None] * TIE
        t = candidates[np.argmin(values, axis=0), np.arange(len(start))]
        d, normal = self.distance(at(t))
        return d, normal, t


@dataclass
class Plane(Obstacle):
    """Solid half-space; the free side is normal . x >= offset (m)."""

    name: str
    normal: np.ndarray
    offset: float

    def __post_init__(self):
        self.normal = _unit(self.normal)

    def distance(self, points):
        return points @ self.normal - self.offset, np.broadcast_to(self.normal, points.shape)


@dataclass
class Sphere(Obstacle):
    """Ball of ``radius`` (m) about ``centre``."""

    name: str
    centre: np.ndarray
    radius: float

    def __post_init__(self):
        self.centre = np.asarray(self.centre, dtype=float)

    def distance(self, points):
        normal, norm = _normalise_rows(points - self.centre)
        return norm - self.radius, normal


@dataclass
class Cylinder(Obstacle):
    """Infinite solid cylinder of ``radius`` (m) about the line through ``point``, ``axis``."""

    name: str
    point: np.ndarray
    axis: np.ndarray
    radius: float

    def __post_init__(self):
        self.point = np.asarray(self.point, dtype=float)
        self.axis = _unit(self.axis)

    def distance(self, points):
        v = points - self.point
        normal, norm = _normalise_rows(v - np.outer(v @ self.axis, self.axis))
        return norm - self.radius, normal


@dataclass
class Capsule(Obstacle):
    """Points within ``radius`` (m) of the segment ``start``-``end`` (round-ended cylinder)."""

    name: str
    start: np.ndarray
    end: np.ndarray
    radius: float

    def __post_init__(self):
        self.start = np.asarray(self.start, dtype=float)
        self.end = np.asarray(self.end, dtype=float)

    def distance(self, points):
        axis = self.end - self.start
        t = np.clip((points - self.start) @ axis / (axis @ axis), 0.0, 1.0)
        normal, norm = _normalise_rows(points - self.start - t[:, None] * axis)
        return norm - self.radius, normal


@dataclass
class Box(Obstacle):
    """Box of ``half_sizes`` (m) about ``centre``, along the columns of ``rotation``.

    ``rotation`` maps box to world coordinates. The distance is C1 outside only (not across the
    edges inside): fine while the rod stays outside.
    """

    name: str
    centre: np.ndarray
    rotation: np.ndarray
    half_sizes: np.ndarray

    def __post_init__(self):
        self.centre = np.asarray(self.centre, dtype=float)
        self.rotation = np.asarray(self.rotation, dtype=float)
        self.half_sizes = np.asarray(self.half_sizes, dtype=float)

    def distance(self, points):
        q = (points - self.centre) @ self.rotation
        excess = np.abs(q) - self.half_sizes
        outside, out_norm = _normalise_rows(np.maximum(excess, 0.0) * np.sign(q))
        rows, face = np.arange(len(q)), np.argmax(excess, axis=1)
        inside = np.zeros_like(q)
        inside[rows, face] = np.sign(q[rows, face])
        is_out = out_norm > 0.0
        normal = np.where(is_out[:, None], outside, inside) @ self.rotation.T
        return np.where(is_out, out_norm, excess[rows, face]), normal


# ---------------------------------------------------------------- rod, loads, results

@dataclass
class Rod:
    """Clamped rod and its loads (SI units).

    :ivar length: m
    :ivar EI: N m^2, bending stiffness
    :ivar body_radius: m, the rod's own radius (clearance kept from obstacles)
    :ivar mass_per_length: kg/m (rho A)
    :ivar gravity: m/s^2 vector
    :ivar tip_force: N vector, fixed in space
    :ivar disks: ((s m, mass kg), ...) point masses on the centerline
    :ivar base: m, the clamped end
    :ivar base_direction: tangent at the base (normalised)
    """

    length: float
    EI: float
    body_radius: float = 0.0
    mass_per_length: float = 0.0
    gravity: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, -9.81]))
    tip_force: np.ndarray = field(default_factory=lambda: np.zeros(3))
    disks: tuple = ()
    base: np.ndarray = field(default_factory=lambda: np.zeros(3))
    base_direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))

    def __post_init__(self):
        self.gravity = np.asarray(self.gravity, dtype=float)
        self.tip_force = np.asarray(self.tip_force, dtype=float)
        self.base = np.asarray(self.base, dtype=float)
        self.base_direction = _unit(self.base_direction)

    @classmethod
    def nitinol(cls, length=0.3, diameter=2e-3, young=58e9, density=6450.0, **loads):
        """Return a solid round rod (default Nitinol, 2 mm, 0.3 m) carrying its own weight.

        ``loads``: other Rod fields (they may override the body radius or mass per length).
        """
        fields = {'body_radius': diameter / 2.0,
                  'mass_per_length': density * np.pi * diameter ** 2 / 4.0, **loads}
        return cls(length=length, EI=young * np.pi * diameter ** 4 / 64.0, **fields)


@dataclass
class Contact:
    """What one obstacle does to the rod.

    :ivar force: N (3,), resultant contact force on the rod
    :ivar magnitude: N, |force|
    :ivar normal_sum: N, sum of the magnitudes of the individual contact forces
    :ivar s: m, force-weighted mean arc length of contact (nan without contact)
    :ivar point: m (3,), force-weighted mean contact point on the centerline
    :ivar obstacle_point: m (3,), the same on the obstacle's surface
    :ivar s_each: m (k,), arc length of each active gap's closest point (one per link)
    :ivar force_each: N (k, 3), the contact force there (may be zero)
    """

    name: str
    force: np.ndarray
    magnitude: float
    normal_sum: float
    s: float
    point: np.ndarray
    obstacle_point: np.ndarray
    s_each: np.ndarray
    force_each: np.ndarray


@dataclass
class Solution:
    """An equilibrium found.

    :ivar s: m (n+1,), node arc lengths
    :ivar positions: m (n+1, 3), nodes
    :ivar tip: m (3,)
    :ivar contacts: {obstacle name: Contact}
    :ivar energy: J, bending plus load potential
    :ivar min_gap: m, smallest clearance left (negative: penetration; inf without obstacles)
    :ivar kkt_residual: |grad E - sum lambda grad g| / |load part of grad E| (0 at a KKT point)
    """

    s: np.ndarray
    positions: np.ndarray
    tip: np.ndarray
    contacts: dict
    energy: float
    min_gap: float
    kkt_residual: float
    success: bool
    message: str
    iterations: int


def node_loads(rod, n):
    """Return the lumped node forces (n+1, 3) N: weight (trapezoid), disks, tip force."""
    h = rod.length / n
    loads = np.tile(rod.mass_per_length * rod.gravity * h, (n + 1, 1))
    loads[[0, -1]] /= 2.0
    for s, mass in rod.disks:
        k = min(int(s / h), n - 1)
        alpha = s / h - k
        loads[k] += (1.0 - alpha) * mass * rod.gravity
        loads[k + 1] += alpha * mass * rod.gravity
    loads[-1] += rod.tip_force
    return loads


def curvature_stencil(n, h):
    """Return (W (n, n+1)): curvature at link k's midpoint = sum_i W[k, i] (direction i).

    Direction 0 is the clamp's (at s = 0), direction i >= 1 link i's (at (i - 1/2) h). Centred
    difference inside; (d_2 - d_0) / (1.5 h) on the first link; on the last, the mean of the
    node's (d_n - d_(n-1)) / h and the free tip's zero.
    """
    w = np.zeros((n, n + 1))
    if n < 2:
        return w
    w[0, [0, 2]] = np.array([-1.0, 1.0]) / (1.5 * h)
    rows = np.arange(1, n - 1)
    w[rows, rows] = -0.5 / h
    w[rows, rows + 2] = 0.5 / h
    w[n - 1, [n - 1, n]] = np.array([-0.5, 0.5]) / h
    return w


def _gaps(obstacles, start, chord, bulge, body_radius):
    """Return per obstacle (gap (n,) m, normal (n, 3), t (n,)) of every link's contact curve."""
    out = []
    for obstacle in obstacles:
        d, normal, t = obstacle.curve_distance(start, chord, bulge)
        out.append((d - body_radius, np.ascontiguousarray(normal), t))
    return out


def _contacts(obstacles, gaps, curve, body_radius, h, grad, jacobians, scale, equality=None,
              load_norm=1.0):
    """Return ({name: Contact}, KKT residual) from the active gaps by NNLS.

    grad: gradient of the scaled energy; jacobians: per obstacle, the gradient rows of its
    scaled gaps; equality: gradient rows of the equality constraints (projected out);
    scale: N per unit multiplier of the scaled problem; curve: (start, chord, bulge) per link.
    """
    active = [np.flatnonzero(gap < ACTIVE_GAP) for gap, _, _ in gaps]
    rows = [jac[idx] for jac, idx in zip(jacobians, active)]
    columns = np.vstack(rows).T if rows else np.zeros((len(grad), 0))
    if equality is not None:  # free multipliers: keep what is orthogonal to their span
        q = np.linalg.qr(equality.T)[0]
        grad = grad - q @ (q.T @ grad)
        columns = columns - q @ (q.T @ columns)
    lam = nnls(columns, grad, maxiter=50 * columns.shape[1] + 50)[0] if columns.size \
        else np.zeros(0)
    residual = np.linalg.norm(columns @ lam - grad) / load_norm
    contacts, first = {}, 0
    for obstacle, (gap, normal, t), idx in zip(obstacles, gaps, active):
        size = lam[first:first + len(idx)] * scale
        first += len(idx)
        start, chord, bulge = (part[idx] for part in curve)
        tt = t[idx, None]
        on_rod = start + tt * chord + tt * (1.0 - tt) * bulge
        on_obstacle = on_rod - (gap[idx] + body_radius)[:, None] * normal[idx]
        s_each, force = (idx + t[idx]) * h, size @ normal[idx]
        total = float(size.sum())
        weights = size / total if total > 0.0 else np.full(len(idx), np.nan)
        touches = total > 0.0  # else the means are nan
        contacts[obstacle.name] = Contact(
            name=obstacle.name, force=force, magnitude=float(np.linalg.norm(force)),
            normal_sum=total, s=float(weights @ s_each) if touches else np.nan,
            point=weights @ on_rod if touches else np.full(3, np.nan),
            obstacle_point=weights @ on_obstacle if touches else np.full(3, np.nan),
            s_each=s_each, force_each=size[:, None] * normal[idx])
    return contacts, float(residual)


def _one_blas_thread(solve):
    """Run ``solve`` with OpenBLAS single-threaded in the calling thread (restored after).

    The matrices here are small: OpenBLAS's threads made the solves 5x slower on an idle
    2-core machine and up to 500x on a loaded one. Linux (/proc/self/maps) and OpenBLAS >= 0.3.27
    only; elsewhere a no-op.
    """
    @functools.wraps(solve)
    def wrapper(*args, **kwargs):
        with contextlib.ExitStack() as stack:
            for setter in _openblas_thread_setters():
                previous = setter(1)
                stack.callback(setter, previous)
            return solve(*args, **kwargs)
    return wrapper


@functools.cache
def _openblas_thread_setters():
    try:
        with open('/proc/self/maps') as maps:
            paths = sorted({line.split()[-1] for line in maps if 'openblas' in line})
    except OSError:
        return ()
    setters = []
    for path in paths:
        try:
            setter = ctypes.CDLL(path).openblas_set_num_threads_local
        except (OSError, AttributeError):
            continue
        setter.restype, setter.argtypes = ctypes.c_int, [ctypes.c_int]
        setters.append(setter)
    return tuple(setters)


def _minimise(energy, x0, constraints, ftol, maxiter, load_steps):
    """Return (x, success, message, iterations) of SLSQP, the loads ramped up in load_steps.

    Each step starts from the last one's equilibrium: from the straight rod under the full load,
    SLSQP may step through an obstacle and settle on its far side (also an equilibrium).
    """
    x, success, iterations = x0, True, 0
    for step in range(1, load_steps + 1):
        result = minimize(functools.partial(energy, scale=step / load_steps), x, jac=True,
                          method='SLSQP', constraints=constraints,
                          options={'ftol': ftol, 'maxiter': maxiter})
        x, success, iterations = result.x, success and result.success, iterations + result.nit
    return x, bool(success), str(result.message), int(iterations)


def _reverse_cumsum(a, axis=0):
    return np.flip(np.cumsum(np.flip(a, axis=axis), axis=axis), axis=axis)


# ---------------------------------------------------------------- planar: link angles

@_one_blas_thread
def solve_planar(rod, obstacles=(), n=200, load_steps=1, ftol=1e-15, maxiter=1000):
    """Return the planar equilibrium (Solution) with n links, the rod in the x-z plane.

    Unknowns: the link angles theta from +z towards +x, through the scaled turning angles u
    (module docstring). ``load_steps``: ramp all loads up in that many solves, each from the
    last (``_minimise``). Raises ValueError for a base direction or load with a y component.
    """
    obstacles = tuple(obstacles)
    L, EI, h = rod.length, rod.EI, rod.length / n
    for vector in (rod.base_direction, rod.gravity, rod.tip_force):
        if abs(vector[1]) > 1e-12 * max(np.linalg.norm(vector), 1.0):
            raise ValueError('the planar reference needs the base direction and loads in x-z')
    loads = node_loads(rod, n)
    beyond = _reverse_cumsum(loads[1:])  # load on nodes k..n: what turning link k moves
    theta0 = np.arctan2(rod.base_direction[0], rod.base_direction[2])
    sigma = np.full(n, np.sqrt(L / h))
    sigma[0] *= np.sqrt(2.0)  # the clamp's half step
    stencil = curvature_stencil(n, h)

    def shape(u):
        """Return (nodes, link directions, their theta-derivatives, curvatures) at u."""
        theta = theta0 + np.cumsum(u / sigma)
        zero = np.zeros(n)
        tangent = np.stack([np.sin(theta), zero, np.cos(theta)], axis=1)
        turned = np.stack([np.cos(theta), zero, -np.sin(theta)], axis=1)
        nodes = rod.base + np.vstack([np.zeros(3), h * np.cumsum(tangent, axis=0)])
        kappa = stencil @ np.concatenate([[theta0], theta])
        return nodes, tangent, turned, kappa

    def curve(u):
        nodes, tangent, turned, kappa = shape(u)
        return nodes[:-1], h * tangent, -(h * h / 2.0) * kappa[:, None] * turned

    def energy(u, scale=1.0, load_part=False):  # J / (EI / L), the loads times scale
        nodes, _, turned, _ = shape(u)
        by_theta = -(scale * L / EI) * h * _dot(turned, beyond)
        load_grad = _reverse_cumsum(by_theta) / sigma
        if load_part:
            return load_grad
        return 0.5 * u @ u - (scale * L / EI) * np.sum(loads[1:] * nodes[1:]), u + load_grad

    def jacobians(u, gaps):
        """Rows d(gap / L)/du per obstacle, at the closest points held fixed (envelope)."""
        _, tangent, turned, kappa = shape(u)
        out = []
        for _, normal, t in gaps:
            along = normal @ turned.T  # n_k . d tangent_i / d theta_i
            jac = h * np.tril(along, -1)  # through r_(k-1): links before k
            sag = t * (1.0 - t) * h * h / 2.0
            rows = np.arange(n)
            jac[rows, rows] += t * h * along[rows, rows] + sag * kappa * _dot(normal, tangent)
            jac -= (sag * along[rows, rows])[:, None] * stencil[:, 1:]  # through c_k
            out.append(_reverse_cumsum(jac, axis=1) / sigma / L)  # theta_i = sum_(j<=i) phi_j
        return out

    def gap_values(u):
        return _gaps(obstacles, *curve(u), rod.body_radius)

    constraints = [{'type': 'ineq',
                    'fun': lambda u: np.concatenate([g for g, _, _ in gap_values(u)]) / L,
                    'jac': lambda u: np.vstack(jacobians(u, gap_values(u)))}] \
        if obstacles else []
    u, success, message, iterations = _minimise(energy, np.zeros(n), constraints, ftol,
                                                maxiter, load_steps)
    gaps = gap_values(u)
    contacts, residual = _contacts(
        obstacles, gaps, curve(u), rod.body_radius, h, energy(u)[1], jacobians(u, gaps),
        EI / L ** 2, load_norm=max(np.linalg.norm(energy(u, load_part=True)), 1e-300))
    nodes = shape(u)[0]
    return Solution(
        s=np.arange(n + 1) * h, positions=nodes, tip=nodes[-1], contacts=contacts,
        energy=float(energy(u)[0] * EI / L),
        min_gap=min((float(g.min()) for g, _, _ in gaps), default=np.inf),
        kkt_residual=residual, success=success, message=message, iterations=iterations)


# ---------------------------------------------------------------- 3-D: node positions

def _bend(a, b):
    """Return |kb|^2 of the turn from rows a to rows b, and its gradients in a and b.

    |kb|^2 = 4 (1 - c) / (1 + c) = 4 |a^ x b^|^2 / (1 + c)^2, c = a^ . b^ = cos(turn).
    """
    (ua, na), (ub, nb) = _normalise_rows(a), _normalise_rows(b)
    c = _dot(ua, ub)
    cross = np.cross(ua, ub)  # not 1 - c: that cancels for small turns (noise SLSQP sees)
    slope = -8.0 / (1.0 + c) ** 2
    return (4.0 * _dot(cross, cross) / (1.0 + c) ** 2,
            slope[:, None] * (ub - c[:, None] * ua) / na[:, None],
            slope[:, None] * (ua - c[:, None] * ub) / nb[:, None])


@_one_blas_thread
def solve_3d(rod, obstacles=(), n=60, load_steps=1, ftol=1e-12, maxiter=1000):
    """Return the 3-D equilibrium (Solution) with n links.

    Unknowns: the nodes r_1 .. r_n through their scaled second differences; link lengths held by
    equality constraints (module docstring). About 3x the unknowns of ``solve_planar`` and a
    dense SLSQP: keep n <= ~150. ``load_steps`` as in ``solve_planar``. A looser ``ftol`` than
    the planar one: below ~1e-13 SLSQP stalls on round-off of the length constraints.
    """
    obstacles = tuple(obstacles)
    L, EI, h = rod.length, rod.EI, rod.length / n
    d0 = rod.base_direction
    loads = node_loads(rod, n)
    beyond = _reverse_cumsum(loads[1:])  # load on nodes k..n: what moving link k moves
    sigma = np.full(n, np.sqrt(L / h ** 3))
    sigma[0] *= np.sqrt(2.0)  # the clamp's half step
    stencil = curvature_stencil(n, h)

    def edges(y):
        return h * d0 + np.cumsum(y.reshape(n, 3) / sigma[:, None], axis=0)

    def nodes_of(e):
        return rod.base + np.vstack([np.zeros(3), np.cumsum(e, axis=0)])

    def to_unknowns(by_edge):
        """Chain rule from edge gradients (..., n, 3) to the unknowns (..., 3 n)."""
        by_second = _reverse_cumsum(by_edge, axis=-2) / sigma[:, None]
        return by_second.reshape(by_edge.shape[:-2] + (3 * n,))

    def energy(y, scale=1.0, load_part=False):  # J / (EI / L), the loads times scale
        e = edges(y)
        load_grad = -(scale * L / EI) * beyond
        if load_part:
            return to_unknowns(load_grad)
        value, grad = -(scale * L / EI) * np.sum(loads[1:] * nodes_of(e)[1:]), load_grad.copy()
        bend, by_a, by_b = _bend(e[:-1], e[1:])
        value += L / (2.0 * h) * bend.sum()
        grad[:-1] += L / (2.0 * h) * by_a
        grad[1:] += L / (2.0 * h) * by_b
        bend, _, by_b = _bend(d0[None, :], e[:1])
        value += L / h * bend[0]
        grad[0] += L / h * by_b[0]
        return value, to_unknowns(grad)

    def curve(y):
        e = edges(y)
        directions = np.vstack([d0, _normalise_rows(e)[0]])
        return nodes_of(e)[:-1], e, -(h * h / 2.0) * stencil @ directions

    def lengths(y):
        e = edges(y)
        return _dot(e, e) / h ** 2 - 1.0

    def lengths_jac(y):
        return to_unknowns(np.eye(n)[:, :, None] * (2.0 / h ** 2) * edges(y)[:, None, :])

    def jacobians(y, gaps):
        """Rows d(gap / L)/dy per obstacle, at the closest points held fixed (envelope)."""
        e = edges(y)
        unit, norm = _normalise_rows(e)
        out = []
        for _, normal, t in gaps:
            jac = np.tril(np.ones((n, n)), -1)[:, :, None] * normal[:, None, :]
            jac[np.arange(n), np.arange(n)] += t[:, None] * normal
            across = normal[:, None, :] - (normal @ unit.T)[:, :, None] * unit[None, :, :]
            sag = t * (1.0 - t) * h * h / 2.0
            jac -= sag[:, None, None] * stencil[:, 1:, None] * across / norm[None, :, None]
            out.append(to_unknowns(jac) / L)
        return out

    def gap_values(y):
        return _gaps(obstacles, *curve(y), rod.body_radius)

    constraints = [{'type': 'eq', 'fun': lengths, 'jac': lengths_jac}]
    if obstacles:
        constraints.append({
            'type': 'ineq',
            'fun': lambda y: np.concatenate([g for g, _, _ in gap_values(y)]) / L,
            'jac': lambda y: np.vstack(jacobians(y, gap_values(y)))})
    y, success, message, iterations = _minimise(energy, np.zeros(3 * n), constraints, ftol,
                                                maxiter, load_steps)
    gaps = gap_values(y)
    contacts, residual = _contacts(
        obstacles, gaps, curve(y), rod.body_radius, h, energy(y)[1], jacobians(y, gaps),
        EI / L ** 2, equality=lengths_jac(y),
        load_norm=max(np.linalg.norm(energy(y, load_part=True)), 1e-300))
    nodes = nodes_of(edges(y))
    return Solution(
        s=np.arange(n + 1) * h, positions=nodes, tip=nodes[-1], contacts=contacts,
        energy=float(energy(y)[0] * EI / L),
        min_gap=min((float(g.min()) for g, _, _ in gaps), default=np.inf),
        kkt_residual=residual, success=success, message=message, iterations=iterations)


# ---------------------------------------------------------------- refinement

def refinement_study(solve, ns=(50, 100, 200, 400), quantity=lambda sol: sol.tip, order=2):
    """Solve at each n (doubling) and extrapolate.

    :param solve: solve(n=...) -> Solution, e.g. functools.partial(solve_planar, rod, obstacles)
    :param quantity: Solution -> float or array (tip, a contact force, ...)
    :param order: assumed order p of the leading error, for Richardson
    :return: dict of ns, values, differences (successive), ratios |d_i| / |d_(i+1)|,
        orders log2 of the ratios, and richardson = v_N + (v_N - v_(N/2)) / (2^p - 1)
    """
    values = np.array([np.asarray(quantity(solve(n=n)), dtype=float) for n in ns])
    differences = np.diff(values, axis=0)
    sizes = np.array([np.linalg.norm(d) for d in differences])
    ratios = sizes[:-1] / np.where(sizes[1:] > 0.0, sizes[1:], np.nan)
    return {'ns': np.asarray(ns), 'values': values, 'differences': differences,
            'ratios': ratios, 'orders': np.log2(ratios),
            'richardson': values[-1] + differences[-1] / (2.0 ** order - 1.0)}
