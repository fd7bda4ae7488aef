"""Compiled integration of the Cosserat rod with cable loads (paper Table I; R&W 2011).

State along the unstretched arc length s (m), SI units:
  r (3)    backbone position, global frame               r' = R v          (eq. 1)
  R (3x3)  orientation, local -> global                  R' = R hat(u)     (eq. 2)
  M (3)    moment of every load beyond s about r(s): external (tip, gravity) and, for the
           distributed cable model, the cables' own tension (global)   M' = -r' x N
with N(s) = F + f (L - s) + W(s) the force of the tip load F, the weight f beyond s and the
guide disks' weight W beyond s (eqs. 3, 4 and 10 integrated, with point loads at the disks: no
cable term, because a cable's pull on its end disk and its pressure along the backbone are
internal to the rod-and-cable system). The strains follow algebraically from the constitutive
laws (eqs. 6, 7), with C scaled per section where its disks stiffen the rod:
  point_moment (the paper):  C u = R^T M,  D (v - e3) = R^T N;  the cables of a section add a
                             point moment t_j R (e3 x l_j) at its end disk, where M jumps
  distributed (R&W 2011):    C u = R^T M - sum_j t_j l_j x tau_j,
                             D (v - e3) = R^T N - sum_j t_j tau_j
                             over the cables passing s, tau_j = (v + u x l_j + l_j') / |...| the
                             cable's local tangent (R&W eq. 12; l_j(s) its route, l_j' = 0 when
                             straight), by a few Newton steps.

The frame is integrated on SE(3) by the fourth-order Runge-Kutta-Munthe-Kaas method: the classical
RK4 tableau applied to the twist (v, u) in the Lie algebra with dexp^-1 truncated after the double
commutator, then (r, R) <- (r, R) exp(Theta). A segment of constant strain (a circular arc or
helix) is therefore integrated exactly at any step count; M is integrated by the same RK4 stages.

Output node layout (:mod:`continuum_statics.core.description.layout`, 21 values): r (3), R
row-major (9),
v - e3 (3), u (3) (both the left
limit at the node), M (3) after any point moment at the node. v - e3 is kept rather than v because
axial strains are ~1e-5. Everything is scalar code over preallocated arrays so numba compiles it
to tight loops; ``cache=True`` keeps the machine code on disk between processes.
"""
import math

import numba
import numpy as np

from continuum_statics.core.description.layout import (  # the layouts and records, stated once
    AXIS_ROWS_AT,
    BASE_POSITION_AT,
    BASE_ROTATION_AT,
    BENDING_AT,
    BODY_FORCE_AT,
    C_AT,
    C_INV_AT,
    D_INV_AT,
    LENGTH_ROWS_AT,
    MOMENT_AT,
    PARAMS_SIZE,
    POSITION_AT,
    ROTATION_AT,
    STATE_SIZE,
    STRETCH_AT,
    TIP_ROWS_AT,
    Probe,
)
from continuum_statics.core.description.routing import hole_in

POINT_MOMENT, DISTRIBUTED = 0, 1
STRAIN_ITERATIONS = 8  # Newton steps at most; 3 reach round-off at 30 N on 10 mm holes

_SIXTH, _TWELFTH = 1.0 / 6.0, 1.0 / 12.0  # multiplications: a division is ~15 cycles


def pack_params(c, d, f_body, r0, rot0, interval_scale=None, interval_weight=None):
    """Pack the rod constants into the flat vector the kernel reads.

    :param c: (3,) diagonal of C, bending and torsional stiffness (N m^2), eq. 7
    :param d: (3,) diagonal of D, shear and axial stiffness (N), eq. 6
    :param f_body: (3,) distributed body force rho*A*g*e_g in the global frame (N/m)
    :param r0: (3,) base position (m); ``rot0``: (3, 3) base orientation R(0)
    :param interval_scale: (N - 1,) factor on C over each integration interval (sections whose
        disks stiffen the rod); None: C everywhere
    :param interval_weight: (N - 1, 3) weight of the disks beyond each interval, global (N),
        the disk at the interval's end included; None: no disk weights
    The two per-interval blocks follow the 27 rod constants when either is given: the scales,
    their reciprocals, then the weights (3 per interval).
    """
    c = np.asarray(c, dtype=float)
    d = np.asarray(d, dtype=float)
    parts = [c, 1.0 / c, d, 1.0 / d, np.asarray(f_body, dtype=float),
             np.asarray(r0, dtype=float), np.asarray(rot0, dtype=float).ravel()]
    if interval_scale is not None or interval_weight is not None:
        size = len(interval_scale if interval_scale is not None else interval_weight)
        scale = np.ones(size) if interval_scale is None else np.asarray(interval_scale, float)
        weight = (np.zeros((size, 3)) if interval_weight is None
                  else np.asarray(interval_weight, dtype=float))
        parts += [scale, 1.0 / scale, weight.ravel()]
    return np.concatenate(parts)


# Taylor coefficients of sin t / t, (1 - cos t) / t^2 and (t - sin t) / t^3 in t^2, to t^16
_A = tuple((-1.0) ** k / math.factorial(2 * k + 1) for k in range(9))
_B = tuple((-1.0) ** k / math.factorial(2 * k + 2) for k in range(9))
_CC = tuple((-1.0) ** k / math.factorial(2 * k + 3) for k in range(9))


@numba.njit(cache=True, nogil=True, inline='always')
def _series(t2, last):
    """Sum the three Taylor series of :func:`_exp_coefficients` up to term number ``last``."""
    a = _A[last]
    b = _B[last]
    c = _CC[last]
    for i in range(last - 1, -1, -1):
        a = _A[i] + t2 * a
        b = _B[i] + t2 * b
        c = _CC[i] + t2 * c
    return a, b, c


