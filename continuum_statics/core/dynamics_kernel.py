"""Compiled time step of the Cosserat rod in motion (Till, Aloi & Rucker, IJRR 38(6), 2019).

State along the unstretched arc length s (m), SI units, per node (:mod:`layout`'s
``DYNAMIC_STATE`` = 24, in this order; the compiled loops index it by number):
  p (3)      position, global                         p_s = R v                       (eq. 7)
  R (9)      orientation, row-major, local -> global  R_s = R hat(u)
  n (3)      internal force, global                   n_s = rho A R (w x q + q_t) - f
  m (3)      internal moment, global                  m_s = R (w x rho J w + rho J w_t) - p_s x n
  q (3)      linear velocity, local                   q_s = v_t - u x q + w x v
  w (3)      angular velocity, local                  w_s = u_t - u x w
with the Kelvin-Voigt laws (Till eq. 3, 4; the paper's eqs. 6, 7 plus damping)
  R^T n = K_se (v - e3) + B_se v_t,   R^T m = K_bt u + B_bt u_t
and every time derivative by BDF-alpha (Till eq. 13): y_t = c0 y + y_h, the history y_h from the
two steps before (:mod:`continuum_statics.core.dynamics`). The strains are therefore algebraic:
  v = (K_se + c0 B_se)^-1 (R^T n + K_se e3 - B_se v_h)
  u = (K_bt + c0 B_bt)^-1 (R^T m - B_bt u_h).

A step is a shooting problem in the base's n(0), m(0) (p, R, q = w = 0 fixed at the base): the
tip must carry the tip load, n(L) = F and m(L) = M. Point loads at the nodes make n and m jump:
the weight and inertia of guide disks, m_d (g - R (q_t + w x q)), and the point-moment cable
model's pull on each section's end disk, t_j R (e3 x l_j) (the paper; internal forces cancel).

The spatial integration is classical RK4 on all 24 values, the history linear across an interval
(second order in s where the history bends; :mod:`test_dynamics` measures the order). Newton's
method on the six unknowns reuses the last step's Jacobian (chord steps) and refreshes it by
forward differences only when a chord step does not reduce the residual.
"""
import numba
import numpy as np

from continuum_statics.core.layout import (
    DYN_B_BT_AT,
    DYN_B_SE_AT,
    DYN_BASE_POSITION_AT,
    DYN_BASE_ROTATION_AT,
    DYN_GRAVITY_AT,
    DYN_HISTORY_SIZE,
    DYN_K_BT_AT,
    DYN_K_SE_AT,
    DYN_MASS_AT,
    DYN_RHO_J_AT,
    DYNAMIC_STATE,
)

_SIXTH = 1.0 / 6.0
HALVINGS = 12  # of a fresh Newton step at most


