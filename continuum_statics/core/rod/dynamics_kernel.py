"""Compiled time step of the Cosserat rod in motion (Till, Aloi & Rucker, IJRR 38(6), 2019).

State along the unstretched arc length s (m), SI units, per node (:mod:`layout`'s
``DYNAMIC_STATE`` = 24, in this order; the compiled loops index it by its ``DYN_*_AT`` names):
  p (3)      position, global                         p_s = R v                       (eq. 7)
  R (9)      orientation, row-major, local -> global  R_s = R hat(u)
  n (3)      internal force, global                   n_s = rho A R (w x q + q_t) - f
  m (3)      internal moment, global                  m_s = R (w x rho J w + rho J w_t) - p_s x n
  q (3)      linear velocity, local                   q_s = v_t - u x q + w x v
  w (3)      angular velocity, local                  w_s = u_t - u x w
with the Kelvin-Voigt laws (Till eq. 3, 4; the paper's eqs. 6, 7 plus damping)
  R^T n = K_se (v - e3) + B_se v_t,   R^T m = K_bt u + B_bt u_t
and every time derivative by BDF-alpha (Till eq. 13): y_t = c0 y + y_h, the history y_h from the
two steps before (:mod:`continuum_statics.core.dynamics.rod_dynamics`). The strains are therefore
algebraic:
  v = (K_se + c0 B_se)^-1 (R^T n + K_se e3 - B_se v_h)
  u = (K_bt + c0 B_bt)^-1 (R^T m - B_bt u_h).

A step is a shooting problem in the base's n(0), m(0) (p, R, q = w = 0 fixed at the base): the
tip must carry the tip load, n(L) = F and m(L) = M. Point loads at the nodes make n and m jump:
the weight and inertia of guide disks, m_d (g - R (q_t + w x q)), and the point-moment cable
model's pull on each section's end disk, t_j R (e3 x l_j) (the paper; internal forces cancel).

The spatial integration is classical RK4 on all 24 values, each of its stages with its own
history (Till et al. keep one per grid point of their scheme likewise). Newton's
method on the six unknowns reuses the last step's Jacobian (chord steps) and refreshes it by
forward differences only when a chord step does not reduce the residual.
"""
import numba
import numpy as np

from continuum_statics.core.description.layout import (
    DYN_ANGULAR_AT,
    DYN_B_BT_AT,
    DYN_B_SE_AT,
    DYN_BASE_POSITION_AT,
    DYN_BASE_ROTATION_AT,
    DYN_FORCE_AT,
    DYN_GRAVITY_AT,
    DYN_HIST_ANGULAR_AT,
    DYN_HIST_BENDING_AT,
    DYN_HIST_STRETCH_AT,
    DYN_HIST_VELOCITY_AT,
    DYN_K_BT_AT,
    DYN_K_SE_AT,
    DYN_MASS_AT,
    DYN_MOMENT_AT,
    DYN_POSITION_AT,
    DYN_RHO_J_AT,
    DYN_ROTATION_AT,
    DYN_VELOCITY_AT,
    DYNAMIC_STATE,
)
from continuum_statics.core.rod.tendon_kernel import path_stretch

_SIXTH = 1.0 / 6.0
HALVINGS = 12  # of a fresh Newton step at most