@numba.njit(cache=True, nogil=True, inline='always')
def _exp_coefficients(t2):
    """(sin t / t, (1 - cos t) / t^2, (t - sin t) / t^3) of t = sqrt(t2).

    Up to t = 1 rad (a step's rotation is far smaller) by their Taylor series, exact to
    round-off: to the term in t^16 (the first omitted term below 1e-17 of each value), and
    under t = 0.1 rad (most steps) to t^8 (below 3e-18): a chain of fused multiply-adds
    instead of a square root, two sines and three divisions (the short chain: 0.5 us of a 4.4 us
    paper-rod IVP). Beyond 1 rad, by the trigonometric formulas.
    """
    if t2 <= 1e-2:
        return _series(t2, 4)  # two calls with constant lengths: each loop is unrolled
    if t2 <= 1.0:
        return _series(t2, 8)
    t = math.sqrt(t2)
    sin_t = math.sin(t)
    half = math.sin(0.5 * t) / t
    return sin_t / t, 2.0 * half * half, (t - sin_t) / (t2 * t)


@numba.njit(cache=True, nogil=True, inline='always')
def _rotation(a, b, w0, w1, w2):
    """Rodrigues: I + a hat(w) + b hat(w)^2 as a row-major 9-tuple.

    With a = sin t / t and b = (1 - cos t) / t^2, t = |w|, this is exp(hat(w)).
    """
    return (1.0 - b * (w1 * w1 + w2 * w2), -a * w2 + b * w0 * w1, a * w1 + b * w0 * w2,
            a * w2 + b * w0 * w1, 1.0 - b * (w0 * w0 + w2 * w2), -a * w0 + b * w1 * w2,
            -a * w1 + b * w0 * w2, a * w0 + b * w1 * w2, 1.0 - b * (w0 * w0 + w1 * w1))


@numba.njit(cache=True, nogil=True, inline='always')
def _mul9(a, b):
    """Product of two row-major 3x3 matrices given as 9-tuples."""
    return (a[0] * b[0] + a[1] * b[3] + a[2] * b[6], a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
            a[0] * b[2] + a[1] * b[5] + a[2] * b[8], a[3] * b[0] + a[4] * b[3] + a[5] * b[6],
            a[3] * b[1] + a[4] * b[4] + a[5] * b[7], a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
            a[6] * b[0] + a[7] * b[3] + a[8] * b[6], a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
            a[6] * b[2] + a[7] * b[5] + a[8] * b[8])


@numba.njit(cache=True, nogil=True, inline='always')
def _se3_exp(theta):
    """exp(theta), theta = (rho, w), on SE(3): (exp(hat(w)) as a 9-tuple, V(w) rho).

    V = I + b hat(w) + c hat(w)^2 with b = (1 - cos t) / t^2, c = (t - sin t) / t^3, t = |w|.
    """
    r0, r1, r2, w0, w1, w2 = theta
    a, b, c = _exp_coefficients(w0 * w0 + w1 * w1 + w2 * w2)
    x0 = w1 * r2 - w2 * r1  # w x rho
    x1 = w2 * r0 - w0 * r2
    x2 = w0 * r1 - w1 * r0
    # V rho = rho + b w x rho + c w x (w x rho)
    return _rotation(a, b, w0, w1, w2), (r0 + b * x0 + c * (w1 * x2 - w2 * x1),
                                         r1 + b * x1 + c * (w2 * x0 - w0 * x2),
                                         r2 + b * x2 + c * (w0 * x1 - w1 * x0))


@numba.njit(cache=True, nogil=True, inline='always')
def _to_local(rot, m0, m1, m2):
    """R^T m for a row-major 9-tuple R."""
    return (rot[0] * m0 + rot[3] * m1 + rot[6] * m2, rot[1] * m0 + rot[4] * m1 + rot[7] * m2,
            rot[2] * m0 + rot[5] * m1 + rot[8] * m2)