@numba.njit(cache=True, nogil=True)
def _derivative(y, hist, c0, params, scale, out):
    """Write y_s of one state ``y`` (24,) with history ``hist`` (12,) into ``out`` (24,)."""
    r00, r01, r02 = y[3], y[4], y[5]
    r10, r11, r12 = y[6], y[7], y[8]
    r20, r21, r22 = y[9], y[10], y[11]
    n0, n1, n2 = y[12], y[13], y[14]
    m0, m1, m2 = y[15], y[16], y[17]
    q0, q1, q2 = y[18], y[19], y[20]
    w0, w1, w2 = y[21], y[22], y[23]
    # R^T n, R^T m (local)
    ln0 = r00 * n0 + r10 * n1 + r20 * n2
    ln1 = r01 * n0 + r11 * n1 + r21 * n2
    ln2 = r02 * n0 + r12 * n1 + r22 * n2
    lm0 = r00 * m0 + r10 * m1 + r20 * m2
    lm1 = r01 * m0 + r11 * m1 + r21 * m2
    lm2 = r02 * m0 + r12 * m1 + r22 * m2
    ks, bs = DYN_K_SE_AT, DYN_B_SE_AT
    kb, bb = DYN_K_BT_AT, DYN_B_BT_AT
    v0 = (ln0 - params[bs] * hist[0]) / (params[ks] + c0 * params[bs])
    v1 = (ln1 - params[bs + 1] * hist[1]) / (params[ks + 1] + c0 * params[bs + 1])
    v2 = (ln2 + params[ks + 2] - params[bs + 2] * hist[2]) / (params[ks + 2]
                                                               + c0 * params[bs + 2])
    u0 = (lm0 - scale * params[bb] * hist[3]) / (scale * (params[kb] + c0 * params[bb]))
    u1 = (lm1 - scale * params[bb + 1] * hist[4]) / (scale * (params[kb + 1]
                                                              + c0 * params[bb + 1]))
    u2 = (lm2 - scale * params[bb + 2] * hist[5]) / (scale * (params[kb + 2]
                                                              + c0 * params[bb + 2]))
    vt0, vt1, vt2 = c0 * v0 + hist[0], c0 * v1 + hist[1], c0 * v2 + hist[2]
    ut0, ut1, ut2 = c0 * u0 + hist[3], c0 * u1 + hist[4], c0 * u2 + hist[5]
    qt0, qt1, qt2 = c0 * q0 + hist[6], c0 * q1 + hist[7], c0 * q2 + hist[8]
    wt0, wt1, wt2 = c0 * w0 + hist[9], c0 * w1 + hist[10], c0 * w2 + hist[11]
    # p_s = R v
    ps0 = r00 * v0 + r01 * v1 + r02 * v2
    ps1 = r10 * v0 + r11 * v1 + r12 * v2
    ps2 = r20 * v0 + r21 * v1 + r22 * v2
    out[0], out[1], out[2] = ps0, ps1, ps2
    # R_s = R hat(u): row i of R times hat(u)
    out[3] = r01 * u2 - r02 * u1
    out[4] = r02 * u0 - r00 * u2
    out[5] = r00 * u1 - r01 * u0
    out[6] = r11 * u2 - r12 * u1
    out[7] = r12 * u0 - r10 * u2
    out[8] = r10 * u1 - r11 * u0
    out[9] = r21 * u2 - r22 * u1
    out[10] = r22 * u0 - r20 * u2
    out[11] = r20 * u1 - r21 * u0
    # n_s = rho A R (w x q + q_t) - rho A g
    rho_a = params[DYN_MASS_AT]
    a0 = w1 * q2 - w2 * q1 + qt0
    a1 = w2 * q0 - w0 * q2 + qt1
    a2 = w0 * q1 - w1 * q0 + qt2
    g = DYN_GRAVITY_AT
    out[12] = rho_a * (r00 * a0 + r01 * a1 + r02 * a2 - params[g])
    out[13] = rho_a * (r10 * a0 + r11 * a1 + r12 * a2 - params[g + 1])
    out[14] = rho_a * (r20 * a0 + r21 * a1 + r22 * a2 - params[g + 2])
    # m_s = R (w x rho J w + rho J w_t) - p_s x n
    j0, j1, j2 = params[DYN_RHO_J_AT], params[DYN_RHO_J_AT + 1], params[DYN_RHO_J_AT + 2]
    h0, h1, h2 = j0 * w0, j1 * w1, j2 * w2
    b0 = w1 * h2 - w2 * h1 + j0 * wt0
    b1 = w2 * h0 - w0 * h2 + j1 * wt1
    b2 = w0 * h1 - w1 * h0 + j2 * wt2
    out[15] = r00 * b0 + r01 * b1 + r02 * b2 - (ps1 * n2 - ps2 * n1)
    out[16] = r10 * b0 + r11 * b1 + r12 * b2 - (ps2 * n0 - ps0 * n2)
    out[17] = r20 * b0 + r21 * b1 + r22 * b2 - (ps0 * n1 - ps1 * n0)
    # q_s = v_t - u x q + w x v;  w_s = u_t - u x w
    out[18] = vt0 - (u1 * q2 - u2 * q1) + (w1 * v2 - w2 * v1)
    out[19] = vt1 - (u2 * q0 - u0 * q2) + (w2 * v0 - w0 * v2)
    out[20] = vt2 - (u0 * q1 - u1 * q0) + (w0 * v1 - w1 * v0)
    out[21] = ut0 - (u1 * w2 - u2 * w1)
    out[22] = ut1 - (u2 * w0 - u0 * w2)
    out[23] = ut2 - (u0 * w1 - u1 * w0)


