"""The classical-RK4 kernel of the single-section rod as it was before the SE(3) integrator.

Kept only as a timing reference for ``python -m continuum_statics bench`` (the issue's "old
classical-RK4 figure, in the same run"): RK4 on the 18 components r, R, v - e3, u of eqs. 1, 2,
8, 9 plus one polar-decomposition step per node. No cables; not used by any solver.
"""
import numba
import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.description.layout import (
    BASE_POSITION_AT,
    BASE_ROTATION_AT,
    BODY_FORCE_AT,
    C_AT,
    C_INV_AT,
    D_AT,
    D_INV_AT,
)
from continuum_statics.core.rod.shape import Shape

STATE_SIZE = 18


@numba.njit(cache=True, nogil=True, inline='always')
def _derivative(y, p, out):
    """Right-hand side of eqs. 1, 2, 8, 9 for the state ``y``; writes ``out``."""
    c0, c1, c2 = p[C_AT], p[C_AT + 1], p[C_AT + 2]
    d0, d1, d2 = p[D_AT], p[D_AT + 1], p[D_AT + 2]
    f0, f1, f2 = p[BODY_FORCE_AT], p[BODY_FORCE_AT + 1], p[BODY_FORCE_AT + 2]
    r00, r01, r02 = y[3], y[4], y[5]
    r10, r11, r12 = y[6], y[7], y[8]
    r20, r21, r22 = y[9], y[10], y[11]
    w0, w1, w2 = y[12], y[13], y[14]  # v - e3
    v0, v1, v2 = w0, w1, w2 + 1.0
    u0, u1, u2 = y[15], y[16], y[17]
    # eq. 1: r' = R v
    out[0] = r00 * v0 + r01 * v1 + r02 * v2
    out[1] = r10 * v0 + r11 * v1 + r12 * v2
    out[2] = r20 * v0 + r21 * v1 + r22 * v2
    # eq. 2: R' = R hat(u); column j of R hat(u) is R times column j of hat(u)
    out[3] = u2 * r01 - u1 * r02
    out[4] = -u2 * r00 + u0 * r02
    out[5] = u1 * r00 - u0 * r01
    out[6] = u2 * r11 - u1 * r12
    out[7] = -u2 * r10 + u0 * r12
    out[8] = u1 * r10 - u0 * r11
    out[9] = u2 * r21 - u1 * r22
    out[10] = -u2 * r20 + u0 * r22
    out[11] = u1 * r20 - u0 * r21
    # local internal force n^l = D (v - e3) (eq. 6) and moment m^l = C u (eq. 7)
    n0 = d0 * w0
    n1 = d1 * w1
    n2 = d2 * w2
    m0 = c0 * u0
    m1 = c1 * u1
    m2 = c2 * u2
    # local body force R^T f
    fl0 = r00 * f0 + r10 * f1 + r20 * f2
    fl1 = r01 * f0 + r11 * f1 + r21 * f2
    fl2 = r02 * f0 + r12 * f1 + r22 * f2
    # eq. 8: v' = D^-1 (-R^T f - u x n^l)
    out[12] = (-fl0 - (u1 * n2 - u2 * n1)) * p[D_INV_AT]
    out[13] = (-fl1 - (u2 * n0 - u0 * n2)) * p[D_INV_AT + 1]
    out[14] = (-fl2 - (u0 * n1 - u1 * n0)) * p[D_INV_AT + 2]
    # eq. 9: u' = C^-1 (-u x m^l - v x n^l)
    out[15] = (-(u1 * m2 - u2 * m1) - (v1 * n2 - v2 * n1)) * p[C_INV_AT]
    out[16] = (-(u2 * m0 - u0 * m2) - (v2 * n0 - v0 * n2)) * p[C_INV_AT + 1]
    out[17] = (-(u0 * m1 - u1 * m0) - (v0 * n1 - v1 * n0)) * p[C_INV_AT + 2]