@numba.njit(cache=True, nogil=True, fastmath={'contract'})
def _strain_newton(ml, nl, u, w, c, p, tensions, routes, point, active):
    """Strains (u, v - e3) of the distributed model (eqs. 6, 7 with the cables' pressure).

    C u = ml - sum t l x tau, D (v - e3) = nl - sum t tau over the cables passing here, with
    tau = q / |q|, q = v + u x l + l' (R&W 2011 eq. 12 in the body frame; l, l' of cable j in
    ``routes[point, 6 j:6 j + 6]``, :class:`~continuum_statics.core.description.routing.Routing`).
    ``c`` the diagonal of C here (N m^2). ``ml``, ``nl`` = R^T M, R^T N; ``u``, ``w`` the
    previous strains, the start of Newton's iteration (exact Jacobian, quadratic convergence:
    l' does not depend on u); ``active[j]``: cable j passes here.
    """
    ml0, ml1, ml2 = ml
    nl0, nl1, nl2 = nl
    routed = routes.shape[0] > 1  # one row: every cable straight, l' = 0
    u0, u1, u2 = u
    w0, w1, w2 = w
    for _ in range(STRAIN_ITERATIONS):
        sm0 = sm1 = sm2 = 0.0  # sum t l x tau
        sn0 = sn1 = sn2 = 0.0  # sum t tau
        k00 = c[0]
        k11 = c[1]
        k22 = c[2]
        k01 = k02 = k12 = 0.0
        for j in range(active.shape[0]):
            t = tensions[j]
            if not active[j] or t == 0.0:
                continue
            # indexed, not a view of the row: a view costs two atomic reference counts
            k = 6 * j
            l0, l1, l2 = routes[point, k], routes[point, k + 1], routes[point, k + 2]
            q0 = w0 + u1 * l2 - u2 * l1  # v + u x l + l'
            q1 = w1 + u2 * l0 - u0 * l2
            q2 = w2 + 1.0 + u0 * l1 - u1 * l0
            if routed:
                q0 += routes[point, k + 3]
                q1 += routes[point, k + 4]
                q2 += routes[point, k + 5]
            inv = 1.0 / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
            tau0, tau1, tau2 = q0 * inv, q1 * inv, q2 * inv
            sm0 += t * (l1 * tau2 - l2 * tau1)
            sm1 += t * (l2 * tau0 - l0 * tau2)
            sm2 += t * (l0 * tau1 - l1 * tau0)
            sn0 += t * tau0
            sn1 += t * tau1
            sn2 += t * tau2
            # d(l x tau)/du = hat(l)^T (I - tau tau^T) hat(l) / |q|
            #              = (|l|^2 I - l l^T - a a^T) / |q|
            # with a = tau x l: Newton's exact Jacobian, so the iteration converges quadratically
            s = t * inv
            ll = l0 * l0 + l1 * l1 + l2 * l2
            a0 = tau1 * l2 - tau2 * l1
            a1 = tau2 * l0 - tau0 * l2
            a2 = tau0 * l1 - tau1 * l0
            k00 += s * (ll - l0 * l0 - a0 * a0)
            k11 += s * (ll - l1 * l1 - a1 * a1)
            k22 += s * (ll - l2 * l2 - a2 * a2)
            k01 -= s * (l0 * l1 + a0 * a1)
            k02 -= s * (l0 * l2 + a0 * a2)
            k12 -= s * (l1 * l2 + a1 * a2)
        r0 = ml0 - c[0] * u0 - sm0
        r1 = ml1 - c[1] * u1 - sm1
        r2 = ml2 - c[2] * u2 - sm2
        # solve the symmetric 3x3 system K du = r by its adjugate
        a00 = k11 * k22 - k12 * k12
        a01 = k02 * k12 - k01 * k22
        a02 = k01 * k12 - k02 * k11
        a11 = k00 * k22 - k02 * k02
        a12 = k01 * k02 - k00 * k12
        a22 = k00 * k11 - k01 * k01
        det = k00 * a00 + k01 * a01 + k02 * a02
        du0 = (a00 * r0 + a01 * r1 + a02 * r2) / det
        du1 = (a01 * r0 + a11 * r1 + a12 * r2) / det
        du2 = (a02 * r0 + a12 * r1 + a22 * r2) / det
        u0 += du0
        u1 += du1
        u2 += du2
        w0 = (nl0 - sn0) * p[D_INV_AT]
        w1 = (nl1 - sn1) * p[D_INV_AT + 1]
        w2 = (nl2 - sn2) * p[D_INV_AT + 2]
        # Newton converges quadratically: after a correction of 1e-9 the error is ~1e-18
        size = abs(u0) + abs(u1) + abs(u2)
        if abs(du0) + abs(du1) + abs(du2) <= 1e-9 * (1.0 + size):
            break
    return (u0, u1, u2), (w0, w1, w2)


@numba.njit(cache=True, nogil=True, inline='always')
def _dexpinv(theta, xi):
    """dexp^-1_(-theta)(xi) on se(3), series truncated after the double commutator.

    For g' = g hat(xi) (strains act in the body frame) and g = g_n exp(theta), theta' =
    dexp^-1_(-theta)(xi) = xi + [theta, xi] / 2 + [theta, [theta, xi]] / 12 + ...
    Twists are (rho, w) = (v, u) 6-tuples; [a, b] = (w_a x rho_b - w_b x rho_a, w_a x w_b).
    """
    p0, p1, p2, q0, q1, q2 = theta
    x0, x1, x2, y0, y1, y2 = xi
    # c = [theta, xi] = (q x x - y x p, q x y)
    c0 = (q1 * x2 - q2 * x1) - (y1 * p2 - y2 * p1)
    c1 = (q2 * x0 - q0 * x2) - (y2 * p0 - y0 * p2)
    c2 = (q0 * x1 - q1 * x0) - (y0 * p1 - y1 * p0)
    c3 = q1 * y2 - q2 * y1
    c4 = q2 * y0 - q0 * y2
    c5 = q0 * y1 - q1 * y0
    # d = [theta, c] = (q x c_rho - c_w x p, q x c_w)
    d0 = (q1 * c2 - q2 * c1) - (c4 * p2 - c5 * p1)
    d1 = (q2 * c0 - q0 * c2) - (c5 * p0 - c3 * p2)
    d2 = (q0 * c1 - q1 * c0) - (c3 * p1 - c4 * p0)
    d3 = q1 * c5 - q2 * c4
    d4 = q2 * c3 - q0 * c5
    d5 = q0 * c4 - q1 * c3
    return (x0 + 0.5 * c0 + d0 * _TWELFTH, x1 + 0.5 * c1 + d1 * _TWELFTH,
            x2 + 0.5 * c2 + d2 * _TWELFTH,
            y0 + 0.5 * c3 + d3 * _TWELFTH, y1 + 0.5 * c4 + d4 * _TWELFTH,
            y2 + 0.5 * c5 + d5 * _TWELFTH)


@numba.njit(cache=True, nogil=True, inline='always')
def _cable_sums(u, w, tensions, routes, active, out):
    """Sum t l x tau (out[0:3]) and t tau (out[3:6]) over active cables at the base (s = 0).

    tau ~ v + u x l + l' with the routes' values at the start of the first interval.
    """
    for i in range(6):
        out[i] = 0.0
    for j in range(active.shape[0]):
        t = tensions[j]
        if not active[j] or t == 0.0:
            continue
        k = 6 * j
        l0, l1, l2 = routes[0, k], routes[0, k + 1], routes[0, k + 2]
        q0 = w[0] + u[1] * l2 - u[2] * l1 + routes[0, k + 3]
        q1 = w[1] + u[2] * l0 - u[0] * l2 + routes[0, k + 4]
        q2 = w[2] + 1.0 + u[0] * l1 - u[1] * l0 + routes[0, k + 5]
        inv = t / math.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        out[0] += inv * (l1 * q2 - l2 * q1)
        out[1] += inv * (l2 * q0 - l0 * q2)
        out[2] += inv * (l0 * q1 - l1 * q0)
        out[3] += inv * q0
        out[4] += inv * q1
        out[5] += inv * q2