@numba.njit(cache=True, nogil=True)
def _derivative(y, hist, c0, params, scale, out, values):
    """Write y_s of one state ``y`` (24,) with history ``hist`` (12,) into ``out`` (24,).

    ``values`` (12,) receives v, u, q, w there: the next step's history at this point.
    """
    r00, r01, r02 = y[DYN_ROTATION_AT], y[DYN_ROTATION_AT + 1], y[DYN_ROTATION_AT + 2]
    r10, r11, r12 = y[DYN_ROTATION_AT + 3], y[DYN_ROTATION_AT + 4], y[DYN_ROTATION_AT + 5]
    r20, r21, r22 = y[DYN_ROTATION_AT + 6], y[DYN_ROTATION_AT + 7], y[DYN_ROTATION_AT + 8]
    n0, n1, n2 = y[DYN_FORCE_AT], y[DYN_FORCE_AT + 1], y[DYN_FORCE_AT + 2]
    m0, m1, m2 = y[DYN_MOMENT_AT], y[DYN_MOMENT_AT + 1], y[DYN_MOMENT_AT + 2]
    q0, q1, q2 = y[DYN_VELOCITY_AT], y[DYN_VELOCITY_AT + 1], y[DYN_VELOCITY_AT + 2]
    w0, w1, w2 = y[DYN_ANGULAR_AT], y[DYN_ANGULAR_AT + 1], y[DYN_ANGULAR_AT + 2]
    # R^T n, R^T m (local)
    ln0 = r00 * n0 + r10 * n1 + r20 * n2
    ln1 = r01 * n0 + r11 * n1 + r21 * n2
    ln2 = r02 * n0 + r12 * n1 + r22 * n2
    lm0 = r00 * m0 + r10 * m1 + r20 * m2
    lm1 = r01 * m0 + r11 * m1 + r21 * m2
    lm2 = r02 * m0 + r12 * m1 + r22 * m2
    ks, bs = DYN_K_SE_AT, DYN_B_SE_AT
    kb, bb = DYN_K_BT_AT, DYN_B_BT_AT
    # the history's blocks, and the same blocks of ``values``
    hv, hu, hq, hw = (DYN_HIST_STRETCH_AT, DYN_HIST_BENDING_AT, DYN_HIST_VELOCITY_AT,
                      DYN_HIST_ANGULAR_AT)
    v0 = (ln0 - params[bs] * hist[hv]) / (params[ks] + c0 * params[bs])
    v1 = (ln1 - params[bs + 1] * hist[hv + 1]) / (params[ks + 1] + c0 * params[bs + 1])
    v2 = (ln2 + params[ks + 2] - params[bs + 2] * hist[hv + 2]) / (params[ks + 2]
                                                                    + c0 * params[bs + 2])
    u0 = (lm0 - scale * params[bb] * hist[hu]) / (scale * (params[kb] + c0 * params[bb]))
    u1 = (lm1 - scale * params[bb + 1] * hist[hu + 1]) / (scale * (params[kb + 1]
                                                                   + c0 * params[bb + 1]))
    u2 = (lm2 - scale * params[bb + 2] * hist[hu + 2]) / (scale * (params[kb + 2]
                                                                   + c0 * params[bb + 2]))
    values[hv], values[hv + 1], values[hv + 2] = v0, v1, v2
    values[hu], values[hu + 1], values[hu + 2] = u0, u1, u2
    values[hq], values[hq + 1], values[hq + 2] = q0, q1, q2
    values[hw], values[hw + 1], values[hw + 2] = w0, w1, w2
    vt0, vt1, vt2 = c0 * v0 + hist[hv], c0 * v1 + hist[hv + 1], c0 * v2 + hist[hv + 2]
    ut0, ut1, ut2 = c0 * u0 + hist[hu], c0 * u1 + hist[hu + 1], c0 * u2 + hist[hu + 2]
    qt0, qt1, qt2 = c0 * q0 + hist[hq], c0 * q1 + hist[hq + 1], c0 * q2 + hist[hq + 2]
    wt0, wt1, wt2 = c0 * w0 + hist[hw], c0 * w1 + hist[hw + 1], c0 * w2 + hist[hw + 2]
    # p_s = R v
    ps0 = r00 * v0 + r01 * v1 + r02 * v2
    ps1 = r10 * v0 + r11 * v1 + r12 * v2
    ps2 = r20 * v0 + r21 * v1 + r22 * v2
    out[DYN_POSITION_AT], out[DYN_POSITION_AT + 1], out[DYN_POSITION_AT + 2] = ps0, ps1, ps2
    # R_s = R hat(u): row i of R times hat(u)
    out[DYN_ROTATION_AT] = r01 * u2 - r02 * u1
    out[DYN_ROTATION_AT + 1] = r02 * u0 - r00 * u2
    out[DYN_ROTATION_AT + 2] = r00 * u1 - r01 * u0
    out[DYN_ROTATION_AT + 3] = r11 * u2 - r12 * u1
    out[DYN_ROTATION_AT + 4] = r12 * u0 - r10 * u2
    out[DYN_ROTATION_AT + 5] = r10 * u1 - r11 * u0
    out[DYN_ROTATION_AT + 6] = r21 * u2 - r22 * u1
    out[DYN_ROTATION_AT + 7] = r22 * u0 - r20 * u2
    out[DYN_ROTATION_AT + 8] = r20 * u1 - r21 * u0
    # n_s = rho A R (w x q + q_t) - rho A g
    rho_a = params[DYN_MASS_AT]
    a0 = w1 * q2 - w2 * q1 + qt0
    a1 = w2 * q0 - w0 * q2 + qt1
    a2 = w0 * q1 - w1 * q0 + qt2
    g = DYN_GRAVITY_AT
    out[DYN_FORCE_AT] = rho_a * (r00 * a0 + r01 * a1 + r02 * a2 - params[g])
    out[DYN_FORCE_AT + 1] = rho_a * (r10 * a0 + r11 * a1 + r12 * a2 - params[g + 1])
    out[DYN_FORCE_AT + 2] = rho_a * (r20 * a0 + r21 * a1 + r22 * a2 - params[g + 2])
    # m_s = R (w x rho J w + rho J w_t) - p_s x n
    j0, j1, j2 = params[DYN_RHO_J_AT], params[DYN_RHO_J_AT + 1], params[DYN_RHO_J_AT + 2]
    h0, h1, h2 = j0 * w0, j1 * w1, j2 * w2
    b0 = w1 * h2 - w2 * h1 + j0 * wt0
    b1 = w2 * h0 - w0 * h2 + j1 * wt1
    b2 = w0 * h1 - w1 * h0 + j2 * wt2
    out[DYN_MOMENT_AT] = r00 * b0 + r01 * b1 + r02 * b2 - (ps1 * n2 - ps2 * n1)
    out[DYN_MOMENT_AT + 1] = r10 * b0 + r11 * b1 + r12 * b2 - (ps2 * n0 - ps0 * n2)
    out[DYN_MOMENT_AT + 2] = r20 * b0 + r21 * b1 + r22 * b2 - (ps0 * n1 - ps1 * n0)
    # q_s = v_t - u x q + w x v;  w_s = u_t - u x w
    out[DYN_VELOCITY_AT] = vt0 - (u1 * q2 - u2 * q1) + (w1 * v2 - w2 * v1)
    out[DYN_VELOCITY_AT + 1] = vt1 - (u2 * q0 - u0 * q2) + (w2 * v0 - w0 * v2)
    out[DYN_VELOCITY_AT + 2] = vt2 - (u0 * q1 - u1 * q0) + (w0 * v1 - w1 * v0)
    out[DYN_ANGULAR_AT] = ut0 - (u1 * w2 - u2 * w1)
    out[DYN_ANGULAR_AT + 1] = ut1 - (u2 * w0 - u0 * w2)
    out[DYN_ANGULAR_AT + 2] = ut2 - (u0 * w1 - u1 * w0)


