"""Slow, independent reference for multi-section tendon-driven Cosserat rods (SciPy only).

Written from Rucker & Webster, "Statics and dynamics of continuum robots with general tendon
routing and external loading", IEEE T-RO 27(6), 2011, without the package's core. Straight
(parallel) routing: tendon j of section k runs at the constant offset l_j (rod's local frame)
from the base disk (s = 0) to its section's end disk s_k, with constant tension t_j >= 0.

State r, R, v, u with r' = R v, R' = R hat(u); internal force n = R D (v - e3), moment
m = R C u, C = diag(EI, EI, GJ), D = diag(GA, GA, EA), G = E / (2 (1 + nu)) (R&W eqs. 6, 7).

``model='distributed'`` (R&W eq. 17, static): with p_j^b' = v + u x l_j (the tendon tangent in
the body frame), A_j = -t_j hat(p_j^b')^2 / |p_j^b'|^3, B_j = hat(l_j) A_j, G = -sum A_j hat(l_j),
H = -sum B_j hat(l_j), a_j = A_j (u x p_j^b'), b_j = hat(l_j) a_j, the strains obey

    [D + A, G; B, C + H] [v'; u'] = [d; c]
    d = -u x D (v - e3) - R^T f - a,   c = -u x C u - v x D (v - e3) - b,

where f = rho A g is the distributed weight (global). Where the tendons of a section end, each
pulls its hole towards the base along its own tangent, F_j = -t_j R p_j^b' / |p_j^b'| (left
limit), with moment (R l_j) x F_j about the backbone: n and m jump by -F_j and -(R l_j) x F_j.

``disk_kinks=True`` (distributed only) adds what the piecewise integration above leaves out:
where the strains jump at a disk, a tendon running on through it kinks there and pushes on its
hole with t_j (tau_j+ - tau_j-). The rod-plus-tendons wrench is then exactly continuous (global
equilibrium holds to round-off); without it, that wrench jumps by the kink load, which is
non-zero only where shear or twist strain jumps at a disk (tip loads, gravity).

General routing (R&W 2011 eqs. 12-17 in full): ``cable_routes`` gives, per tendon, a function
(s, inside) -> (l, l', l'') of its hole position in the body frame and its first two derivatives
(on the piece holding ``inside`` where the route turns at a disk; None: at s). Then
p_j^b' = v + u x l_j + l_j', and a_j = A_j (u x p_j^b' + u x l_j' + l_j''); everything else is
as above (the end-disk pull along the tendon's own tangent p_j^b'). Written from the paper's
equations, not from the package's rod-plus-tendons cut formulation.

``model='point_moment'`` (the paper's): no distributed tendon load and no tendon force; each
tendon applies only the point moment t_j R(s_k) (e3 x l_j) at its end disk; between disks
n' = -f, m' = -r' x n.

The base state (r(0), R(0)) is given; the six unknowns are the base internal force and moment
(body frame, scaled), from which v(0), u(0) follow. They are found with ``scipy.optimize.root``
on the tip conditions n(L-) = F_tip + tendon loads at L, m(L-) = tau_tip + their moments,
integrating with ``solve_ivp`` (DOP853) piecewise between disks.

Checked (test_multisection_physics.py) against: Euler-Bernoulli F L^3 / (3 E I); the
point-moment arc of curvature t |l| / (E I); and the distributed model's arc, derived by hand:
with one tendon, no external load, the rod-plus-tendon body beyond s is free, so
n = -t tau and m = -(R l) x t tau; v = (0, 0, v3), u = (u1, u2, 0) give tau = R e3 and solve
d = c = 0 above with v3 = 1 - t / (E A), u = t (e3 x l) / (E I): a circular arc of radius
(1 - t / (E A)) E I / (t |l|) through the angle t |l| L / (E I), i.e. the point-moment arc
scaled by 1 - t / (E A). With disk_kinks=True the rod-plus-tendons equilibrium holds at every s.
"""
import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import root

