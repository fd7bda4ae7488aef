"""Stateless message <-> numpy helpers for the nodes (no physics here).

Validation happens at this boundary: every reader raises ``ValueError`` with a message a user can
act on (what was wrong, what was expected), so a node can log it, report it on diagnostics and drop
that input. Writers never emit a NaN: they raise instead.
"""
import math

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
import numpy as np
from sensor_msgs.msg import JointState

from continuum_statics.core.rod.rotations import quaternion_direction, quaternion_to_rotation

#: Quaternion of the identity rotation, [x, y, z, w].
IDENTITY_QUATERNION = (0.0, 0.0, 0.0, 1.0)
_NS = 1_000_000_000


# -- stamps: the one conversion between builtin_interfaces/Time and integer nanoseconds ---------
def stamp_ns(stamp):
    """Return a builtin_interfaces/Time (or anything with ``sec``, ``nanosec``) as int ns."""
    return stamp.sec * _NS + stamp.nanosec


def ns_to_stamp(nanoseconds, stamp=None):
    """Write int nanoseconds into ``stamp`` (a Time, or a new one when None); return it."""
    stamp = Time() if stamp is None else stamp
    stamp.sec, stamp.nanosec = int(nanoseconds // _NS), int(nanoseconds % _NS)
    return stamp


def seconds_to_stamp(seconds):
    """Return float seconds as a builtin_interfaces/Time."""
    return ns_to_stamp(int(round(seconds * 1e9)))


def stamp_or_now(sec, nanosec, clock):
    """(sec, nanosec) of a message, or of ``clock``'s now when unstamped (both zero)."""
    if sec == 0 and nanosec == 0:
        now = clock.now().to_msg()
        return now.sec, now.nanosec
    return sec, nanosec



def cable_index(names, cable_names, require_all=True):
    """Map message names onto the robot's cable order.

    :param names: the ``name`` field of a JointState
    :param cable_names: the robot's cable names
    :param require_all: every cable must appear (a measurement); False allows a subset (a command)
    :returns: int array ``index`` with ``values_in_robot_order[index] = message_values``
    :raises ValueError: on unknown, repeated or (with ``require_all``) missing names
    """
    if len(names) > len(cable_names):  # bounded work per message, whatever its size
        raise ValueError('%d names for a robot with %d cables (%s)'
                         % (len(names), len(cable_names), ', '.join(cable_names)))
    lookup = {name: i for i, name in enumerate(cable_names)}
    index = []
    for name in names:
        if name not in lookup:
            raise ValueError('unknown cable name %r (the robot has %s)'
                             % (name, ', '.join(cable_names)))
        index.append(lookup[name])
    if len(set(index)) != len(index):
        seen = set()
        repeated = sorted({name for name in names if name in seen or seen.add(name)})
        raise ValueError('repeated cable names %s' % ', '.join(repeated))
    if require_all and len(index) != len(cable_names):
        missing = [name for name in cable_names if name not in set(names)]
        raise ValueError('missing cable(s) %s: a measurement needs all of %s'
                         % (', '.join(missing), ', '.join(cable_names)))
    if not index:
        raise ValueError('no cable names in the message')
    return np.array(index, dtype=np.intp)


def joint_positions(msg, n_names=None):
    """Return ``msg.position`` as a finite float array whose size matches ``msg.name``.

    :raises ValueError: on a size mismatch or a non-finite value
    """
    n_names = len(msg.name) if n_names is None else n_names
    positions = np.asarray(msg.position, dtype=float)
    if positions.shape != (n_names,):
        raise ValueError('JointState has %d names but %d positions' % (n_names, positions.size))
    if not np.all(np.isfinite(positions)):
        bad = [str(msg.name[i]) for i in np.flatnonzero(~np.isfinite(positions))]
        raise ValueError('non-finite cable length for %s' % ', '.join(bad))
    for field in ('velocity', 'effort'):  # optional, but when given they must fit too
        values = np.asarray(getattr(msg, field), dtype=float)
        if values.size and values.shape != (n_names,):
            raise ValueError('JointState has %d names but %d %s values'
                             % (n_names, values.size, field))
        if not np.all(np.isfinite(values)):
            raise ValueError('non-finite %s in JointState' % field)
    return positions


def joint_state(names, positions, stamp, velocities=None, efforts=None, msg=None):
    """Fill (or create) a JointState; every array must be finite.

    :param msg: a JointState to reuse (its fields are overwritten), or None for a new one
    :raises ValueError: on a non-finite value
    """
    msg = JointState() if msg is None else msg
    msg.header.stamp = stamp
    msg.name = list(names)
    msg.position = _finite_list(positions, 'position')
    msg.velocity = [] if velocities is None else _finite_list(velocities, 'velocity')
    msg.effort = [] if efforts is None else _finite_list(efforts, 'effort')
    return msg


def _finite_list(values, what):
    values = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(values)):
        raise ValueError('refusing to publish a non-finite %s: %s' % (what, values))
    return values.tolist()


