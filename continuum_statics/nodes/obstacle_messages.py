"""Obstacles and Contacts messages <-> the core's obstacles and contacts; /tf transforms.

``continuum_statics_interfaces/msg/Obstacles``: parallel arrays ``names``, ``primitives``
(shape_msgs/SolidPrimitive) and ``poses`` in ``header.frame_id``. SPHERE dimensions [radius];
CYLINDER [height, radius] is read as a capsule of length ``height`` (the cylinder with a
hemisphere on each end); BOX [x, y, z] full edges. Each entry is judged on its own: a bad one
(no name, a name twice, another primitive type, wrong dimensions, sizes not in (0, 100] m, a
non-finite pose, an orientation that is not a unit quaternion) is refused by name and the others
are taken.
"""
import math

import numpy as np

from continuum_statics.core.description.obstacles import MAX_SIZE, Obstacle
from continuum_statics.core.rod.rotations import quaternion_to_rotation, rotation_to_quaternion

#: SolidPrimitive type constants (shape_msgs) -> (kind, dimensions it needs).
SPHERE, BOX, CYLINDER = 2, 1, 3
_PRIMITIVES = {SPHERE: ('sphere', 1), CYLINDER: ('capsule', 2), BOX: ('box', 3)}
#: A unit quaternion may be off by this much (float32 round trips, hand-typed poses).
QUATERNION_TOLERANCE = 1e-3


def obstacles_from_msg(msg):
    """Return ([Obstacle in ``header.frame_id``], {name or '#index': why refused}).

    :raises ValueError: when the arrays differ in length (no entry can be paired)
    """
    names, primitives, poses = list(msg.names), list(msg.primitives), list(msg.poses)
    if not len(names) == len(primitives) == len(poses):
        raise ValueError('names, primitives and poses differ in length (%d, %d, %d)'
                         % (len(names), len(primitives), len(poses)))
    frame_id = msg.header.frame_id.lstrip('/')
    obstacles, refused, seen = [], {}, set()
    for index, (name, primitive, pose) in enumerate(zip(names, primitives, poses)):
        label = name or '#%d' % index
        if not name:
            refused[label] = 'obstacle %d has no name' % index
            continue
        if name in seen:
            refused[label] = 'the name %r is given twice in one message' % name
            continue
        seen.add(name)
        try:
            obstacles.append(obstacle_from(name, primitive, pose, frame_id))
        except ValueError as error:
            refused[label] = str(error)
    return obstacles, refused


def obstacle_from(name, primitive, pose, frame_id=''):
    """Return the Obstacle of one SolidPrimitive and Pose (ValueError names what is wrong)."""
    kind, count = _PRIMITIVES.get(primitive.type, (None, 0))
    if kind is None:
        raise ValueError('obstacle %r: primitive type %d is not SPHERE (2), CYLINDER (3, a '
                         'capsule) or BOX (1)' % (name, primitive.type))
    dimensions = [float(v) for v in primitive.dimensions]
    if len(dimensions) != count:
        raise ValueError('obstacle %r: a %s needs %d dimensions, got %s'
                         % (name, kind, count, dimensions))
    if not all(math.isfinite(v) and 0.0 < v <= MAX_SIZE for v in dimensions):
        raise ValueError('obstacle %r: dimensions must be in (0, %g] m, got %s'
                         % (name, MAX_SIZE, dimensions))
    size = (dimensions[1], dimensions[0]) if kind == 'capsule' else tuple(dimensions)
    p, q = pose.position, pose.orientation
    position = np.array([p.x, p.y, p.z], dtype=float)
    quaternion = np.array([q.x, q.y, q.z, q.w], dtype=float)
    if not (np.all(np.isfinite(position)) and np.all(np.isfinite(quaternion))):
        raise ValueError('obstacle %r: the pose is not finite' % name)
    if abs(np.linalg.norm(quaternion) - 1.0) > QUATERNION_TOLERANCE:
        raise ValueError('obstacle %r: the orientation must be a unit quaternion, got |q| = %.6g'
                         % (name, np.linalg.norm(quaternion)))
    rotation = quaternion_to_rotation(quaternion / np.linalg.norm(quaternion))
    return Obstacle(name, kind, size, position, rotation, frame_id or None)