@numba.njit(cache=True, nogil=True)
def _base_stretch(rot, force, p, model, tensions, routes, active, u, w):
    """v(0) - e3 for a given u(0): D (v - e3) = R^T N - sum t tau(u, v), by fixed-point steps."""
    nl0 = rot[0] * force[0] + rot[3] * force[1] + rot[6] * force[2]
    nl1 = rot[1] * force[0] + rot[4] * force[1] + rot[7] * force[2]
    nl2 = rot[2] * force[0] + rot[5] * force[1] + rot[8] * force[2]
    w[0], w[1], w[2] = nl0 * p[D_INV_AT], nl1 * p[D_INV_AT + 1], nl2 * p[D_INV_AT + 2]
    if model != DISTRIBUTED:
        return
    sums = np.empty(6)
    for _ in range(6):  # converges by a factor t / EA per step
        _cable_sums(u, w, tensions, routes, active, sums)
        w[0] = (nl0 - sums[3]) * p[D_INV_AT]
        w[1] = (nl1 - sums[4]) * p[D_INV_AT + 1]
        w[2] = (nl2 - sums[5]) * p[D_INV_AT + 2]


@numba.njit(cache=True, nogil=True, fastmath={'contract'})
def integrate_batch(s_grid, params, model, tip_forces, base_bendings, disk_moments, tensions,
                    stage_routes, route_kinks, cable_end_node, section_end_node):
    """Integrate a batch of initial-value problems from base to tip.

    :param s_grid: (N,) node arc lengths, s_grid[0] = 0, s_grid[-1] = rod length (m)
    :param params: rod constants and base pose, from :func:`pack_params`
    :param model: POINT_MOMENT or DISTRIBUTED
    :param tip_forces: (B, 3) tip force F per problem, global frame (N)
    :param base_bendings: (B, 3) u(0) per problem, local frame (1/m)
    :param disk_moments: (B, S, 3) point moment at each section's end disk, local frame (N m)
    :param tensions: (B, n_cables) cable tensions for the distributed model (N)
    :param stage_routes: (3 (N - 1), 6 n_cables) l (m) and l' of every cable at the start,
        middle and end of each interval, local frame (``Routing.stage_routes``); one row
        (1, 6 n_cables) when every cable is straight
    :param route_kinks: (N - 1,) a cable turns where interval i starts (l' jumps): the strain is
        recomputed there
    :param cable_end_node: (n_cables,) node of each cable's end disk
    :param section_end_node: (S,) node of each section's end disk
    :returns: (B, N, 21) states, layout in the module docstring

    The integration loop holds its state in scalars and tuples and passes no array to a helper:
    numba reference-counts every array a call or a view touches (two atomic operations each),
    which was half the time of a step. The strain is algebraic (eqs. 6, 7 inverted) unless a
    tensioned cable of the distributed model passes, which takes :func:`_strain_newton`.
    That strain block is written out three times (node, RK stages, next node) on purpose: an
    ``inline='always'`` helper taking the arrays it needs measured 4.6 -> 6.1 us per kernel
    call (``make bench``, paper rod), its arrays reference-counted again.
    """
    n_batch = base_bendings.shape[0]
    n_nodes = s_grid.shape[0]
    n_cables = cable_end_node.shape[0]
    n_sections = section_end_node.shape[0]
    routed = 1 if stage_routes.shape[0] > 1 else 0  # one row: every cable straight
    length = s_grid[n_nodes - 1]
    states = np.empty((n_batch, n_nodes, STATE_SIZE))
    active = np.zeros(n_cables, dtype=np.bool_)
    vectors = np.empty((3, 3))  # force, u, w of the base (for _base_stretch)
    sums = np.empty(6)
    c_rod = (params[C_AT], params[C_AT + 1], params[C_AT + 2])
    c_inv_rod = (params[C_INV_AT], params[C_INV_AT + 1], params[C_INV_AT + 2])
    c, c_inv = c_rod, c_inv_rod
    # per-interval factors on C and disk weights follow the rod constants when a robot file
    # gives bending_scale or disk_mass (pack_params)
    per_interval = params.shape[0] > PARAMS_SIZE
    inverse_at = PARAMS_SIZE + n_nodes - 1
    weight_at = inverse_at + n_nodes - 1
    d_inv = (params[D_INV_AT], params[D_INV_AT + 1], params[D_INV_AT + 2])
    f_body = (params[BODY_FORCE_AT], params[BODY_FORCE_AT + 1], params[BODY_FORCE_AT + 2])
    q = BASE_ROTATION_AT
    rot0 = (params[q], params[q + 1], params[q + 2], params[q + 3], params[q + 4], params[q + 5],
            params[q + 6], params[q + 7], params[q + 8])
    for b in range(n_batch):
        tens = tensions[b]
        tf0, tf1, tf2 = tip_forces[b, 0], tip_forces[b, 1], tip_forces[b, 2]
        f0, f1, f2 = tf0, tf1, tf2  # the point loads beyond the current interval
        if per_interval:  # eq. 10 with the disks' weight
            f0, f1, f2 = (tf0 + params[weight_at], tf1 + params[weight_at + 1],
                          tf2 + params[weight_at + 2])
        for i in range(3):
            states[b, 0, POSITION_AT + i] = params[BASE_POSITION_AT + i]
            vectors[0, i] = f_body[i] * length  # eq. 10: n(0)
            vectors[1, i] = base_bendings[b, i]
        vectors[0, 0] += f0
        vectors[0, 1] += f1
        vectors[0, 2] += f2
        for i in range(9):
            states[b, 0, ROTATION_AT + i] = rot0[i]
        for j in range(n_cables):
            active[j] = cable_end_node[j] >= 1
        # v(0) for the given u(0) (eq. 10 with the cables' pull); M(0) then follows from u(0)
        _base_stretch(params[BASE_ROTATION_AT:BASE_ROTATION_AT + 9], vectors[0], params, model,
                      tens, stage_routes, active, vectors[1], vectors[2])
        u = (vectors[1, 0], vectors[1, 1], vectors[1, 2])
        w = (vectors[2, 0], vectors[2, 1], vectors[2, 2])
        # M(0) = R(0) (C u(0) + sum t l x tau)
        if per_interval:
            sc = params[PARAMS_SIZE]
            c = (c_rod[0] * sc, c_rod[1] * sc, c_rod[2] * sc)
        ml0, ml1, ml2 = c[0] * u[0], c[1] * u[1], c[2] * u[2]
        if model == DISTRIBUTED:
            _cable_sums(vectors[1], vectors[2], tens, stage_routes, active, sums)
            ml0, ml1, ml2 = ml0 + sums[0], ml1 + sums[1], ml2 + sums[2]
        rot = rot0
        m0 = rot[0] * ml0 + rot[1] * ml1 + rot[2] * ml2
        m1 = rot[3] * ml0 + rot[4] * ml1 + rot[5] * ml2
        m2 = rot[6] * ml0 + rot[7] * ml1 + rot[8] * ml2
        p0, p1, p2 = (states[b, 0, POSITION_AT], states[b, 0, POSITION_AT + 1],
                      states[b, 0, POSITION_AT + 2])
        for i in range(3):
            states[b, 0, STRETCH_AT + i] = w[i]
            states[b, 0, BENDING_AT + i] = u[i]
        states[b, 0, MOMENT_AT], states[b, 0, MOMENT_AT + 1], states[b, 0, MOMENT_AT + 2] = \
            m0, m1, m2
        fresh = True  # u, w hold the strain at the current node for the coming interval
        for node in range(1, n_nodes):
            s0 = s_grid[node - 1]
            h = s_grid[node] - s0
            newton = False  # a tensioned cable of the distributed model passes this interval
            interval = node - 1
            point = 3 * interval if routed else 0  # row of the interval's start in the table
            if per_interval:
                sc, isc = params[PARAMS_SIZE + interval], params[inverse_at + interval]
                c = (c_rod[0] * sc, c_rod[1] * sc, c_rod[2] * sc)
                c_inv = (c_inv_rod[0] * isc, c_inv_rod[1] * isc, c_inv_rod[2] * isc)
                if interval > 0 and sc != params[PARAMS_SIZE + interval - 1]:
                    fresh = False  # C changes at this node: so does the strain
                at = weight_at + 3 * interval
                if interval > 0 and (params[at] != params[at - 3] or params[at + 1]
                                     != params[at - 2] or params[at + 2] != params[at - 1]):
                    fresh = False  # a disk's weight: N jumps at this node (M does not)
                f0, f1, f2 = tf0 + params[at], tf1 + params[at + 1], tf2 + params[at + 2]
            for j in range(n_cables):
                active[j] = cable_end_node[j] >= node
                if model == DISTRIBUTED and active[j] and tens[j] != 0.0:
                    newton = True
            if newton and route_kinks[interval]:
                fresh = False  # a cable turns at this node: the strain jumps here too
            # stage 1 at the node: its own strain when still valid
            n0, n1, n2 = f0 + f_body[0] * (length - s0), f1 + f_body[1] * (length - s0), \
                f2 + f_body[2] * (length - s0)
            if not fresh:
                ml, nl = _to_local(rot, m0, m1, m2), _to_local(rot, n0, n1, n2)
                if newton:
                    u, w = _strain_newton(ml, nl, u, w, c, params, tens, stage_routes, point,
                                          active)
                else:
                    u = (ml[0] * c_inv[0], ml[1] * c_inv[1], ml[2] * c_inv[2])
                    w = (nl[0] * d_inv[0], nl[1] * d_inv[1], nl[2] * d_inv[2])
            xi = (w[0], w[1], w[2] + 1.0, u[0], u[1], u[2])
            k = (h * xi[0], h * xi[1], h * xi[2], h * xi[3], h * xi[4], h * xi[5])
            d0 = rot[0] * xi[0] + rot[1] * xi[1] + rot[2] * xi[2]  # M' = -r' x N, r' = R v
            d1 = rot[3] * xi[0] + rot[4] * xi[1] + rot[5] * xi[2]
            d2 = rot[6] * xi[0] + rot[7] * xi[1] + rot[8] * xi[2]
            km = (-h * (d1 * n2 - d2 * n1), -h * (d2 * n0 - d0 * n2), -h * (d0 * n1 - d1 * n0))
            k_sum, km_sum = k, km
            for stage in range(1, 4):  # RKMK4 stages 2-4: theta = scale k_(stage-1)
                scale = 1.0 if stage == 3 else 0.5
                weight = 1.0 if stage == 3 else 2.0
                theta = (scale * k[0], scale * k[1], scale * k[2], scale * k[3], scale * k[4],
                         scale * k[5])
                a, bb, _ = _exp_coefficients(theta[3] * theta[3] + theta[4] * theta[4]
                                             + theta[5] * theta[5])
                rot_stage = _mul9(rot, _rotation(a, bb, theta[3], theta[4], theta[5]))
                ms0, ms1, ms2 = m0 + scale * km[0], m1 + scale * km[1], m2 + scale * km[2]
                s = s0 + scale * h
                n0, n1, n2 = f0 + f_body[0] * (length - s), f1 + f_body[1] * (length - s), \
                    f2 + f_body[2] * (length - s)
                ml, nl = _to_local(rot_stage, ms0, ms1, ms2), _to_local(rot_stage, n0, n1, n2)
                if newton:
                    u, w = _strain_newton(ml, nl, u, w, c, params, tens, stage_routes,
                                          point + routed * (1 if stage < 3 else 2), active)
                else:
                    u = (ml[0] * c_inv[0], ml[1] * c_inv[1], ml[2] * c_inv[2])
                    w = (nl[0] * d_inv[0], nl[1] * d_inv[1], nl[2] * d_inv[2])
                xi = (w[0], w[1], w[2] + 1.0, u[0], u[1], u[2])
                dk = _dexpinv(theta, xi)
                k = (h * dk[0], h * dk[1], h * dk[2], h * dk[3], h * dk[4], h * dk[5])
                d0 = rot_stage[0] * xi[0] + rot_stage[1] * xi[1] + rot_stage[2] * xi[2]
                d1 = rot_stage[3] * xi[0] + rot_stage[4] * xi[1] + rot_stage[5] * xi[2]
                d2 = rot_stage[6] * xi[0] + rot_stage[7] * xi[1] + rot_stage[8] * xi[2]
                km = (-h * (d1 * n2 - d2 * n1), -h * (d2 * n0 - d0 * n2),
                      -h * (d0 * n1 - d1 * n0))
                k_sum = (k_sum[0] + weight * k[0], k_sum[1] + weight * k[1],
                         k_sum[2] + weight * k[2], k_sum[3] + weight * k[3],
                         k_sum[4] + weight * k[4], k_sum[5] + weight * k[5])
                km_sum = (km_sum[0] + weight * km[0], km_sum[1] + weight * km[1],
                          km_sum[2] + weight * km[2])
            theta = (k_sum[0] * _SIXTH, k_sum[1] * _SIXTH, k_sum[2] * _SIXTH,
                     k_sum[3] * _SIXTH, k_sum[4] * _SIXTH, k_sum[5] * _SIXTH)
            m0 += km_sum[0] * _SIXTH
            m1 += km_sum[1] * _SIXTH
            m2 += km_sum[2] * _SIXTH
            # (r, R) <- (r, R) exp(theta)
            expo, trans = _se3_exp(theta)
            p0, p1, p2 = (p0 + rot[0] * trans[0] + rot[1] * trans[1] + rot[2] * trans[2],
                          p1 + rot[3] * trans[0] + rot[4] * trans[1] + rot[5] * trans[2],
                          p2 + rot[6] * trans[0] + rot[7] * trans[1] + rot[8] * trans[2])
            rot = _mul9(rot, expo)
            s = s_grid[node]
            n0, n1, n2 = f0 + f_body[0] * (length - s), f1 + f_body[1] * (length - s), \
                f2 + f_body[2] * (length - s)
            ml, nl = _to_local(rot, m0, m1, m2), _to_local(rot, n0, n1, n2)
            if newton:
                u, w = _strain_newton(ml, nl, u, w, c, params, tens, stage_routes,
                                      point + 2 * routed, active)
            else:
                u = (ml[0] * c_inv[0], ml[1] * c_inv[1], ml[2] * c_inv[2])
                w = (nl[0] * d_inv[0], nl[1] * d_inv[1], nl[2] * d_inv[2])
            # at an end disk the point moment or the set of cables changes the next strain
            fresh = True
            for sec in range(n_sections):
                if section_end_node[sec] == node:
                    fresh = False
                    if model == POINT_MOMENT:
                        t0, t1, t2 = (disk_moments[b, sec, 0], disk_moments[b, sec, 1],
                                      disk_moments[b, sec, 2])
                        m0 -= rot[0] * t0 + rot[1] * t1 + rot[2] * t2
                        m1 -= rot[3] * t0 + rot[4] * t1 + rot[5] * t2
                        m2 -= rot[6] * t0 + rot[7] * t1 + rot[8] * t2
            states[b, node, POSITION_AT] = p0
            states[b, node, POSITION_AT + 1] = p1
            states[b, node, POSITION_AT + 2] = p2
            for i in range(9):
                states[b, node, ROTATION_AT + i] = rot[i]
            for i in range(3):
                states[b, node, STRETCH_AT + i] = w[i]
                states[b, node, BENDING_AT + i] = u[i]
            states[b, node, MOMENT_AT] = m0
            states[b, node, MOMENT_AT + 1] = m1
            states[b, node, MOMENT_AT + 2] = m2
    return states