@numba.njit(cache=True, nogil=True)
def _point_loads(y, hist, c0, node, disk_mass, params, tensions, cable_offsets, cable_end_node):
    """Apply the jumps of n and m at ``node``: disk weight and inertia, cables ending there."""
    mass = disk_mass[node]
    if mass > 0.0:  # external force m_d (g - a), a = R (q_t + w x q); n(s+) = n(s-) - it
        q0, q1, q2 = y[DYN_VELOCITY_AT], y[DYN_VELOCITY_AT + 1], y[DYN_VELOCITY_AT + 2]
        w0, w1, w2 = y[DYN_ANGULAR_AT], y[DYN_ANGULAR_AT + 1], y[DYN_ANGULAR_AT + 2]
        hq = DYN_HIST_VELOCITY_AT
        a0 = w1 * q2 - w2 * q1 + c0 * q0 + hist[hq]
        a1 = w2 * q0 - w0 * q2 + c0 * q1 + hist[hq + 1]
        a2 = w0 * q1 - w1 * q0 + c0 * q2 + hist[hq + 2]
        g = DYN_GRAVITY_AT
        for i in range(3):
            row = DYN_ROTATION_AT + 3 * i
            acc = y[row] * a0 + y[row + 1] * a1 + y[row + 2] * a2
            y[DYN_FORCE_AT + i] -= mass * (params[g + i] - acc)
    for j in range(cable_end_node.shape[0]):
        t = tensions[j]
        if cable_end_node[j] != node or t == 0.0:
            continue
        # t R (e3 x l): e3 x l = (-l1, l0, 0)
        x0, x1 = -t * cable_offsets[j, 1], t * cable_offsets[j, 0]
        for i in range(3):
            row = DYN_ROTATION_AT + 3 * i
            y[DYN_MOMENT_AT + i] -= y[row] * x0 + y[row + 1] * x1