@numba.njit(cache=True, nogil=True, inline='always')
def _orthonormalise(y):
    """One Newton step of the polar decomposition on the rotation block of ``y`` (in place).

    R <- 1.5 R - 0.5 R (R^T R); written with scalars so no array is allocated per step.
    """
    a00, a01, a02 = y[3], y[4], y[5]
    a10, a11, a12 = y[6], y[7], y[8]
    a20, a21, a22 = y[9], y[10], y[11]
    g00 = a00 * a00 + a10 * a10 + a20 * a20
    g11 = a01 * a01 + a11 * a11 + a21 * a21
    g22 = a02 * a02 + a12 * a12 + a22 * a22
    g01 = a00 * a01 + a10 * a11 + a20 * a21
    g02 = a00 * a02 + a10 * a12 + a20 * a22
    g12 = a01 * a02 + a11 * a12 + a21 * a22
    y[3] = 1.5 * a00 - 0.5 * (a00 * g00 + a01 * g01 + a02 * g02)
    y[4] = 1.5 * a01 - 0.5 * (a00 * g01 + a01 * g11 + a02 * g12)
    y[5] = 1.5 * a02 - 0.5 * (a00 * g02 + a01 * g12 + a02 * g22)
    y[6] = 1.5 * a10 - 0.5 * (a10 * g00 + a11 * g01 + a12 * g02)
    y[7] = 1.5 * a11 - 0.5 * (a10 * g01 + a11 * g11 + a12 * g12)
    y[8] = 1.5 * a12 - 0.5 * (a10 * g02 + a11 * g12 + a12 * g22)
    y[9] = 1.5 * a20 - 0.5 * (a20 * g00 + a21 * g01 + a22 * g02)
    y[10] = 1.5 * a21 - 0.5 * (a20 * g01 + a21 * g11 + a22 * g12)
    y[11] = 1.5 * a22 - 0.5 * (a20 * g02 + a21 * g12 + a22 * g22)


@numba.njit(cache=True, nogil=True)
def integrate_batch(s_grid, params, tip_forces, base_bendings):
    """Integrate a batch of initial-value problems from base to tip.

    :param s_grid: (N,) node arc lengths, s_grid[0] = 0, s_grid[-1] = rod length (m)
    :param params: rod constants and base pose, from :func:`pack_params`
    :param tip_forces: (B, 3) tip force F per problem, global frame (N)
    :param base_bendings: (B, 3) u(0) per problem, local frame (1/m)
    :returns: (B, N, 18) states: r (m), R row-major, v - e3, u (1/m) at every node
    """
    n_batch = base_bendings.shape[0]
    n_nodes = s_grid.shape[0]
    length = s_grid[n_nodes - 1]
    states = np.empty((n_batch, n_nodes, STATE_SIZE))
    tmp = np.empty(STATE_SIZE)
    k1 = np.empty(STATE_SIZE)
    k2 = np.empty(STATE_SIZE)
    k3 = np.empty(STATE_SIZE)
    k4 = np.empty(STATE_SIZE)
    for b in range(n_batch):
        y = states[b, 0]
        for i in range(3):
            y[i] = params[BASE_POSITION_AT + i]
        for i in range(9):
            y[3 + i] = params[BASE_ROTATION_AT + i]
        # eq. 10: n(0) = F + rho*A*g*L*e_g, so v(0) - e3 = D^-1 R(0)^T n(0)
        for i in range(3):
            n_base = 0.0
            for j in range(3):
                n_base += params[BASE_ROTATION_AT + 3 * j + i] * (
                    tip_forces[b, j] + params[BODY_FORCE_AT + j] * length)
            y[12 + i] = n_base * params[D_INV_AT + i]
            y[15 + i] = base_bendings[b, i]
        for node in range(1, n_nodes):
            h = s_grid[node] - s_grid[node - 1]
            y = states[b, node - 1]
            _derivative(y, params, k1)
            for i in range(STATE_SIZE):
                tmp[i] = y[i] + 0.5 * h * k1[i]
            _derivative(tmp, params, k2)
            for i in range(STATE_SIZE):
                tmp[i] = y[i] + 0.5 * h * k2[i]
            _derivative(tmp, params, k3)
            for i in range(STATE_SIZE):
                tmp[i] = y[i] + h * k3[i]
            _derivative(tmp, params, k4)
            y_next = states[b, node]
            for i in range(STATE_SIZE):
                y_next[i] = y[i] + h / 6.0 * (k1[i] + 2.0 * (k2[i] + k3[i]) + k4[i])
            _orthonormalise(y_next)
    return states


def solve_ivp(robot, u0, tip_force):
    """Shape as the old ``Robot.solve_ivp`` made it: checked inputs, kernel, Shape."""
    u0 = as_vector(u0, 3, 'u0')
    tip_force = as_vector(tip_force, 3, 'tip_force')
    states = integrate_batch(robot.s_grid, robot.params, tip_force[None], u0[None])
    return Shape(robot.s_grid, states[0], u0, tip_force, robot.c, robot.d)