@numba.njit(cache=True, nogil=True)
def integrate_passive(s_grid, params, tip_force, base_bending):
    """(N, 21) states of one IVP with no cable load: ``Robot.solve_ivp``'s kernel.

    The same integration as :func:`integrate_batch` with no cables (a passive rod's strain
    neither jumps at an end disk nor meets a cable); four arguments and (3,) vectors instead of
    eleven and batches of one: ~0.7 us less per call, a fifth of a single-section IVP.
    Non-finite inputs give no states (0 rows): the caller says which.
    """
    for i in range(3):
        if not (math.isfinite(tip_force[i]) and math.isfinite(base_bending[i])):
            return np.empty((0, STATE_SIZE))
    # np.int64: a bare constant is typed Literal[int](0), a second specialisation of
    # integrate_batch (~3 s CPU more of cold compile); one signature per kernel (warmup.py)
    states = integrate_batch(s_grid, params, np.int64(POINT_MOMENT), tip_force.reshape((1, 3)),
                             base_bending.reshape((1, 3)), np.zeros((1, 0, 3)), np.zeros((1, 0)),
                             np.zeros((1, 0)), np.zeros(s_grid.shape[0] - 1, dtype=np.bool_),
                             np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))
    return states[0]


@numba.njit(cache=True, nogil=True)
def cable_lengths_batch(states, guide_nodes, hole_offsets, cable_last_guide):
    """Cable lengths (B, n_cables) of a batch of shapes (paper eq. 11, errata applied).

    A cable runs through its hole at every guide node from the base disk (guide 0, node 0) up to
    and including its end disk ``guide_nodes[cable_last_guide[j]]``: its length is the sum of the
    straight distances between consecutive holes. ``hole_offsets`` (n_cables, G, 3) are the
    holes in the rod's local frame at each guide (m, ``Routing.hole_offsets``).
    """
    n_batch = states.shape[0]
    n_cables = hole_offsets.shape[0]
    lengths = np.zeros((n_batch, n_cables))
    for b in range(n_batch):
        for j in range(n_cables):
            x0, x1, x2 = hole_in(states[b, guide_nodes[0]], hole_offsets[j, 0])
            for g in range(1, cable_last_guide[j] + 1):
                h0, h1, h2 = hole_in(states[b, guide_nodes[g]], hole_offsets[j, g])
                lengths[b, j] += math.sqrt((h0 - x0) ** 2 + (h1 - x1) ** 2 + (h2 - x2) ** 2)
                x0, x1, x2 = h0, h1, h2
    return lengths