@numba.njit(cache=True, nogil=True)
def _segment(model, c0, history, start, k0, k1, tensions, states, left, stages, work):
    """Integrate nodes ``k0`` -> ``k1`` from ``start`` (24,), the state just past node ``k0``.

    Writes ``states``, ``left`` and ``stages`` of those nodes and intervals (the rows of the
    whole rod's arrays); ``work`` (6, 24) is scratch, its row 0 the state at ``k1`` after.
    """
    s_grid, params, disk_mass = model.s_grid, model.params, model.disk_mass
    bending_scale, cable_offsets, cable_end_node = (model.bending_scale, model.cable_offsets,
                                                    model.cable_end_node)
    y, d1, d2, d3, d4, tmp = work[0], work[1], work[2], work[3], work[4], work[5]
    for i in range(DYNAMIC_STATE):
        y[i] = start[i]
    states[k0, :] = y
    if k0 == 0:
        for i in range(6):  # n, m
            left[0, i] = y[DYN_FORCE_AT + i]
    for k in range(k0, k1):
        h = s_grid[k + 1] - s_grid[k]
        scale = bending_scale[k]
        _derivative(y, history[k, 0], c0, params, scale, d1, stages[k, 0])
        for i in range(DYNAMIC_STATE):
            tmp[i] = y[i] + 0.5 * h * d1[i]
        _derivative(tmp, history[k, 1], c0, params, scale, d2, stages[k, 1])
        for i in range(DYNAMIC_STATE):
            tmp[i] = y[i] + 0.5 * h * d2[i]
        _derivative(tmp, history[k, 2], c0, params, scale, d3, stages[k, 2])
        for i in range(DYNAMIC_STATE):
            tmp[i] = y[i] + h * d3[i]
        _derivative(tmp, history[k, 3], c0, params, scale, d4, stages[k, 3])
        for i in range(DYNAMIC_STATE):
            y[i] += h * _SIXTH * (d1[i] + 2.0 * (d2[i] + d3[i]) + d4[i])
        for i in range(6):
            left[k + 1, i] = y[DYN_FORCE_AT + i]
        _point_loads(y, history[k, 3], c0, k + 1, disk_mass, params, tensions,
                     cable_offsets, cable_end_node)
        states[k + 1, :] = y


@numba.njit(cache=True, nogil=True)
def _start_of(model, x, j, bounds, out):
    """Write segment ``j``'s start state (24,) from the unknowns ``x`` into ``out``."""
    if j == 0:  # the base: p, R fixed, q = w = 0; n(0), m(0) unknown
        params = model.params
        for i in range(3):
            out[DYN_POSITION_AT + i] = params[DYN_BASE_POSITION_AT + i]
        for i in range(9):
            out[DYN_ROTATION_AT + i] = params[DYN_BASE_ROTATION_AT + i]
        for i in range(6):
            out[DYN_FORCE_AT + i] = x[i]  # n, m
            out[DYN_VELOCITY_AT + i] = 0.0  # q, w
    else:
        at = 6 + DYNAMIC_STATE * (j - 1)
        for i in range(DYNAMIC_STATE):
            out[i] = x[at + i]