@numba.njit(cache=True, nogil=True)
def _point_loads(y, hist, c0, node, disk_mass, params, tensions, cable_offsets, cable_end_node):
    """Apply the jumps of n and m at ``node``: disk weight and inertia, cables ending there."""
    mass = disk_mass[node]
    if mass > 0.0:  # external force m_d (g - a), a = R (q_t + w x q); n(s+) = n(s-) - it
        q0, q1, q2 = y[18], y[19], y[20]
        w0, w1, w2 = y[21], y[22], y[23]
        a0 = w1 * q2 - w2 * q1 + c0 * q0 + hist[6]
        a1 = w2 * q0 - w0 * q2 + c0 * q1 + hist[7]
        a2 = w0 * q1 - w1 * q0 + c0 * q2 + hist[8]
        g = DYN_GRAVITY_AT
        for i in range(3):
            acc = y[3 + 3 * i] * a0 + y[4 + 3 * i] * a1 + y[5 + 3 * i] * a2
            y[12 + i] -= mass * (params[g + i] - acc)
    for j in range(cable_end_node.shape[0]):
        t = tensions[j]
        if cable_end_node[j] != node or t == 0.0:
            continue
        # t R (e3 x l): e3 x l = (-l1, l0, 0)
        x0, x1 = -t * cable_offsets[j, 1], t * cable_offsets[j, 0]
        for i in range(3):
            y[15 + i] -= y[3 + 3 * i] * x0 + y[4 + 3 * i] * x1


@numba.njit(cache=True, nogil=True)
def shoot(model, c0, history, base, tensions, states, left, work):
    """Integrate one step's IVP from the base's ``base`` = (n(0), m(0)) into ``states`` (N, 24).

    :param model: the robot's :class:`~continuum_statics.core.layout.DynamicsModel`
    :param history: (N, 2, 12) v_h, u_h, q_h, w_h at the nodes (``DYN_HISTORY_SIZE``), the
        limit from the base side [:, 0] and from the tip side [:, 1] (strains jump at point loads)
    :param left: (N, 6) out: n, m on the base side of each node (``states`` holds the tip side)
    :param tensions: (n_cables,) N
    :param work: (6, 24) scratch
    """
    s_grid, params, disk_mass = model.s_grid, model.params, model.disk_mass
    bending_scale, cable_offsets, cable_end_node = (model.bending_scale, model.cable_offsets,
                                                    model.cable_end_node)
    n_nodes = s_grid.shape[0]
    y, k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4], work[5]
    hist = np.empty(DYN_HISTORY_SIZE)
    for i in range(3):
        y[i] = params[DYN_BASE_POSITION_AT + i]
    for i in range(9):
        y[3 + i] = params[DYN_BASE_ROTATION_AT + i]
    for i in range(6):
        y[12 + i] = base[i]
    for i in range(6):
        y[18 + i] = 0.0
    for i in range(6):
        left[0, i] = y[12 + i]
    _point_loads(y, history[0, 1], c0, 0, disk_mass, params, tensions, cable_offsets,
                 cable_end_node)
    states[0, :] = y
    for k in range(n_nodes - 1):
        h = s_grid[k + 1] - s_grid[k]
        scale = bending_scale[k]
        _derivative(y, history[k, 1], c0, params, scale, k1)
        for i in range(DYN_HISTORY_SIZE):
            hist[i] = 0.5 * (history[k, 1, i] + history[k + 1, 0, i])
        for i in range(DYNAMIC_STATE):
            tmp[i] = y[i] + 0.5 * h * k1[i]
        _derivative(tmp, hist, c0, params, scale, k2)
        for i in range(DYNAMIC_STATE):
            tmp[i] = y[i] + 0.5 * h * k2[i]
        _derivative(tmp, hist, c0, params, scale, k3)
        for i in range(DYNAMIC_STATE):
            tmp[i] = y[i] + h * k3[i]
        _derivative(tmp, history[k + 1, 0], c0, params, scale, k4)
        for i in range(DYNAMIC_STATE):
            y[i] += h * _SIXTH * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
        for i in range(6):
            left[k + 1, i] = y[12 + i]
        _point_loads(y, history[k + 1, 0], c0, k + 1, disk_mass, params, tensions,
                     cable_offsets, cable_end_node)
        states[k + 1, :] = y


@numba.njit(cache=True, nogil=True)
def _residual(states, tip, scales, out):
    last = states.shape[0] - 1
    for i in range(6):
        out[i] = (states[last, 12 + i] - tip[i]) / scales[i]