def obstacles_msg(obstacles, frame_id, stamp=None):
    """Return an Obstacles message of sphere, capsule and box obstacles (planes refused)."""
    from geometry_msgs.msg import Pose
    from shape_msgs.msg import SolidPrimitive

    from continuum_statics_interfaces.msg import Obstacles

    msg = Obstacles()
    msg.header.frame_id = frame_id
    if stamp is not None:
        msg.header.stamp = stamp
    for obstacle in obstacles:
        if obstacle.kind == 'plane':
            raise ValueError('obstacle %r: a plane is not a SolidPrimitive' % obstacle.name)
        size = obstacle.size
        primitive = SolidPrimitive(type={'sphere': SPHERE, 'capsule': CYLINDER,
                                         'box': BOX}[obstacle.kind])
        primitive.dimensions = [float(v) for v in (
            (size[1], size[0]) if obstacle.kind == 'capsule' else size)]
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = (float(v) for v in obstacle.position)
        (pose.orientation.x, pose.orientation.y, pose.orientation.z,
         pose.orientation.w) = (float(v) for v in rotation_to_quaternion(obstacle.rotation))
        msg.names.append(obstacle.name)
        msg.primitives.append(primitive)
        msg.poses.append(pose)
    return msg


def transforms_of(msg):
    """Yield (parent, child, R (3, 3), t (3,)) of a tf2_msgs/TFMessage's finite transforms."""
    for transform in msg.transforms:
        t, q = transform.transform.translation, transform.transform.rotation
        quaternion = np.array([q.x, q.y, q.z, q.w], dtype=float)
        norm = float(np.linalg.norm(quaternion))
        if not (math.isfinite(norm) and abs(norm - 1.0) < 0.1):
            continue
        yield (transform.header.frame_id, transform.child_frame_id,
               quaternion_to_rotation(quaternion / norm), np.array([t.x, t.y, t.z], dtype=float))


def contacts_msg(contacts, frame_id, sec, nanosec, msg=None):
    """Return a Contacts message of the core's contacts (base frame), or ValueError if not finite.

    ``points`` are the contacts' points as the core gives them (on the obstacle's surface).
    """
    from geometry_msgs.msg import Point, Vector3

    from continuum_statics_interfaces.msg import Contacts

    values = [(c.obstacle, float(c.s), np.asarray(c.point, dtype=float),
               np.asarray(c.normal, dtype=float), float(c.force)) for c in contacts]
    for name, s, point, normal, force in values:
        if not (math.isfinite(s) and math.isfinite(force) and np.all(np.isfinite(point))
                and np.all(np.isfinite(normal))):
            raise ValueError('contact with %r is not finite' % name)
    msg = Contacts() if msg is None else msg
    msg.header.frame_id = frame_id
    msg.header.stamp.sec, msg.header.stamp.nanosec = int(sec), int(nanosec)
    msg.obstacles = [v[0] for v in values]
    msg.s = [v[1] for v in values]
    msg.points = [Point(x=p[0], y=p[1], z=p[2]) for p in (v[2].tolist() for v in values)]
    msg.normals = [Vector3(x=n[0], y=n[1], z=n[2]) for n in (v[3].tolist() for v in values)]
    msg.forces = [max(v[4], 0.0) for v in values]
    return msg


class EmptyContacts:
    """Serialized Contacts without contacts, stamped per call (the 1 kHz path: ~1 us, no object).

    CDR: 4 bytes of encapsulation, then the header's stamp (int32 sec, uint32 nanosec).
    """

    def __init__(self, frame_id):
        from rclpy.serialization import serialize_message

        self._template = bytearray(serialize_message(contacts_msg((), frame_id, 0, 0)))
        if self._template[:2] != b'\x00\x01':  # not little-endian CDR: no template here
            raise RuntimeError('unexpected CDR encapsulation %r' % bytes(self._template[:2]))
        self._stamp = np.frombuffer(memoryview(self._template)[4:12], dtype='<u4')

    def encode(self, sec, nanosec):
        """Return the bytes of an empty Contacts stamped (sec, nanosec)."""
        self._stamp[0] = int(sec) & 0xFFFFFFFF  # int32 in two's complement
        self._stamp[1] = int(nanosec)
        return bytes(self._template)