@numba.njit(cache=True, nogil=True)
def _segment_residual(model, j, bounds, x, end, tip, out):
    """Write the residual block that segment ``j``'s end state ``end`` (24,) meets into ``out``.

    Continuity with the next segment's start (24 values, each divided by its scale), or at the
    tip n(L) - F, m(L) - M (6).
    """
    scales = model.scales
    n_segments = bounds.shape[0] - 1
    if j == n_segments - 1:
        at = DYNAMIC_STATE * (n_segments - 1)
        for i in range(6):
            out[at + i] = (end[DYN_FORCE_AT + i] - tip[i]) / scales[DYN_FORCE_AT + i]
    else:
        at = DYNAMIC_STATE * j
        start = 6 + DYNAMIC_STATE * j
        for i in range(DYNAMIC_STATE):
            out[at + i] = (end[i] - x[start + i]) / scales[i]


@numba.njit(cache=True, nogil=True)
def shoot(model, c0, history, x, tensions, tip, states, left, stages, work, residual):
    """Integrate every segment from its start in ``x`` and write the ``residual``.

    Multiple shooting (the rod split at the nodes ``bounds``): ``x`` holds n(0), m(0) (6) and
    the full state (24) at the start of each segment after the first; the residual is each
    segment's mismatch with the next (24) and the tip's load balance (6). One segment is the
    statics' single shooting; more keep the growth of a perturbation along a segment small
    (it grows like exp(s (rho A c0^2 / E I)^(1/4)) in the time-discretised equations).

    :param model: the robot's :class:`~continuum_statics.core.description.layout.DynamicsModel`
    :param history: (N - 1, 4, 12) v_h, u_h, q_h, w_h at each interval's four RK4 stages
        (``DYN_HISTORY_SIZE``): every point the equations are evaluated at keeps its own
        history, so BDF-alpha applies to the discrete system exactly (a history interpolated
        between nodes gained 30 % of energy per second with the trapezoidal rule)
    :param tensions: (n_cables,) N
    :param tip: (6,) F (N), M (N m), global
    :param left: (N, 6) out: n, m on the base side of each node (``states`` holds the tip side)
    :param stages: (N - 1, 4, 12) out: v, u, q, w at each stage (the next history's values)
    :param work: (7, 24) scratch
    """
    start, bounds = work[6], model.bounds
    for j in range(bounds.shape[0] - 1):
        _start_of(model, x, j, bounds, start)
        _segment(model, c0, history, start, bounds[j], bounds[j + 1], tensions, states, left,
                 stages, work[:6])
        _segment_residual(model, j, bounds, x, work[0], tip, residual)


@numba.njit(cache=True, nogil=True)
def _lu_factor(a, pivots):
    """Factor ``a`` (M, M) in place as P A = L U with partial pivoting; False if singular."""
    m = a.shape[0]
    for k in range(m):
        p = k
        big = abs(a[k, k])
        for i in range(k + 1, m):
            if abs(a[i, k]) > big:
                big, p = abs(a[i, k]), i
        if big == 0.0 or not np.isfinite(big):
            return False
        pivots[k] = p
        if p != k:
            for j in range(m):
                a[k, j], a[p, j] = a[p, j], a[k, j]
        inverse = 1.0 / a[k, k]
        for i in range(k + 1, m):
            factor = a[i, k] * inverse
            a[i, k] = factor
            if factor != 0.0:
                for j in range(k + 1, m):
                    a[i, j] -= factor * a[k, j]
    return True


@numba.njit(cache=True, nogil=True)
def _lu_solve(lu, pivots, b, out):
    """Solve A out = b with the factors of :func:`_lu_factor`."""
    m = lu.shape[0]
    for i in range(m):
        out[i] = b[i]
    for k in range(m):
        p = pivots[k]
        if p != k:
            out[k], out[p] = out[p], out[k]
    for i in range(m):
        total = out[i]
        for j in range(i):
            total -= lu[i, j] * out[j]
        out[i] = total
    for i in range(m - 1, -1, -1):
        total = out[i]
        for j in range(i + 1, m):
            total -= lu[i, j] * out[j]
        out[i] = total / lu[i, i]