E3 = np.array([0.0, 0.0, 1.0])


def hat(w):
    """Return the 3x3 skew matrix of w (hat(w) @ x = w x x)."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


class _Rod:
    """Constants of one problem (SI units)."""

    def __init__(self, length, diameter, youngs_modulus, poisson_ratio, density, gravity):
        area = np.pi * diameter ** 2 / 4.0
        inertia = np.pi * diameter ** 4 / 64.0
        shear = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
        self.length = float(length)
        self.ei = youngs_modulus * inertia
        self.ea = youngs_modulus * area
        self.c = np.diag([self.ei, self.ei, shear * 2.0 * inertia])
        self.d = np.diag([shear * area, shear * area, self.ea])
        self.f = density * area * np.asarray(gravity, float)

    def strains(self, n_body, m_body):
        """Return v, u from the internal force and moment in the body frame."""
        return E3 + n_body / np.diag(self.d), m_body / np.diag(self.c)


def _straight(offset):
    """Return the route (s, inside) -> (l, l', l'') of a tendon at a constant offset."""
    zero = np.zeros(3)
    return lambda _s, inside=None: (offset, zero, zero)


def _rhs(rod, offsets, tensions, model, routes=None, inside=None):
    """Return the right-hand side y' = F(s, y), y = [r, R (row-major), v, u].

    ``inside``: an arc length inside the piece integrated (a route's piece between the disks
    where it turns: its derivatives there, also at the piece's ends).
    """
    routes = routes or [_straight(l_j) for l_j in offsets]

    def rhs(s, y):
        rot = y[3:12].reshape(3, 3)
        v = y[12:15]
        u = y[15:18]
        u_hat = hat(u)
        dv = rod.d @ (v - E3)
        f_body = rot.T @ rod.f
        d = -u_hat @ dv - f_body
        c = -u_hat @ (rod.c @ u) - np.cross(v, dv)
        lhs = np.zeros((6, 6))
        lhs[:3, :3] = rod.d
        lhs[3:, 3:] = rod.c
        if model == 'distributed':
            for route, t_j in zip(routes, tensions):
                if t_j == 0.0:
                    continue
                l_j, dl_j, ddl_j = route(s, inside)
                l_hat = hat(l_j)
                pb = v + np.cross(u, l_j) + dl_j
                norm = np.linalg.norm(pb)
                pb_hat = hat(pb)
                a_mat = -t_j * (pb_hat @ pb_hat) / norm ** 3
                b_mat = l_hat @ a_mat
                a_vec = a_mat @ (np.cross(u, pb) + np.cross(u, dl_j) + ddl_j)
                lhs[:3, :3] += a_mat
                lhs[:3, 3:] -= a_mat @ l_hat
                lhs[3:, :3] += b_mat
                lhs[3:, 3:] -= b_mat @ l_hat
                d -= a_vec
                c -= l_hat @ a_vec
        dvu = np.linalg.solve(lhs, np.concatenate([d, c]))
        dy = np.empty(18)
        dy[:3] = rot @ v
        dy[3:12] = (rot @ u_hat).ravel()
        dy[12:] = dvu
        return dy

    return rhs


def _end_loads(rot, v, u, offsets, tensions, model, tangents=None):
    """Return the total force and moment (global, about the backbone) of tendons ending here.

    ``tangents``: each tendon's l' there (general routing; default zero).
    """
    force = np.zeros(3)
    moment = np.zeros(3)
    tangents = np.zeros_like(offsets) if tangents is None else tangents
    for l_j, dl_j, t_j in zip(offsets, tangents, tensions):
        if model == 'distributed':
            pb = v + np.cross(u, l_j) + dl_j
            f_j = -t_j * rot @ pb / np.linalg.norm(pb)
            force += f_j
            moment += np.cross(rot @ l_j, f_j)
        else:
            moment += t_j * rot @ np.cross(E3, l_j)
    return force, moment


def _tendon_wrench(rot, v, u, offsets, tensions, indices, tangents=None):
    """Return sum t_j tau_j and sum (R l_j) x t_j tau_j over the given tendons (global).

    ``tangents``: each tendon's l' here (general routing; default zero).
    """
    force = np.zeros(3)
    moment = np.zeros(3)
    tangents = np.zeros_like(offsets) if tangents is None else tangents
    for j in indices:
        pb = v + np.cross(u, offsets[j]) + tangents[j]
        pull = tensions[j] * rot @ pb / np.linalg.norm(pb)
        force += pull
        moment += np.cross(rot @ offsets[j], pull)
    return force, moment


def _kinked(rod, rot, v, u, v_new, u_new, n_new, m_new, offsets, tensions, continuing,
            before=None, after=None):
    """Return v, u beyond a disk where the continuing tendons' tangents kink.

    The strains jump at the disk, so a continuing tendon's tangent R (v + u x l) jumps too and
    the tendon pushes on its hole with t (tau+ - tau-). Its point wrench is fixed by requiring
    that the rod-plus-tendons wrench (n + sum t tau, m + sum (R l) x t tau) is continuous.
    ``before``, ``after``: the tendons' l' on either side (general routing: a route that turns
    at the disk kinks the tendon there even where the strains would not jump).
    """
    force_minus, moment_minus = _tendon_wrench(rot, v, u, offsets, tensions, continuing, before)
    scale = np.concatenate([np.full(3, rod.ei / rod.length ** 2), np.full(3, rod.ei / rod.length)])

    def jump(x):
        """Return the rod-plus-tendons wrench mismatch across the disk (scaled)."""
        n_k, m_k = x[:3] * scale[:3], x[3:] * scale[3:]
        force_plus, moment_plus = _tendon_wrench(rot, *rod.strains(rot.T @ n_k, rot.T @ m_k),
                                                 offsets, tensions, continuing, after)
        return np.concatenate([n_k + force_plus - n_new - force_minus,
                               m_k + moment_plus - m_new - moment_minus]) / scale

    sol = root(jump, np.concatenate([n_new, m_new]) / scale, method='hybr', tol=1e-14)
    if np.max(np.abs(jump(sol.x))) > 1e-12:
        raise RuntimeError('reference: kink at a disk did not converge')
    x = sol.x * scale
    return rod.strains(rot.T @ x[:3], rot.T @ x[3:])


def _shoot(rod, problem, x, s_eval=None, rtol=1e-12, atol=1e-14):
    """Integrate from the base with scaled base wrench x; return the tip residual (and nodes)."""
    ends, offsets, cable_sections, tensions, model = problem['cables']
    routes = problem.get('routes')
    force_scale = rod.ei / rod.length ** 2
    moment_scale = rod.ei / rod.length
    v, u = rod.strains(x[:3] * force_scale, x[3:] * moment_scale)
    y = np.concatenate([problem['base_position'], problem['base_rotation'].ravel(), v, u])
    breaks = sorted({float(e) for e in ends if 0.0 < e < rod.length} | {rod.length}
                    | {float(b) for b in problem.get('route_breaks', ()) if 0.0 < b < rod.length})
    start = 0.0
    nodes = []
    for stop in breaks:
        active = [j for j in range(len(tensions)) if ends[cable_sections[j]] >= stop - 1e-12]
        rhs = _rhs(rod, offsets[active], tensions[active], model,
                   None if routes is None else [routes[j] for j in active],
                   0.5 * (start + stop))
        wanted = [] if s_eval is None else s_eval[(s_eval >= start) & (s_eval <= stop)]
        sol = solve_ivp(rhs, (start, stop), y, method='DOP853', rtol=rtol, atol=atol,
                        t_eval=np.union1d(wanted, [stop]))  # the piece's end: the next start
        if not sol.success:
            raise RuntimeError(f'reference integration failed: {sol.message}')
        if len(wanted):
            keep = np.isin(sol.t, wanted)
            nodes.append((sol.t[keep], sol.y.T[keep]))
        y = sol.y[:, -1].copy()
        rot = y[3:12].reshape(3, 3)
        v, u = y[12:15], y[15:18]
        ending = [j for j in range(len(tensions))
                  if abs(ends[cable_sections[j]] - stop) <= 1e-12]
        holes, before, after = offsets, None, None
        if routes is not None:  # l here, l' on either side (one-sided where a route turns)
            holes = np.array([route(stop)[0] for route in routes]).reshape(-1, 3)
            before = np.array([route(stop, stop - 1e-9)[1] for route in routes]).reshape(-1, 3)
            after = np.array([route(stop, stop + 1e-9)[1] for route in routes]).reshape(-1, 3)
        force, moment = _end_loads(rot, v, u, holes[ending], tensions[ending], model,
                                   None if before is None else before[ending])
        n = rot @ rod.d @ (v - E3)
        m = rot @ rod.c @ u
        if stop < rod.length:
            # the point loads act on the rod: internal wrench beyond the disk
            n_new, m_new = n - force, m - moment
            v_new, u_new = rod.strains(rot.T @ n_new, rot.T @ m_new)
            if (problem['disk_kinks'] or routes is not None) and model == 'distributed':
                v_new, u_new = _kinked(rod, rot, v, u, v_new, u_new, n_new, m_new, holes,
                                       tensions, [j for j in range(len(tensions))
                                                  if ends[cable_sections[j]] > stop + 1e-12],
                                       before, after)
            y[12:15], y[15:18] = v_new, u_new
        start = stop
    residual = np.concatenate([
        (n - problem['tip_force'] - force) / force_scale,
        (m - problem['tip_moment'] - moment) / moment_scale])
    return residual, nodes


def _initial_guess(rod, problem, load=1.0):
    """Return a guess: section 1 cable moments, tip load and weight on a straight rod."""
    ends, offsets, cable_sections, tensions, model = problem['cables']
    moment = np.zeros(3)
    axial = 0.0
    for l_j, t_j in zip(offsets, tensions):
        moment += t_j * np.cross(E3, l_j)
        if model == 'distributed':
            axial -= t_j
    rot0 = problem['base_rotation']
    tip = problem['base_position'] + rot0 @ E3 * rod.length
    force = problem['tip_force'] + rod.f * rod.length * load
    m_global = problem['tip_moment'] + np.cross(tip - problem['base_position'], force)
    n_body = rot0.T @ force + np.array([0.0, 0.0, axial])
    m_body = moment + rot0.T @ m_global
    return np.concatenate([n_body / (rod.ei / rod.length ** 2), m_body / (rod.ei / rod.length)])


COARSE = {'rtol': 1e-9, 'atol': 1e-11}
FINE = {'rtol': 1e-12, 'atol': 1e-14}


def _solve_coarse(rod, problem, x):
    """Return the scaled base wrench solving the tip conditions at coarse accuracy, or None."""
    def coarse(z):
        return _shoot(rod, problem, z, **COARSE)[0]

    if np.max(np.abs(coarse(x))) < 1e-8:
        return x
    # small initial trust region: far from the solution the shots get expensive
    sol = root(coarse, x, method='hybr', options={'factor': 0.5, 'xtol': 1e-11})
    if np.max(np.abs(sol.fun)) < 1e-7:
        return sol.x
    return None


def _polish(rod, problem, x, iterations=30):
    """Newton-iterate at full accuracy with a forward-difference Jacobian from coarse shots."""
    base = _shoot(rod, problem, x, **COARSE)[0]
    step = 1e-6
    jac = np.empty((6, 6))
    for i in range(6):
        z = x.copy()
        z[i] += step
        jac[:, i] = (_shoot(rod, problem, z, **COARSE)[0] - base) / step
    best, best_x = np.inf, x
    for _ in range(iterations):
        residual = np.max(np.abs(_shoot(rod, problem, x, **FINE)[0]))
        if residual < best:
            best, best_x = residual, x
        elif residual > 0.5 * best:  # at the integration's noise floor
            break
        if best < 1e-12:
            break
        x = x - np.linalg.solve(jac, _shoot(rod, problem, x, **FINE)[0])
    return best_x


def solve_reference(length, diameter, youngs_modulus, poisson_ratio, density, base_position,
                    base_rotation, gravity, section_ends, cable_offsets, cable_sections,
                    tensions, tip_force, tip_moment, model, s_eval, disk_kinks=False,
                    cable_routes=None, route_breaks=()):
    """Solve the tendon-driven rod's statics; return positions and rotations at s_eval.

    Lengths in m, moduli in Pa, density in kg/m^3, gravity in m/s^2, tensions in N, tip force in
    N and tip moment in N m (global frame). ``model`` is 'distributed' or 'point_moment'.
    ``cable_routes``: per tendon s -> (l, l', l'') (general routing, distributed model; the
    disk kinks are then always on); ``cable_offsets`` then only seeds the first guess (l(0));
    ``route_breaks``: arc lengths where a route turns (l' jumps: its disks), m.
    Returns a dict with ``positions`` (len(s_eval), 3), ``rotations`` (len(s_eval), 3, 3), the
    rod's internal force ``n`` (N) and moment ``m`` (N m) there (global frame; left limits at a
    disk) and ``residual`` (scaled tip residual).
    """
    if model not in ('distributed', 'point_moment'):
        raise ValueError(f'model must be distributed or point_moment, got {model!r}')
    tensions = np.asarray(tensions, float).reshape(-1)
    offsets = np.asarray(cable_offsets, float).reshape(-1, 3)
    s_eval = np.asarray(s_eval, float)

    def make(load):
        """Return the rod and problem with all loads scaled by load (continuation)."""
        rod = _Rod(length, diameter, youngs_modulus, poisson_ratio, density,
                   load * np.asarray(gravity, float))
        return rod, {
            'base_position': np.asarray(base_position, float),
            'base_rotation': np.asarray(base_rotation, float).reshape(3, 3),
            'tip_force': load * np.asarray(tip_force, float),
            'tip_moment': load * np.asarray(tip_moment, float),
            'disk_kinks': bool(disk_kinks),
            'routes': cable_routes,
            'route_breaks': tuple(route_breaks),
            'cables': ([float(e) for e in section_ends], offsets,
                       [int(k) for k in cable_sections], load * tensions, model),
        }

    rod, problem = make(1.0)
    x = _solve_coarse(rod, problem, _initial_guess(rod, problem))
    if x is None:  # ramp the loads up from the unloaded rod
        x = _initial_guess(*make(0.0))
        for load in np.linspace(0.125, 1.0, 8):
            x = _solve_coarse(*make(load), x)
            if x is None:
                raise RuntimeError('reference shooting failed during load continuation')
    x = _polish(rod, problem, x)
    residual, nodes = _shoot(rod, problem, x, s_eval=s_eval)
    # scaled by E I / L^2 and E I / L: 1e-9 moves a node by well under 1e-9 m
    if np.max(np.abs(residual)) > 1e-9:
        raise RuntimeError(f'reference shooting did not converge: residual {residual}')
    positions = np.full((len(s_eval), 3), np.nan)
    rotations = np.full((len(s_eval), 3, 3), np.nan)
    forces = np.full((len(s_eval), 3), np.nan)
    moments = np.full((len(s_eval), 3), np.nan)
    for s_piece, y_piece in reversed(nodes):  # at a disk, the left limit wins
        for s_i, y_i in zip(s_piece, y_piece):
            index = np.flatnonzero(s_eval == s_i)
            rot = y_i[3:12].reshape(3, 3)
            positions[index] = y_i[:3]
            rotations[index] = rot
            forces[index] = rot @ rod.d @ (y_i[12:15] - E3)
            moments[index] = rot @ rod.c @ y_i[15:18]
    return {'positions': positions, 'rotations': rotations, 'n': forces, 'm': moments,
            'residual': residual}
