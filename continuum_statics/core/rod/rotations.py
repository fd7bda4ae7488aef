"""Rotation helpers: quaternions in ROS order [x, y, z, w]."""
import math

import numba
import numpy as np


def quaternion_to_rotation(q):
    """Rotation matrix (3, 3) of a unit quaternion ``[x, y, z, w]``."""
    x, y, z, w = np.asarray(q, dtype=float)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def quaternion_direction(q):
    """Return the unit z axis (3,) of quaternion ``q`` [x, y, z, w] (normalised first).

    A goal pose's direction and a tip frame's axis along the rod: the one conversion.
    """
    q = np.asarray(q, dtype=float)
    return quaternion_to_rotation(q / np.linalg.norm(q))[:, 2]


@numba.njit(cache=True, nogil=True)
def quaternion_into(r, out):
    """Write the unit quaternion [x, y, z, w], w >= 0, of rotation ``r`` into ``out``.

    Shepperd's method: branch on the largest diagonal term so no division loses precision.
    """
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > max(r[0, 0], r[1, 1], r[2, 2]):
        t = 2.0 * np.sqrt(1.0 + trace)
        x, y, z, w = ((r[2, 1] - r[1, 2]) / t, (r[0, 2] - r[2, 0]) / t,
                      (r[1, 0] - r[0, 1]) / t, 0.25 * t)
    elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
        t = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        x, y, z, w = (0.25 * t, (r[0, 1] + r[1, 0]) / t, (r[0, 2] + r[2, 0]) / t,
                      (r[2, 1] - r[1, 2]) / t)
    elif r[1, 1] >= r[2, 2]:
        t = 2.0 * np.sqrt(1.0 - r[0, 0] + r[1, 1] - r[2, 2])
        x, y, z, w = ((r[0, 1] + r[1, 0]) / t, 0.25 * t, (r[1, 2] + r[2, 1]) / t,
                      (r[0, 2] - r[2, 0]) / t)
    else:
        t = 2.0 * np.sqrt(1.0 - r[0, 0] - r[1, 1] + r[2, 2])
        x, y, z, w = ((r[0, 2] + r[2, 0]) / t, (r[1, 2] + r[2, 1]) / t, 0.25 * t,
                      (r[1, 0] - r[0, 1]) / t)
    scale = (-1.0 if w < 0.0 else 1.0) / np.sqrt(x * x + y * y + z * z + w * w)
    out[0], out[1], out[2], out[3] = x * scale, y * scale, z * scale, w * scale


@numba.njit(cache=True, nogil=True)
def _quaternions(rotations, out):
    for k in range(rotations.shape[0]):
        quaternion_into(rotations[k], out[k])


def rotation_to_quaternion(rotations):
    """Return unit quaternions ``[x, y, z, w]`` (w >= 0) of rotation matrices (..., 3, 3)."""
    m = np.asarray(rotations, dtype=float)
    flat = np.ascontiguousarray(m).reshape(-1, 3, 3)
    if not flat.flags.writeable:  # a Shape's: one specialisation of the kernels (writable)
        flat = flat.copy()
    out = np.empty((flat.shape[0], 4))
    _quaternions(flat, out)
    return out.reshape(m.shape[:-2] + (4,))


def rotation_vector_matrix(vector):
    """Rotation matrix of a rotation vector (axis times angle, rad): Rodrigues' formula."""
    vector = np.asarray(vector, dtype=float)
    angle = float(np.linalg.norm(vector))
    if angle < 1e-12:
        return np.eye(3)
    k = vector / angle
    hat = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * hat + (1.0 - np.cos(angle)) * hat @ hat


@numba.njit(cache=True, nogil=True)
def rotation_vector_into(vector):
    """Return exp([v]x) (3, 3) of a rotation vector (rad): Rodrigues' formula, compiled."""
    x, y, z = vector[0], vector[1], vector[2]
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-12:
        a, b = 1.0, 0.5  # sin(t) / t and (1 - cos(t)) / t^2 at t -> 0
    else:
        a, b = math.sin(angle) / angle, (1.0 - math.cos(angle)) / (angle * angle)
    turn = np.empty((3, 3))  # I + a [v]x + b [v]x^2
    turn[0, 0] = 1.0 - b * (y * y + z * z)
    turn[1, 1] = 1.0 - b * (x * x + z * z)
    turn[2, 2] = 1.0 - b * (x * x + y * y)
    turn[0, 1], turn[1, 0] = b * x * y - a * z, b * x * y + a * z
    turn[0, 2], turn[2, 0] = b * x * z + a * y, b * x * z - a * y
    turn[1, 2], turn[2, 1] = b * y * z - a * x, b * y * z + a * x
    return turn