@numba.njit(cache=True, nogil=True)
def _cable_rows(model, states, x, cables, work, residual):
    """Write the cables' rows of a length-driven step: min(kappa t, free - consumed) / radius.

    The semismooth form of R&W 2011's length constraint with slack (as the statics',
    ``length_statics``): a taut cable's path, stretched by its tension with capstan friction
    (``tendon_kernel.path_stretch``), takes its free length; a slack one carries nothing.
    """
    first = x.shape[0] - cables.free.shape[0]
    tensions = x[first:]
    consumed, motor, mean = work
    path_stretch(states, model.guide_nodes, model.cable_last_guide, model.hole_offsets,
                 model.base_axis, tensions, cables.friction, model.compliance, consumed, motor,
                 mean)
    for j in range(tensions.shape[0]):
        residual[first + j] = min(model.kappa * tensions[j],
                                  cables.free[j] - consumed[j]) / model.radius


@numba.njit(cache=True, nogil=True)
def _evaluate(model, c0, history, x, cables, tip, states, left, stages, work, cable_work,
              residual):
    """Write the whole residual at ``x``: the segments, the tip and (driven by lengths) cables."""
    n_free = cables.free.shape[0]
    tensions = x[x.shape[0] - n_free:] if n_free else cables.tensions
    shoot(model, c0, history, x, tensions, tip, states, left, stages, work, residual)
    if n_free:
        _cable_rows(model, states, x, cables, cable_work, residual)


@numba.njit(cache=True, nogil=True)
def _refresh(model, c0, history, x, cables, tip, residual, jacobian, nominal, scratch):
    """Forward differences of the residual in each unknown.

    A segment's unknowns rerun that segment alone (the others keep ``nominal`` = (states, left,
    stages) of ``x``); a tension reruns the whole rod.
    """
    states, left, stages, work = scratch[0], scratch[1], scratch[2], scratch[3]
    trial, cable_work = scratch[4], scratch[5]
    bounds = model.bounds
    n_unknowns = x.shape[0]
    n_free = cables.free.shape[0]
    tensions = x[n_unknowns - n_free:] if n_free else cables.tensions
    column = np.empty(n_unknowns)
    states[:, :] = nominal[0]
    for j in range(bounds.shape[0] - 1):
        first = 0 if j == 0 else 6 + DYNAMIC_STATE * (j - 1)
        count = 6 if j == 0 else DYNAMIC_STATE
        k0, k1 = bounds[j], bounds[j + 1]
        for c in range(first, first + count):
            scale = model.scales[DYN_FORCE_AT + c] if j == 0 else model.scales[c - first]
            delta = 1e-7 * scale
            for i in range(n_unknowns):
                trial[i] = x[i]
            trial[c] += delta
            _start_of(model, trial, j, bounds, work[6])
            _segment(model, c0, history, work[6], k0, k1, tensions, states, left, stages,
                     work[:6])
            for i in range(n_unknowns):
                column[i] = residual[i]
            _segment_residual(model, j, bounds, trial, work[0], tip, column)
            # the perturbed unknown also enters the previous segment's continuity block
            if j > 0:
                row = DYNAMIC_STATE * (j - 1) + (c - first)
                column[row] = residual[row] - delta / model.scales[c - first]
            if n_free:  # the cables see the rod as a full shoot would: the next start at k1
                if j < bounds.shape[0] - 2:
                    states[k1, :] = nominal[0][k1]
                _cable_rows(model, states, trial, cables, cable_work, column)
            for i in range(n_unknowns):
                jacobian[i, c] = (column[i] - residual[i]) / delta
            for k in range(k0, k1 + 1):
                states[k, :] = nominal[0][k]
    for c in range(n_unknowns - n_free, n_unknowns):
        delta = 1e-7 * model.tension_scale
        for i in range(n_unknowns):
            trial[i] = x[i]
        trial[c] += delta
        _evaluate(model, c0, history, trial, cables, tip, states, left, stages, work,
                  cable_work, column)
        for i in range(n_unknowns):
            jacobian[i, c] = (column[i] - residual[i]) / delta


