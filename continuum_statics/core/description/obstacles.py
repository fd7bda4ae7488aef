"""Obstacles around the robot: the robot file's ``obstacles:`` and their signed distances.

Four rigid primitives (doc/obstacles.md), each with a pose in its frame
(the robot's base frame unless ``frame_id`` says otherwise):

- ``sphere {radius}``;
- ``capsule {radius, length}``: a cylinder of that length along its local z with round ends
  (a ``shape_msgs/SolidPrimitive`` CYLINDER is read as one);
- ``box {size: [x, y, z]}``: full edge lengths along its local axes;
- ``plane {normal, offset}``: the free side is ``normal . x >= offset`` (base frame).

:meth:`Obstacle.distance` gives the signed distance of points to the surface (m, negative
inside) and the outward unit normal there, the gradient of that distance: the direction a
frictionless contact pushes the body. What must clear an obstacle is the body's radius
(``body_radius``: the robot file's, else the outermost cable hole, where the disks reach at
least, else the rod's radius).
"""
from dataclasses import dataclass
import math

import numpy as np

from continuum_statics.core.description.inputs import mapping

KINDS = ('sphere', 'capsule', 'box', 'plane')
_OBSTACLE_KEYS = {'name', 'frame_id', 'position', 'orientation', *KINDS}
_SIZE_KEYS = {'sphere': ('radius',), 'capsule': ('radius', 'length'), 'box': ('size',),
              'plane': ('normal', 'offset')}
#: Largest obstacle dimension a file may give (m): beyond it a unit is wrong (mm for m).
MAX_SIZE = 100.0


@dataclass(frozen=True, eq=False)
class Obstacle:
    """One rigid obstacle (SI units).

    :ivar name: unique among the robot's obstacles (contacts and refusals name it)
    :ivar kind: one of :data:`KINDS`
    :ivar size: sphere (radius,); capsule (radius, length); box (x, y, z) edges; plane ()
    :ivar position: (3,) centre (plane: its point nearest the frame's origin), m
    :ivar rotation: (3, 3) obstacle axes in its frame (capsule axis and plane normal: local z)
    :ivar frame_id: frame of the pose; None: the robot's base frame
    """

    name: str
    kind: str
    size: tuple
    position: np.ndarray
    rotation: np.ndarray
    frame_id: str = None

    def distance(self, points, normals=True):
        """Signed distances (n,) of points (n, 3) to the surface (m) and outward normals (n, 3).

        ``normals=False``: the distances only (normals None), for a scan of the whole body.
        """
        p = np.atleast_2d(np.asarray(points, dtype=float)) - self.position
        if self.kind == 'plane':
            axis = self.rotation[:, 2]
            return p @ axis, np.broadcast_to(axis, p.shape).copy() if normals else None
        if self.kind == 'sphere':
            return _round(p, self.size[0], normals)
        if self.kind == 'capsule':
            axis = self.rotation[:, 2]
            half = 0.5 * self.size[1]
            along = np.clip(p @ axis, -half, half)
            return _round(p - along[:, None] * axis, self.size[0], normals)
        local = p @ self.rotation  # box: in its own axes
        excess = np.abs(local) - 0.5 * np.asarray(self.size)
        outside = np.maximum(excess, 0.0)
        out_norm = np.linalg.norm(outside, axis=1)
        inside = np.max(excess, axis=1)
        distance = np.where(out_norm > 0.0, out_norm, inside)
        if not normals:
            return distance, None
        # outside: the gradient points from the nearest surface point; inside: the nearest face
        face = np.zeros_like(local)
        face[np.arange(len(local)), np.argmax(excess, axis=1)] = 1.0
        direction = np.where((out_norm > 0.0)[:, None],
                             outside / np.maximum(out_norm, 1e-300)[:, None], face)
        normal = (np.sign(local) + (local == 0.0)) * direction
        return distance, normal @ self.rotation.T

    def moved(self, rotation, translation, frame_id=None):
        """Return this obstacle mapped by x -> rotation x + translation (into ``frame_id``)."""
        rotation = np.asarray(rotation, dtype=float)
        return Obstacle(self.name, self.kind, self.size,
                        rotation @ self.position + np.asarray(translation, dtype=float),
                        rotation @ self.rotation, frame_id)


def _round(offset, radius, normals=True):
    """Distances and normals of points at ``offset`` (n, 3) from a centre point, minus radius."""
    norm = np.linalg.norm(offset, axis=1)
    if not normals:
        return norm - radius, None
    safe = np.maximum(norm, 1e-300)
    normal = offset / safe[:, None]
    normal[norm == 0.0] = (1.0, 0.0, 0.0)  # at the very centre any direction is outward
    return norm - radius, normal