@numba.njit(cache=True, nogil=True)
def section_tensions(moment, cables, offsets, out):
    """Least-norm tensions t >= 0 of one section's cables whose moments sum to ``moment``.

    The moment a cable applies is t (e3 x l) (local, in the cross-section plane); antagonistic
    cables stay slack. Enumerates the supports: the optimum is the least-norm solution on its own
    support, so the smallest feasible candidate is it. ``cables`` indexes ``offsets``; writes
    ``out[cables]``. A moment no combination can apply gets the best clipped candidate.
    """
    n = cables.shape[0]
    for j in range(n):
        out[cables[j]] = 0.0
    b0, b1 = moment[0], moment[1]
    if n == 0 or (b0 == 0.0 and b1 == 0.0):
        return
    best, best_miss = 1e300, 1e300
    best_mask = 0
    best_l0, best_l1 = 0.0, 0.0
    scale = 0.0
    for j in range(n):
        scale = max(scale, offsets[cables[j], 0] ** 2 + offsets[cables[j], 1] ** 2)
    for mask in range(1, 1 << n):
        # Gram matrix of the arms a_j = e3 x l_j = (-l_y, l_x) on this support
        g00 = g01 = g11 = 0.0
        for j in range(n):
            if mask & (1 << j):
                a0, a1 = -offsets[cables[j], 1], offsets[cables[j], 0]
                g00 += a0 * a0
                g01 += a0 * a1
                g11 += a1 * a1
        det = g00 * g11 - g01 * g01
        if det > 1e-12 * scale * scale:
            l0 = (g11 * b0 - g01 * b1) / det
            l1 = (g00 * b1 - g01 * b0) / det
        else:  # arms in line: least-norm on their common direction
            l0 = b0 / max(g00 + g11, 1e-300)
            l1 = b1 / max(g00 + g11, 1e-300)
        norm, miss, feasible = 0.0, 0.0, True
        m0 = m1 = 0.0
        for j in range(n):
            if mask & (1 << j):
                a0, a1 = -offsets[cables[j], 1], offsets[cables[j], 0]
                t = a0 * l0 + a1 * l1
                if t < 0.0:
                    feasible = False
                    t = 0.0
                norm += t * t
                m0 += t * a0
                m1 += t * a1
        miss = (m0 - b0) ** 2 + (m1 - b1) ** 2
        tol = 1e-20 * (b0 * b0 + b1 * b1)
        if feasible and miss <= tol:
            miss = 0.0
        if miss < best_miss - tol or (miss <= best_miss + tol and norm < best):
            best, best_miss, best_mask = norm, miss, mask
            best_l0, best_l1 = l0, l1
    for j in range(n):
        if best_mask & (1 << j):
            a0, a1 = -offsets[cables[j], 1], offsets[cables[j], 0]
            out[cables[j]] = max(0.0, a0 * best_l0 + a1 * best_l1)