@numba.njit(cache=True, nogil=True)
def _fresh_inverse(model, c0, history, x, cables, tip, res, inverse, pivots, nominal, scratch):
    """Write the inverse of a fresh finite-difference Jacobian into ``inverse``; False: none."""
    jacobian = scratch[6]
    _refresh(model, c0, history, x, cables, tip, res, jacobian, nominal, scratch)
    if not _lu_factor(jacobian, pivots):
        return False
    unit = np.zeros(x.shape[0])
    column = np.empty(x.shape[0])
    for c in range(x.shape[0]):
        unit[c] = 1.0
        _lu_solve(jacobian, pivots, unit, column)
        inverse[:, c] = column
        unit[c] = 0.0
    return True


@numba.njit(cache=True, nogil=True)
def solve_step(model, c0, history, x, inverse, pivots, tip, cables, states, left, stages,
               motor, tolerance, max_iterations, refresh_first):
    """Quasi-Newton on ``x`` until every segment meets, the tip balances and the cables fit.

    ``x`` holds 6 + 24 (K - 1) values (:func:`shoot`), then, for a step driven by lengths
    (``cables.free`` given), each cable's end tension (N). ``inverse`` (M, M) carries the
    inverse Jacobian of the residual from step to step: computed from forward differences at
    the start (``refresh_first``) and when a step fails to reduce the residual or three in a
    row fail to halve it, else updated by Broyden's good formula after each step (a rank-one
    change, O(M^2)); ``pivots`` (M,) is scratch. ``x``, ``states`` (N, 24), ``left`` (N, 6),
    ``stages`` and ``motor`` (the motor-side tensions, N) hold the solution. Returns
    (converged, IVPs integrated (whole rods), Jacobian refreshes).
    """
    n_unknowns = x.shape[0]
    n_segments = model.bounds.shape[0] - 1
    n_cables = cables.friction.shape[0]
    n_free = cables.free.shape[0]
    work = np.empty((7, DYNAMIC_STATE))
    cable_work = (np.empty(n_cables), np.empty(n_cables), np.empty(n_cables))
    res = np.empty(n_unknowns)
    trial_res = np.empty(n_unknowns)
    trial = np.empty(n_unknowns)
    step = np.empty(n_unknowns)
    h_y = np.empty(n_unknowns)
    s_h = np.empty(n_unknowns)
    column_states = np.empty_like(states)
    column_left = np.empty_like(left)
    column_stages = np.empty_like(stages)
    scratch = (column_states, column_left, column_stages, work, np.empty(n_unknowns),
               cable_work, np.empty((n_unknowns, n_unknowns)))
    nominal = (states, left, stages)
    refresh_cost = (6.0 + DYNAMIC_STATE * (n_segments - 1)) / n_segments + n_free
    _evaluate(model, c0, history, x, cables, tip, states, left, stages, work, cable_work, res)
    norm = np.sqrt(np.sum(res * res))
    ivps, refreshes = 1.0, 0
    fresh = False
    slow = 0  # steps in a row that did not halve the residual
    converged = False
    if refresh_first:
        ivps += refresh_cost
        refreshes, fresh = 1, True
        if not _fresh_inverse(model, c0, history, x, cables, tip, res, inverse, pivots,
                              nominal, scratch):
            return False, ivps, refreshes
    for _ in range(max_iterations):
        if norm <= tolerance:
            converged = True
            break
        for i in range(n_unknowns):
            total = 0.0
            for j in range(n_unknowns):
                total += inverse[i, j] * res[j]
            step[i] = total
        # a quasi-Newton step is tried whole; a fresh Jacobian's is halved until it reduces
        # the residual (backtracking: far from the solution the full step may overshoot)
        fraction = 1.0
        trial_norm = np.inf
        for _ in range(HALVINGS if fresh else 1):
            for i in range(n_unknowns):
                trial[i] = x[i] - fraction * step[i]
            _evaluate(model, c0, history, trial, cables, tip, column_states, column_left,
                      column_stages, work, cable_work, trial_res)
            ivps += 1.0
            trial_norm = np.sqrt(np.sum(trial_res * trial_res))
            if trial_norm < norm:
                break
            fraction *= 0.5
        if trial_norm < norm and (fresh or slow < 3):
            # Broyden: H += (s - H y) (s^T H) / (s^T H y), s = the step taken, y = its change
            # of the residual
            for i in range(n_unknowns):
                step[i] = trial[i] - x[i]
                trial_res[i], res[i] = trial_res[i] - res[i], trial_res[i]  # y; res = new
            denominator = 0.0
            for i in range(n_unknowns):
                total, other = 0.0, 0.0
                for j in range(n_unknowns):
                    total += inverse[i, j] * trial_res[j]
                    other += step[j] * inverse[j, i]
                h_y[i], s_h[i] = total, other
                denominator += step[i] * total
            if abs(denominator) > 1e-300:
                for i in range(n_unknowns):
                    factor = (step[i] - h_y[i]) / denominator
                    for j in range(n_unknowns):
                        inverse[i, j] += factor * s_h[j]
            x[:] = trial
            states[:, :] = column_states
            left[:, :] = column_left
            stages[:, :, :] = column_stages
            slow = slow + 1 if trial_norm > 0.5 * norm else 0
            norm = trial_norm
            fresh = False
            continue
        if fresh:  # a fresh Jacobian's step does not reduce the residual: no solution near
            break
        ivps += refresh_cost
        refreshes += 1
        fresh, slow = True, 0
        if not _fresh_inverse(model, c0, history, x, cables, tip, res, inverse, pivots,
                              nominal, scratch):
            break
    else:
        converged = norm <= tolerance
    if n_free:  # the motor-side tensions of the solution
        consumed, mean = cable_work[0], cable_work[2]
        path_stretch(states, model.guide_nodes, model.cable_last_guide, model.hole_offsets,
                     model.base_axis, x[n_unknowns - n_free:], cables.friction,
                     model.compliance, consumed, motor, mean)
    else:
        motor[:] = cables.tensions
    return converged, ivps, refreshes


