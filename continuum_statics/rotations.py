"""Rotation helpers: quaternions ([x, y, z, w], ROS order), hat and vee maps."""
import numpy as np


def quaternion_to_rotation(q):
    """Rotation matrix (3, 3) of a unit quaternion ``[x, y, z, w]``."""
    x, y, z, w = np.asarray(q, dtype=float)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rotation_to_quaternion(rotations):
    """Return unit quaternions ``[x, y, z, w]`` (w >= 0) of rotation matrices (..., 3, 3).

    Shepperd's method: branch on the largest diagonal term so no division loses precision.
    """
    m = np.asarray(rotations, dtype=float)
    flat = m.reshape(-1, 3, 3)
    q = np.empty((flat.shape[0], 4))
    for k, r in enumerate(flat):
        trace = r[0, 0] + r[1, 1] + r[2, 2]
        if trace > max(r[0, 0], r[1, 1], r[2, 2]):
            t = 2.0 * np.sqrt(1.0 + trace)
            q[k] = [(r[2, 1] - r[1, 2]) / t, (r[0, 2] - r[2, 0]) / t,
                    (r[1, 0] - r[0, 1]) / t, 0.25 * t]
        elif r[0, 0] >= r[1, 1] and r[0, 0] >= r[2, 2]:
            t = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
            q[k] = [0.25 * t, (r[0, 1] + r[1, 0]) / t,
                    (r[0, 2] + r[2, 0]) / t, (r[2, 1] - r[1, 2]) / t]
        elif r[1, 1] >= r[2, 2]:
            t = 2.0 * np.sqrt(1.0 - r[0, 0] + r[1, 1] - r[2, 2])
            q[k] = [(r[0, 1] + r[1, 0]) / t, 0.25 * t,
                    (r[1, 2] + r[2, 1]) / t, (r[0, 2] - r[2, 0]) / t]
        else:
            t = 2.0 * np.sqrt(1.0 - r[0, 0] - r[1, 1] + r[2, 2])
            q[k] = [(r[0, 2] + r[2, 0]) / t, (r[1, 2] + r[2, 1]) / t,
                    0.25 * t, (r[1, 0] - r[0, 1]) / t]
    q *= np.where(q[:, 3:4] < 0.0, -1.0, 1.0)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return q.reshape(m.shape[:-2] + (4,))


def hat(w):
    """Skew-symmetric matrix of a 3-vector, so that ``hat(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def vee(m):
    """3-vector of the skew-symmetric part of (..., 3, 3) matrices (inverse of :func:`hat`)."""
    m = np.asarray(m)
    return 0.5 * np.stack([m[..., 2, 1] - m[..., 1, 2],
                           m[..., 0, 2] - m[..., 2, 0],
                           m[..., 1, 0] - m[..., 0, 1]], axis=-1)