def check_frame(frame_id, base_frame_id, what):
    """Raise ValueError unless ``frame_id`` is the robot's base frame (empty is not accepted)."""
    if frame_id != base_frame_id:
        raise ValueError('%s is in frame %r; it must be in the robot base frame %r'
                         % (what, frame_id, base_frame_id))


def tip_load(msg, base_frame_id, max_force=math.inf, max_torque=math.inf, what='tip_wrench'):
    """Return a WrenchStamped in the base frame as a finite (6,) array: force (N), torque (N m).

    Each component is checked for finiteness first, then the magnitudes with ``math.hypot``
    (which cannot overflow), so a 1e155 N force is "too large", never "not finite".

    :param max_force: largest plausible force magnitude, N
    :param max_torque: largest plausible torque magnitude, N m
    :param what: the topic's name, for the messages
    :raises ValueError: on another frame, a non-finite component or an implausible magnitude
    """
    check_frame(msg.header.frame_id, base_frame_id, what)
    force, torque = msg.wrench.force, msg.wrench.torque
    values = (force.x, force.y, force.z, torque.x, torque.y, torque.z)
    if not all(math.isfinite(v) for v in values):
        raise ValueError('%s has a non-finite component: force (%g, %g, %g), '
                         'torque (%g, %g, %g)' % ((what,) + values))
    force_norm, torque_norm = math.hypot(*values[:3]), math.hypot(*values[3:])
    if force_norm > max_force:
        raise ValueError('%s force %.3g N is too large (max_tip_force %.3g N)'
                         % (what, force_norm, max_force))
    if torque_norm > max_torque:
        raise ValueError('%s torque %.3g N m is too large (max_tip_torque %.3g N m)'
                         % (what, torque_norm, max_torque))
    return np.array(values)


def base_frame_pose(msg, base_frame_id, what, hint=''):
    """Return (position (3,) m, quaternion [x, y, z, w], stamp ns) of a PoseStamped.

    :param hint: appended to the frame error (what the user should do)
    :raises ValueError: another frame than the base frame, or a non-finite position
    """
    if msg.header.frame_id != base_frame_id:
        raise ValueError('frame %r is not the base frame %r%s'
                         % (msg.header.frame_id, base_frame_id, hint))
    position = pose_position(msg.pose)
    if not np.all(np.isfinite(position)):
        raise ValueError('non-finite position')
    q = msg.pose.orientation
    return position, np.array([q.x, q.y, q.z, q.w]), stamp_ns(msg.header.stamp)


def tracked_pose(msg, base_frame_id, use_rotation=False, hint=''):
    """Return (position (3,) m, rotation (3, 3) or None, stamp ns, sigma m or None) of a pose.

    The one parser of a tracked pose: statics' sensors (``sensors/<name>``,
    ``tip_pose_measured``), and the tracker tip_controller and tip_load_estimator read from
    statics' accepted readings, so every node takes and refuses the same messages. An empty
    frame id is the base frame; the rotation is read when ``use_rotation`` and the quaternion is
    a unit one (else None). ``msg`` is a PoseStamped, or a PoseWithCovarianceStamped whose
    position covariance gives ``sigma``: the square root of its largest diagonal value when all
    three are finite and positive (else None, the configured noise).

    :param hint: appended to the frame error (what the user should do)
    :raises ValueError: another frame than the base frame, or a non-finite position
    """
    frame = msg.header.frame_id
    if frame and frame != base_frame_id:
        raise ValueError('frame %r is not the base frame %r%s' % (frame, base_frame_id, hint))
    pose, sigma = msg.pose, None
    if isinstance(msg, PoseWithCovarianceStamped):
        pose, variances = msg.pose.pose, np.asarray(msg.pose.covariance, dtype=float)[[0, 7, 14]]
        if np.all(np.isfinite(variances)) and np.all(variances > 0.0):
            sigma = math.sqrt(float(np.max(variances)))
    position = pose_position(pose)
    if not np.all(np.isfinite(position)):
        raise ValueError('a reading that is not finite: position %s' % position)
    rotation = None
    if use_rotation:
        q = pose.orientation
        quaternion = np.array([q.x, q.y, q.z, q.w])
        if np.all(np.isfinite(quaternion)) and abs(np.linalg.norm(quaternion) - 1.0) < 1e-3:
            rotation = quaternion_to_rotation(quaternion)
    return position, rotation, stamp_ns(msg.header.stamp), sigma