@numba.njit(cache=True, nogil=True)
def loads_from_state(x, fixed_tensions, model, bases, ranks, bending_stiffness, section_cables,
                     section_cable_count, offsets, disk_moments, tensions):
    """Section point moments and cable tensions of one solver state (in place).

    ``x`` = [u(0) (3); per section, the coordinates of the section's cable moment in its basis
    ``bases[k]`` (3, 2 local; ``ranks[k]`` columns used), in units of E I (1/m)].
    ``fixed_tensions`` (measured or commanded, N) add to the tensions the moments imply.
    """
    n_sections = bases.shape[0]
    n_cables = offsets.shape[0]
    moment = np.empty(3)
    col = 3
    for j in range(n_cables):
        tensions[j] = 0.0
    for k in range(n_sections):
        for i in range(3):
            moment[i] = 0.0
            for c in range(ranks[k]):
                moment[i] += bases[k, i, c] * x[col + c] * bending_stiffness
        col += ranks[k]
        cables = section_cables[k, :section_cable_count[k]]
        if model == DISTRIBUTED:
            if ranks[k] > 0:
                section_tensions(moment, cables, offsets, tensions)
            for i in range(3):
                disk_moments[k, i] = 0.0
        else:
            for i in range(3):
                disk_moments[k, i] = moment[i]
            for j in cables:  # t (e3 x l)
                t = fixed_tensions[j]
                disk_moments[k, 0] -= t * offsets[j, 1]
                disk_moments[k, 1] += t * offsets[j, 0]
    for j in range(n_cables):
        tensions[j] += fixed_tensions[j]


@numba.njit(cache=True, nogil=True, inline='always')
def batch_loads(model, x, fixed_tensions, tip_force, b, forces, bendings, moments, tensions):
    """Fill row ``b`` of a batch's loads with those of solver state ``x`` (N, N m, 1/m)."""
    loads_from_state(x, fixed_tensions, model.code, model.section_bases, model.section_ranks,
                     model.params[C_AT], model.section_cables, model.section_cable_count,
                     model.cable_offsets, moments[b], tensions[b])
    for i in range(3):
        forces[b, i] = tip_force[i]
        bendings[b, i] = x[i]


@numba.njit(cache=True, nogil=True, inline='always')
def integrate_with_lengths(model, forces, bendings, moments, tensions):
    """(B, N, 21) states and (B, n_cables) cable lengths (m) of a batch of a robot's IVPs."""
    states = integrate_batch(model.s_grid, model.params, model.code, forces, bendings, moments,
                             tensions, model.stage_routes, model.route_kinks,
                             model.cable_end_node, model.section_end_node)
    return states, cable_lengths_batch(states, model.guide_nodes, model.hole_offsets,
                                       model.cable_last_guide)