# Keeps the GIL (the one kernel that does): the simulated driver steps it a thousand times a
# second beside the other nodes' Python threads, and a kernel that releases the GIL must win it
# back after every step, waiting out another thread's switch interval (5 ms): beside one busy
# Python thread a 0.24 ms step took 5.7 ms (0.26 ms holding it), and the rod fell behind real
# time. A step is a fraction of a millisecond: holding the GIL that long stalls nobody.
@numba.njit(cache=True, nogil=False)
def advance(model, coefficients, memory, x, last_x, inverse, pivots, tip, cables, states,
            left, stages, motor, tolerance, max_iterations):
    """One time step: BDF-alpha history, predictor, :func:`solve_step`, memory moved on.

    :param coefficients: (c0, c1, c2, d1) of BDF-alpha (``dynamics.bdf_alpha``)
    :param memory: (previous, current, rate, history), each (N - 1, 4, 12): y(t_i-1), y(t_i),
        y_t(t_i) at every RK4 stage, and the history's scratch
    :param last_x: (2, M) the unknowns one and two steps before (the predictor's)
    A step that fails keeps every array as it was. Returns (converged, IVPs, refreshes).
    """
    c0, c1, c2, d1 = coefficients
    previous, current, rate, history = memory
    # y_h = c1 y(t_i-1) + c2 y(t_i-2) + d1 y_t(t_i-1) (Till et al. 2019, eq. 13)
    history[:] = c1 * current + c2 * previous + d1 * rate
    saved = (x.copy(), states.copy(), left.copy(), stages.copy(), motor.copy())
    for i in range(x.shape[0]):  # quadratic extrapolation of the last three steps' unknowns
        x[i] = 3.0 * (x[i] - last_x[0, i]) + last_x[1, i]
    converged, ivps, refreshes = solve_step(model, c0, history, x, inverse, pivots, tip, cables,
                                            states, left, stages, motor, tolerance,
                                            max_iterations, np.bool_(False))  # not Literal
    if not converged:
        x[:] = saved[0]
        states[:, :] = saved[1]
        left[:, :] = saved[2]
        stages[:, :, :] = saved[3]
        motor[:] = saved[4]
        return converged, ivps, refreshes
    last_x[1] = last_x[0]
    last_x[0] = saved[0]
    rate[:] = c0 * stages + history
    previous[:] = current
    current[:] = stages
    return converged, ivps, refreshes