@numba.njit(cache=True, nogil=True)
def solve_step(model, c0, history, base, jacobian, tip, tensions, states, left, tolerance,
               max_iterations):
    """Newton's method on ``base`` (6,) until the tip carries ``tip`` (6,: F, M, global).

    ``jacobian`` (6, 6) d residual / d base (residual = (n, m)(L) - tip, divided by ``scales``)
    is read as the start and refreshed in place when a chord step fails to reduce the residual.
    ``base``, ``states`` (N, 24) and ``left`` (N, 6) hold the solution. Returns (converged,
    IVPs integrated, Jacobian refreshes).
    """
    scales = model.scales
    work = np.empty((6, DYNAMIC_STATE))
    res = np.empty(6)
    trial_res = np.empty(6)
    trial = np.empty(6)
    column_states = np.empty_like(states)
    column_left = np.empty_like(left)
    shoot(model, c0, history, base, tensions, states, left, work)
    _residual(states, tip, scales, res)
    norm = np.sqrt(np.sum(res * res))
    ivps, refreshes = 1, 0
    fresh = False
    for _ in range(max_iterations):
        if norm <= tolerance:
            return True, ivps, refreshes
        step = np.linalg.solve(jacobian, res)
        # a chord step is tried whole; a fresh Jacobian's step is halved until it reduces the
        # residual (backtracking: far from the solution the full step may overshoot)
        fraction = 1.0
        for _ in range(HALVINGS if fresh else 1):
            for i in range(6):
                trial[i] = base[i] - fraction * step[i]
            shoot(model, c0, history, trial, tensions, column_states, column_left, work)
            ivps += 1
            _residual(column_states, tip, scales, trial_res)
            trial_norm = np.sqrt(np.sum(trial_res * trial_res))
            if trial_norm < norm:
                break
            fraction *= 0.5
        if trial_norm < 0.5 * norm or (fresh and trial_norm < norm):
            base[:] = trial
            states[:, :] = column_states
            left[:, :] = column_left
            res[:] = trial_res
            norm = trial_norm
            fresh = False
            continue
        if fresh:  # a fresh Jacobian's step does not reduce the residual: no equilibrium near
            return False, ivps, refreshes
        # refresh the Jacobian by forward differences at the current base
        for j in range(6):
            delta = 1e-7 * scales[j] if scales[j] > 0.0 else 1e-7
            for i in range(6):
                trial[i] = base[i]
            trial[j] += delta
            shoot(model, c0, history, trial, tensions, column_states, column_left, work)
            ivps += 1
            _residual(column_states, tip, scales, trial_res)
            for i in range(6):
                jacobian[i, j] = (trial_res[i] - res[i]) / delta
        refreshes += 1
        fresh = True
    return norm <= tolerance, ivps, refreshes


@numba.njit(cache=True, nogil=True)
def strains_and_velocities(model, states, left, history, c0, out):
    """Write each node's v, u, q, w (N, 2, 12) of solved ``states``: the history's quantities.

    [:, 0] on the base side of a node (n, m from ``left``), [:, 1] on the tip side.
    """
    params, bending_scale = model.params, model.bending_scale
    n_nodes = states.shape[0]
    for k in range(n_nodes):
        y = states[k]
        for side in range(2):
            interval = min(max(k - 1 + side, 0), n_nodes - 2)
            scale = bending_scale[interval]
            for i in range(3):
                if side == 0:
                    n0, n1, n2 = left[k, 0], left[k, 1], left[k, 2]
                    m0, m1, m2 = left[k, 3], left[k, 4], left[k, 5]
                else:
                    n0, n1, n2 = y[12], y[13], y[14]
                    m0, m1, m2 = y[15], y[16], y[17]
                ln = n0 * y[3 + i] + n1 * y[6 + i] + n2 * y[9 + i]
                lm = m0 * y[3 + i] + m1 * y[6 + i] + m2 * y[9 + i]
                ks, bs = params[DYN_K_SE_AT + i], params[DYN_B_SE_AT + i]
                kb, bb = scale * params[DYN_K_BT_AT + i], scale * params[DYN_B_BT_AT + i]
                out[k, side, i] = ((ln + (ks if i == 2 else 0.0) - bs * history[k, side, i])
                                   / (ks + c0 * bs))
                out[k, side, 3 + i] = (lm - bb * history[k, side, 3 + i]) / (kb + c0 * bb)
                out[k, side, 6 + i] = y[18 + i]
                out[k, side, 9 + i] = y[21 + i]