def plane(name, normal, offset, frame_id=None):
    """Return the plane ``normal . x = offset``; its free side is ``normal . x >= offset``."""
    normal = np.asarray(normal, dtype=float)
    length = float(np.linalg.norm(normal))
    if not math.isfinite(length) or length < 1e-9:
        raise ValueError('obstacle %r: plane.normal must be a non-zero vector' % name)
    axis = normal / length
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, axis)
    x /= np.linalg.norm(x)
    rotation = np.column_stack([x, np.cross(axis, x), axis])
    return Obstacle(name, 'plane', (), axis * float(offset) / length, rotation, frame_id)


def parse_obstacles(entries, field='obstacles'):
    """Validate a robot file's ``obstacles:`` list into a tuple of :class:`Obstacle`."""
    if entries is None:
        return ()
    if not isinstance(entries, list):
        raise ValueError('%s must be a list of obstacles, got %r' % (field, entries))
    obstacles, names = [], set()
    for i, entry in enumerate(entries):
        where = '%s[%d]' % (field, i)
        mapping(entry, where, _OBSTACLE_KEYS)
        name = entry.get('name')
        if not isinstance(name, str) or not name:
            raise ValueError('%s.name must be a non-empty string, got %r' % (where, name))
        if name in names:
            raise ValueError('%s.name %r is used twice: contacts and refusals name obstacles'
                             % (where, name))
        names.add(name)
        kinds = [kind for kind in KINDS if kind in entry]
        if len(kinds) != 1:
            raise ValueError('%s (%r) must give exactly one of %s, got %s'
                             % (where, name, ', '.join(KINDS), kinds or 'none'))
        obstacles.append(obstacle_from(name, kinds[0], entry[kinds[0]], entry, where))
    return tuple(obstacles)


def obstacle_from(name, kind, shape, entry, where):
    """Build one obstacle from its shape mapping and pose keys (``position``, ``orientation``)."""
    field = '%s.%s' % (where, kind)
    if not isinstance(shape, dict) or set(shape) != set(_SIZE_KEYS[kind]):
        raise ValueError('%s must be a mapping with keys %s, got %r'
                         % (field, ', '.join(_SIZE_KEYS[kind]), shape))
    frame_id = entry.get('frame_id')
    if frame_id is not None and (not isinstance(frame_id, str) or not frame_id):
        raise ValueError('%s.frame_id must be a frame name, got %r' % (where, frame_id))
    if kind == 'plane':
        if 'position' in entry or 'orientation' in entry:
            raise ValueError('%s: a plane is given by normal and offset, not a pose' % where)
        return plane(name, _numbers(shape['normal'], 3, field + '.normal'),
                     _numbers([shape['offset']], 1, field + '.offset')[0], frame_id)
    position = _numbers(entry.get('position', [0.0, 0.0, 0.0]), 3, where + '.position')
    quaternion = _numbers(entry.get('orientation', [0.0, 0.0, 0.0, 1.0]), 4,
                          where + '.orientation')
    if abs(np.linalg.norm(quaternion) - 1.0) > 1e-3:
        raise ValueError('%s.orientation must be a unit quaternion [x, y, z, w], got %s'
                         % (where, quaternion.tolist()))
    if kind == 'box':
        size = _numbers(shape['size'], 3, field + '.size')
    else:
        size = _numbers([shape[key] for key in _SIZE_KEYS[kind]], len(_SIZE_KEYS[kind]), field)
    if np.any(size <= 0.0) or np.any(size > MAX_SIZE):
        raise ValueError('%s: sizes must be in (0, %g] m, got %s' % (field, MAX_SIZE,
                                                                      size.tolist()))
    # imported here: scipy's import is ~0.5 s of a node's start, most robots have no obstacles
    from scipy.spatial.transform import Rotation

    rotation = Rotation.from_quat(quaternion).as_matrix()  # scalar last: [x, y, z, w]
    return Obstacle(name, kind, tuple(float(v) for v in size), position, rotation, frame_id)


def _numbers(value, size, field):
    if not isinstance(value, (list, tuple)) or len(value) != size:
        raise ValueError('%s must be a list of %d numbers, got %r' % (field, size, value))
    try:
        array = np.array([float(v) for v in value])
    except (TypeError, ValueError):
        raise ValueError('%s must be numbers, got %r' % (field, value)) from None
    if not np.all(np.isfinite(array)):
        raise ValueError('%s must be finite, got %r' % (field, value))
    return array


def in_base_frame(obstacles, base_frame_id):
    """Return the obstacles as given, refusing one in another frame (ValueError names it)."""
    for obstacle in obstacles:
        if obstacle.frame_id not in (None, '', base_frame_id):
            raise ValueError('obstacle %r is in frame %r, not the base frame %r: give its pose '
                             'in the base frame (the obstacles topic takes any frame /tf '
                             'connects to it)' % (obstacle.name, obstacle.frame_id,
                                                  base_frame_id))
    return tuple(obstacles)