def twist_vectors(msg, base_frame_id):
    """Return (linear (3,) m/s, angular (3,) rad/s) of a TwistStamped in the base frame.

    An empty frame is taken as the base frame.
    :raises ValueError: another frame
    """
    frame = msg.header.frame_id
    if frame not in ('', base_frame_id):
        raise ValueError('frame %r is not the base frame %r' % (frame, base_frame_id))
    t = msg.twist
    return (np.array([t.linear.x, t.linear.y, t.linear.z]),
            np.array([t.angular.x, t.angular.y, t.angular.z]))


def float32_value(value):
    """Return the decimal a float32 field was set from (0.3, not 0.30000001192092896).

    Uses the shortest decimal that rounds to the same float32 (numpy's float32 repr).
    """
    return float(str(np.float32(value)))


def goal_position(pose_stamped, base_frame_id):
    """Return the position of a goal PoseStamped as a finite (3,) array in the base frame, m.

    The orientation is not controlled (three tip-position goals for three bending unknowns), but it
    must not be NaN either.

    :raises ValueError: on another or an empty frame, or a non-finite number
    """
    check_frame(pose_stamped.header.frame_id, base_frame_id, 'the tip goal')
    p, q = pose_stamped.pose.position, pose_stamped.pose.orientation
    values = (p.x, p.y, p.z, q.x, q.y, q.z, q.w)
    if not all(math.isfinite(v) for v in values):
        raise ValueError('the tip goal has a non-finite number: position (%g, %g, %g), '
                         'orientation (%g, %g, %g, %g)' % values)
    return np.array(values[:3])


def goal_direction(pose_stamped, asked, what='goal'):
    """Return the tip direction goal of a goal pose: the unit z axis of its orientation.

    :param asked: what asked for a direction, for the error (e.g. 'use_direction')
    :param what: the pose's name in the error ('goal', 'target')
    :raises ValueError: when the orientation is not a unit quaternion (within 1e-3)
    """
    q = pose_stamped.pose.orientation
    quaternion = np.array([q.x, q.y, q.z, q.w])
    norm = float(np.linalg.norm(quaternion))
    if not abs(norm - 1.0) < 1e-3:
        raise ValueError('%s but the %s orientation is not a unit quaternion (norm %.3g)'
                         % (asked, what, norm))
    return quaternion_direction(quaternion)


def set_pose(pose, position, quaternion):
    """Write a position (3,) and quaternion [x, y, z, w] (Python floats) into a Pose."""
    p, q = pose.position, pose.orientation
    p.x, p.y, p.z = position
    q.x, q.y, q.z, q.w = quaternion


def fill_path(path, header, positions, quaternions):
    """Write poses base -> tip into ``path`` in place, reusing its PoseStamped objects.

    Every pose shares ``header`` (one stamp, one frame), which is what a backbone sampled at one
    instant is. Reusing the objects keeps the per-cycle cost to plain attribute writes.

    :param positions: (n, 3) array, m
    :param quaternions: (n, 4) array [x, y, z, w]
    :raises ValueError: on a non-finite value (nothing is written then)
    """
    positions = np.asarray(positions, dtype=float)
    quaternions = np.asarray(quaternions, dtype=float)
    if not (np.all(np.isfinite(positions)) and np.all(np.isfinite(quaternions))):
        raise ValueError('refusing to publish a backbone with non-finite poses')
    n = positions.shape[0]
    poses = path.poses
    if len(poses) != n:
        poses = [PoseStamped() for _ in range(n)]
        path.poses = poses
    path.header = header
    for pose_stamped, position, quaternion in zip(poses, positions.tolist(),
                                                  quaternions.tolist()):
        pose_stamped.header = header
        set_pose(pose_stamped.pose, position, quaternion)
    return path


def backbone_path(data, base_frame_id):
    """Return a serialized nav_msgs/Path (a backbone) as a Path, checked.

    :raises ValueError: malformed bytes, no poses, another frame or a non-finite pose
    """
    from nav_msgs.msg import Path
    from rclpy.serialization import deserialize_message
    try:
        path = deserialize_message(data, Path)
    except Exception as error:  # rclpy raises RMWError on bad bytes
        raise ValueError('malformed Path: %s' % error) from None
    points = [(p.pose.position.x, p.pose.position.y, p.pose.position.z,
               p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
               p.pose.orientation.w) for p in path.poses]
    if not points or path.header.frame_id != base_frame_id or not np.all(np.isfinite(points)):
        raise ValueError('unusable Path: %d poses, frame %r' % (len(points), path.header.frame_id))
    return path


def path_positions(path):
    """Return the positions of a Path as an (n, 3) array."""
    return np.array([(p.pose.position.x, p.pose.position.y, p.pose.position.z)
                     for p in path.poses], dtype=float).reshape(-1, 3)


def pose_position(pose):
    """Return the position of a Pose as a (3,) array."""
    return np.array((pose.position.x, pose.position.y, pose.position.z))