@numba.njit(cache=True, nogil=True)
def probe(model, tip_force, tip_moment, fixed_tensions, x, n_free):
    """Model outputs at a solver state and their forward-difference Jacobian.

    ``model`` is the robot's :class:`~continuum_statics.core.description.layout.KernelModel`.
    Integrates
    ``x`` and ``x + model.step e_k`` for the first ``n_free`` components in one batch (columns
    of point moments at the tip are exact and need no integration) and returns a
    :class:`~continuum_statics.core.description.layout.Probe`: values = [tip position (3, m); tip
    z axis
    (3); cable lengths (n_cables, m); (M_end - tau) L / (E I) (3), the tip moment balance, zero
    at equilibrium] (rows :class:`~continuum_statics.core.description.layout.ProbeRows`), their
    Jacobian
    (n_free columns) and the nominal (N, 21) states. ``model.section_state_index`` = [index of
    the first moment coordinate of each section, or -1] (sections ending at the tip node have
    exact columns in the point model).
    """
    s_grid, params, code, step = model.s_grid, model.params, model.code, model.step
    section_state_index, section_bases = model.section_state_index, model.section_bases
    section_ranks, section_end_node = model.section_ranks, model.section_end_node
    cable_offsets = model.cable_offsets
    n_x = x.shape[0]
    n_cables = cable_offsets.shape[0]
    n_sections = section_bases.shape[0]
    n_nodes = s_grid.shape[0]
    length = s_grid[n_nodes - 1]
    ei = params[C_AT]
    exact = np.zeros(n_x, dtype=np.bool_)
    if code == POINT_MOMENT:
        for k in range(n_sections):
            if section_end_node[k] == n_nodes - 1 and section_state_index[k] >= 0:
                for c in range(section_ranks[k]):
                    exact[section_state_index[k] + c] = True
    columns = np.full(n_free + 1, -1, dtype=np.int64)
    n_batch = 1
    for col in range(n_free):
        if not exact[col]:
            columns[n_batch] = col
            n_batch += 1
    forces = np.empty((n_batch, 3))
    bendings = np.empty((n_batch, 3))
    moments = np.empty((n_batch, n_sections, 3))
    tensions = np.empty((n_batch, n_cables))
    trial = np.empty(n_x)
    for b in range(n_batch):
        for i in range(n_x):
            trial[i] = x[i]
        if columns[b] >= 0:
            trial[columns[b]] += step
        batch_loads(model, trial, fixed_tensions, tip_force, b, forces, bendings, moments,
                    tensions)
    states, lengths = integrate_with_lengths(model, forces, bendings, moments, tensions)
    balance_at = LENGTH_ROWS_AT + n_cables
    rows = balance_at + 3
    table = np.empty((n_batch, rows))
    scale = length / ei
    for b in range(n_batch):
        tip = states[b, n_nodes - 1]
        for i in range(3):
            table[b, TIP_ROWS_AT + i] = tip[POSITION_AT + i]
            table[b, AXIS_ROWS_AT + i] = tip[ROTATION_AT + 2 + 3 * i]  # column 2 of R
            table[b, balance_at + i] = (tip[MOMENT_AT + i] - tip_moment[i]) * scale
        for j in range(n_cables):
            table[b, LENGTH_ROWS_AT + j] = lengths[b, j]
    values = table[0].copy()
    jacobian = np.zeros((rows, n_free))
    for b in range(1, n_batch):
        col = columns[b]
        for r in range(rows):
            jacobian[r, col] = (table[b, r] - table[0, r]) / step
    # exact columns: a point moment B c E I at the tip only moves M_end by -R(L) B c E I
    tip = states[0, n_nodes - 1]
    for k in range(n_sections):
        if (code != POINT_MOMENT or section_end_node[k] != n_nodes - 1
                or section_state_index[k] < 0):
            continue
        for c in range(section_ranks[k]):
            col = section_state_index[k] + c
            if col >= n_free:
                continue
            for i in range(3):
                g = (tip[ROTATION_AT + 3 * i] * section_bases[k, 0, c]
                     + tip[ROTATION_AT + 1 + 3 * i] * section_bases[k, 1, c]
                     + tip[ROTATION_AT + 2 + 3 * i] * section_bases[k, 2, c])
                jacobian[balance_at + i, col] = -g * ei * scale
    return Probe(values, jacobian, states[0].copy())


@numba.njit(cache=True, nogil=True)
def tip_jacobian(model, tip_force, base_bending, disk_moments, tensions, force_step,
                 bending_step):
    """6x6 tip Jacobian by forward differences (paper sec. V.B) from one batch of 7 IVPs.

    Rows: tip position (m) then tip rotation angle (rad), from vee(dR R^T), the paper's
    omega-hat = R-dot R^T; columns: tip force F (N) then u(0) (1/m); cable loads held fixed.
    """
    forces = np.empty((7, 3))
    bendings = np.empty((7, 3))
    moments = np.empty((7, disk_moments.shape[0], 3))
    tens = np.empty((7, tensions.shape[0]))
    for b in range(7):
        for i in range(3):
            forces[b, i] = tip_force[i]
            bendings[b, i] = base_bending[i]
        moments[b] = disk_moments
        tens[b] = tensions
    for k in range(3):
        forces[1 + k, k] += force_step
        bendings[4 + k, k] += bending_step
    states = integrate_batch(model.s_grid, model.params, model.code, forces, bendings, moments,
                             tens, model.stage_routes, model.route_kinks, model.cable_end_node,
                             model.section_end_node)
    tip = states.shape[1] - 1
    jac = np.empty((6, 6))
    w = np.empty((3, 3))
    for col in range(6):
        b = col + 1
        h = force_step if col < 3 else bending_step
        for i in range(3):
            jac[i, col] = (states[b, tip, POSITION_AT + i] - states[0, tip, POSITION_AT + i]) / h
        for i in range(3):
            for j in range(3):
                acc = 0.0
                for k in range(3):
                    acc += ((states[b, tip, ROTATION_AT + 3 * i + k]
                             - states[0, tip, ROTATION_AT + 3 * i + k])
                            * states[0, tip, ROTATION_AT + 3 * j + k])
                w[i, j] = acc / h
        jac[3, col] = 0.5 * (w[2, 1] - w[1, 2])
        jac[4, col] = 0.5 * (w[0, 2] - w[2, 0])
        jac[5, col] = 0.5 * (w[1, 0] - w[0, 1])
    return jac
