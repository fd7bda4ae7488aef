"""Stateless message <-> numpy helpers for the nodes (no physics here).

Validation happens at this boundary: every reader raises ``ValueError`` with a message a user can
act on (what was wrong, what was expected), so a node can log it, report it on diagnostics and drop
that input. Writers never emit a NaN: they raise instead.
"""
import math
import struct

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseStamped
import numpy as np
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker, MarkerArray

#: Quaternion of the identity rotation, [x, y, z, w].
IDENTITY_QUATERNION = (0.0, 0.0, 0.0, 1.0)


def stamp_to_seconds(stamp):
    """Return a builtin_interfaces/Time as float seconds."""
    return stamp.sec + stamp.nanosec * 1e-9


def seconds_to_stamp(seconds):
    """Return float seconds as a builtin_interfaces/Time."""
    nanoseconds = int(round(seconds * 1e9))
    return Time(sec=nanoseconds // 1_000_000_000, nanosec=nanoseconds % 1_000_000_000)


def is_zero_stamp(stamp):
    """Return True for an unset (zero) stamp."""
    return stamp.sec == 0 and stamp.nanosec == 0


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


def tip_load(msg, base_frame_id, max_force=math.inf, max_torque=math.inf):
    """Return a WrenchStamped in the base frame as a finite (6,) array: force (N), torque (N m).

    Each component is checked for finiteness first, then the magnitudes with ``math.hypot``
    (which cannot overflow), so a 1e155 N force is "too large", never "not finite".

    :param max_force: largest plausible force magnitude, N
    :param max_torque: largest plausible torque magnitude, N m
    :raises ValueError: on another frame, a non-finite component or an implausible magnitude
    """
    check_frame(msg.header.frame_id, base_frame_id, 'tip_wrench')
    force, torque = msg.wrench.force, msg.wrench.torque
    values = (force.x, force.y, force.z, torque.x, torque.y, torque.z)
    if not all(math.isfinite(v) for v in values):
        raise ValueError('tip_wrench has a non-finite component: force (%g, %g, %g), '
                         'torque (%g, %g, %g)' % values)
    force_norm, torque_norm = math.hypot(*values[:3]), math.hypot(*values[3:])
    if force_norm > max_force:
        raise ValueError('tip_wrench force %.3g N is too large (max_tip_force %.3g N)'
                         % (force_norm, max_force))
    if torque_norm > max_torque:
        raise ValueError('tip_wrench torque %.3g N m is too large (max_tip_torque %.3g N m)'
                         % (torque_norm, max_torque))
    return np.array(values)


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


def path_positions(path):
    """Return the positions of a Path as an (n, 3) array."""
    return np.array([(p.pose.position.x, p.pose.position.y, p.pose.position.z)
                     for p in path.poses], dtype=float).reshape(-1, 3)


def pose_position(pose):
    """Return the position of a Pose as a (3,) array."""
    return np.array((pose.position.x, pose.position.y, pose.position.z))


def make_header(stamp, frame_id):
    """Return a std_msgs/Header."""
    return Header(stamp=stamp, frame_id=frame_id)


def _color(rgba):
    return ColorRGBA(r=float(rgba[0]), g=float(rgba[1]), b=float(rgba[2]), a=float(rgba[3]))


def _set_points(marker, array):
    """Write (k, 3) points into ``marker.points``, reusing its Point objects."""
    values = np.asarray(array, dtype=float).tolist()
    points = marker.points
    if len(points) != len(values):
        points = [Point() for _ in values]
        marker.points = points
    for point, (x, y, z) in zip(points, values):
        point.x, point.y, point.z = x, y, z


#: Tube colour of each section, base to tip (RGBA), repeated beyond the fourth.
SECTION_COLORS = ((0.85, 0.55, 0.15, 1.0), (0.2, 0.6, 0.85, 1.0), (0.45, 0.75, 0.3, 1.0),
                  (0.75, 0.35, 0.7, 1.0))


class BackboneMarkers:
    """RViz markers of a backbone (tube, guide disks, cables, tip arrow), updated in place.

    The Marker objects are made once and only their poses and points change, which keeps a
    30 Hz marker stream cheap. Marker ids are stable, so RViz updates rather than adds.

    :param namespace: prefix of the marker namespaces
    :param tube_diameter: drawn rod diameter, m (cables are drawn a quarter as thick)
    :param disk_diameter: guide-disk diameter, m
    :param disk_thickness: guide-disk thickness, m
    """

    def __init__(self, namespace='continuum', tube_diameter=0.006, disk_diameter=0.026,
                 disk_thickness=0.002):
        self.namespace = namespace
        self.tube_diameter = float(tube_diameter)
        self.disk_diameter = float(disk_diameter)
        self.disk_thickness = float(disk_thickness)
        self._tube = self._marker('backbone', 0, Marker.LINE_STRIP, (0.85, 0.55, 0.15, 1.0))
        self._tip = self._marker('tip', 0, Marker.ARROW, (0.9, 0.1, 0.1, 1.0))
        # An arrow points along its local x: the tip frame's x axis is drawn.
        self._tip.scale.x, self._tip.scale.y, self._tip.scale.z = 0.03, 0.003, 0.003
        self._disks = []
        self._cables = []
        self.array = MarkerArray()

    def _marker(self, name, marker_id, marker_type, rgba):
        marker = Marker(ns='%s/%s' % (self.namespace, name), id=marker_id, type=marker_type,
                        action=Marker.ADD)
        marker.pose.orientation.w = 1.0
        marker.color = _color(rgba)
        return marker

    def update(self, header, positions, quaternions, guide_positions, guide_quaternions,
               cable_points, point_sections=None, cable_sections=None):
        """Return the MarkerArray for one backbone.

        :param header: frame and stamp of every marker
        :param positions: (n, 3) backbone points base -> tip, m
        :param quaternions: (n, 4) backbone orientations [x, y, z, w]
        :param guide_positions: (n_guides, 3) guide-disk centres, m
        :param guide_quaternions: (n_guides, 4) guide-disk orientations (normal = local z)
        :param cable_points: per cable a (k, 3) array of points, base exit -> its end disk, m
        :param point_sections: (n,) section index of each backbone point: the tube is coloured
            by section (None: one colour)
        :param cable_sections: (n_cables,) section index of each cable, for its colour
        :raises ValueError: on a non-finite input (nothing is changed then)
        """
        arrays = [np.asarray(a, dtype=float) for a in (
            positions, quaternions, guide_positions, guide_quaternions)]
        cable_points = [np.asarray(points, dtype=float) for points in cable_points]
        if not all(np.all(np.isfinite(a)) for a in arrays + cable_points):
            raise ValueError('refusing to publish markers with non-finite points')
        positions, quaternions, guide_positions, guide_quaternions = arrays
        while len(self._disks) < len(guide_positions):
            disk = self._marker('guides', len(self._disks), Marker.CYLINDER,
                                (0.6, 0.6, 0.65, 0.8))
            disk.scale.x = disk.scale.y = self.disk_diameter
            disk.scale.z = self.disk_thickness
            self._disks.append(disk)
        del self._disks[len(guide_positions):]
        while len(self._cables) < len(cable_points):
            cable = self._marker('cables', len(self._cables), Marker.LINE_STRIP,
                                 (0.1, 0.4, 0.9, 1.0))
            self._cables.append(cable)
        del self._cables[len(cable_points):]
        self._tube.scale.x = self.tube_diameter
        _set_points(self._tube, positions)
        if point_sections is not None and len(point_sections) == len(positions):
            self._tube.colors = [_color(SECTION_COLORS[k % len(SECTION_COLORS)])
                                 for k in point_sections]
        else:
            self._tube.colors = []
        set_pose(self._tip.pose, positions[-1].tolist(), quaternions[-1].tolist())
        for disk, position, quaternion in zip(self._disks, guide_positions.tolist(),
                                              guide_quaternions.tolist()):
            set_pose(disk.pose, position, quaternion)
        for index, (cable, points) in enumerate(zip(self._cables, cable_points)):
            cable.scale.x = self.tube_diameter * 0.25
            if cable_sections is not None:
                rgba = SECTION_COLORS[int(cable_sections[index]) % len(SECTION_COLORS)]
                cable.color = _color((0.6 * rgba[0], 0.6 * rgba[1], 0.6 * rgba[2], 1.0))
            _set_points(cable, points)
        markers = [self._tube] + self._disks + self._cables + [self._tip]
        for marker in markers:
            marker.header = header
        self.array.markers = markers
        return self.array


class PoseSequenceEncoder:
    """Serialize a nav_msgs/Path or geometry_msgs/PoseStamped straight to CDR bytes.

    rclpy spends ~0.2 ms converting a 20-pose Path object to C before publishing it; the layout of
    these messages is fixed once the frame and the pose count are, so a template is filled with
    numpy instead (~10 us) and published as serialized bytes (``Publisher.publish(bytes)``).
    The bytes equal ``rclpy.serialization.serialize_message`` of the same message (XCDR1, little
    endian, as the ROS 2 DDS middlewares use); the tests check that.

    :param frame_id: frame of the header (and of every pose header of a Path)
    :param count: number of poses for a Path; None for a single PoseStamped
    """

    def __init__(self, frame_id, count=None):
        self.frame_id = frame_id
        self.count = count
        writer = _CdrTemplate()
        stamps = [writer.header(frame_id)]
        doubles = []
        if count is None:
            doubles.append(writer.pose())
        else:
            writer.uint32(count)
            for _ in range(count):
                stamps.append(writer.header(frame_id))
                doubles.append(writer.pose())
        self._buffer = writer.buffer
        body = memoryview(self._buffer)[4:]
        self._int32 = np.frombuffer(body[:len(body) // 4 * 4], dtype='<i4')
        self._uint32 = np.frombuffer(body[:len(body) // 4 * 4], dtype='<u4')
        self._float64 = np.frombuffer(body[:len(body) // 8 * 8], dtype='<f8')
        self._sec = np.array(stamps, dtype=np.intp) // 4
        self._nanosec = self._sec + 1
        self._poses = np.array(doubles, dtype=np.intp).reshape(-1, 1) // 8 + np.arange(7)

    def encode(self, sec, nanosec, positions, quaternions):
        """Return the serialized message for one stamp and (count, 3) / (count, 4) arrays.

        :raises ValueError: on a non-finite value or a wrong number of poses
        """
        values = np.hstack([np.reshape(positions, (-1, 3)), np.reshape(quaternions, (-1, 4))])
        if values.shape[0] != self._poses.shape[0]:
            raise ValueError('expected %d poses, got %d' % (self._poses.shape[0], values.shape[0]))
        if not np.all(np.isfinite(values)):
            raise ValueError('refusing to publish non-finite poses')
        self._int32[self._sec] = sec
        self._uint32[self._nanosec] = nanosec
        self._float64[self._poses] = values
        return bytes(self._buffer)


class _CdrTemplate:
    """Little-endian XCDR1 writer that records where stamps and poses go (offsets from origin)."""

    def __init__(self):
        self.buffer = bytearray(b'\x00\x01\x00\x00')  # encapsulation: CDR, little endian

    def _align(self, size):
        self.buffer.extend(b'\x00' * (-(len(self.buffer) - 4) % size))

    def uint32(self, value):
        self._align(4)
        self.buffer.extend(int(value).to_bytes(4, 'little'))

    def header(self, frame_id):
        """Write a std_msgs/Header with a zero stamp; return the stamp's offset."""
        self._align(4)
        offset = len(self.buffer) - 4
        self.buffer.extend(b'\x00' * 8)
        encoded = frame_id.encode('utf-8') + b'\x00'
        self.uint32(len(encoded))
        self.buffer.extend(encoded)
        return offset

    def pose(self):
        """Write an identity geometry_msgs/Pose; return the offset of its first double."""
        self._align(8)
        offset = len(self.buffer) - 4
        self.buffer.extend(np.array([0.0] * 6 + [1.0], dtype='<f8').tobytes())
        return offset


class JointStateView:
    """A serialized sensor_msgs/JointState, read without building a Python message.

    Parsing the CDR bytes directly skips building a Python message (~40 us at 1 kHz). ``names``
    and ``frame_id`` are decoded on first use, and only when ``name_bytes`` (the serialized name
    list, a cache key) differs from the previous message's, which for a driver's stream is never.
    Strings read as rclpy reads them: up to the first NUL, UTF-8 with replacement characters.

    :ivar sec: header stamp seconds; ``nanosec`` likewise (always < 1e9)
    :ivar name_bytes: the serialized ``name`` sequence (bytes, little-endian CDR) or, for a message
        rclpy decoded, a tuple: never a prefix of other bytes, so never a cache hit for them
    :ivar position: float array of ``position`` (no copy); ``velocity``, ``effort`` likewise
    """

    __slots__ = ('sec', 'nanosec', 'name_bytes', 'position', 'velocity', 'effort', '_names',
                 '_frame')

    def __init__(self, sec, nanosec, name_bytes, position, velocity, effort, names=None,
                 frame=None):
        self.sec, self.nanosec = sec, nanosec
        self.name_bytes, self.position, self._names = name_bytes, position, names
        self.velocity, self.effort, self._frame = velocity, effort, frame

    @property
    def names(self):
        """The ``name`` list, decoded on first use."""
        if self._names is None:
            self._names = _decode_string_sequence(self.name_bytes)
        return self._names

    @property
    def frame_id(self):
        """The header's ``frame_id``."""
        if isinstance(self._frame, bytes):
            self._frame = _cdr_text(self._frame)
        return self._frame


_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')
#: Encapsulation header of plain little-endian CDR (XCDR1), what the ROS 2 middlewares send.
CDR_LE = b'\x00\x01'
#: Smallest serialized JointState: encapsulation, stamp, empty frame_id, four empty sequences.
MIN_JOINT_STATE_BYTES = 32


def _aligned(offset, size):
    """Align a buffer offset (the CDR origin is byte 4, after the encapsulation header)."""
    return offset + (-(offset - 4) % size)


def _cdr_text(raw):
    """Decode CDR string bytes as rclpy does: up to the first NUL, UTF-8 with 'replace'."""
    return raw.split(b'\x00', 1)[0].decode('utf-8', 'replace')


def _decode_string_sequence(data):
    count, = _U32.unpack_from(data, 0)
    offset, names = 4, []
    for _ in range(count):
        offset += -offset % 4  # name_bytes starts 4-aligned relative to the CDR origin
        length, = _U32.unpack_from(data, offset)
        names.append(_cdr_text(data[offset + 4:offset + 4 + length]))
        offset += 4 + length
    return names


def _string_end(data, offset):
    """End of the CDR string at ``offset`` (4-aligned); ValueError when it runs past the end."""
    length, = _U32.unpack_from(data, offset)
    end = offset + 4 + length
    if end > len(data):
        raise ValueError('a string runs past the end')
    return end


def _float64_sequence(data, offset, what):
    """Return (array, end) of the float64 sequence whose length is at 4-aligned ``offset``."""
    count, = _U32.unpack_from(data, offset)
    offset += 4
    if not count:
        return np.empty(0), offset
    offset = _aligned(offset, 8)
    if count > (len(data) - offset) // 8:
        raise ValueError('%s runs past the end' % what)
    return np.frombuffer(data, dtype='<f8', count=count, offset=offset), offset + 8 * count


def check_stamp(sec, nanosec):
    """Raise ValueError unless ``nanosec`` < 1e9 (a builtin_interfaces/Time invariant)."""
    if not 0 <= nanosec < 1_000_000_000:
        raise ValueError('stamp nanosec %d is not below 1e9' % nanosec)


def parse_joint_state(data, previous_name_bytes=None):
    """Return a :class:`JointStateView` of serialized JointState ``data``.

    Accepts exactly what rclpy's deserializer accepts, with the same content (the fuzz tests
    check that against rclpy), except stamps with ``nanosec`` >= 1e9, which are rejected.

    :param previous_name_bytes: ``name_bytes`` of the last message: when the new little-endian
        message starts its name list with the same bytes they are reused, and nothing is decoded
    :raises ValueError: on an empty payload, malformed data or an invalid stamp
    """
    if len(data) == 0:
        raise ValueError('empty payload')
    if len(data) < MIN_JOINT_STATE_BYTES:
        # Never handed to rclpy: Fast CDR reads out of bounds (segfault) on a bare 4-byte
        # encapsulation header whose options announce padding.
        raise ValueError('malformed JointState (%d bytes, at least %d needed)'
                         % (len(data), MIN_JOINT_STATE_BYTES))
    if data[:2] != CDR_LE or len(data) < 4 or data[3] & 3:
        # big endian, another encapsulation, or padding announced in the options (rare, and
        # Fast CDR's reading of it is its own): let rclpy read it
        return _parse_with_rclpy(data)
    try:
        sec, nanosec = _STAMP.unpack_from(data, 4)
        frame_start = 16
        start = _aligned(_string_end(data, 12), 4)
        if isinstance(previous_name_bytes, bytes) and data.startswith(previous_name_bytes,
                                                                      start):
            end = start + len(previous_name_bytes)
        else:
            count, = _U32.unpack_from(data, start)
            if count > (len(data) - start - 4) // 4:  # every string takes 4 bytes or more
                raise ValueError('%d names cannot fit' % count)
            end = start + 4
            for _ in range(count):
                end = _string_end(data, _aligned(end, 4))
        position, offset = _float64_sequence(data, _aligned(end, 4), 'position')
        velocity, offset = _float64_sequence(data, _aligned(offset, 4), 'velocity')
        effort, offset = _float64_sequence(data, _aligned(offset, 4), 'effort')
    except (struct.error, ValueError) as error:
        raise ValueError('malformed JointState (%s)' % error) from None
    check_stamp(sec, nanosec)
    frame_end = 16 + _U32.unpack_from(data, 12)[0]
    return JointStateView(sec, nanosec, data[start:end], position, velocity, effort,
                          frame=data[frame_start:frame_end])


def _parse_with_rclpy(data):
    from rclpy.serialization import deserialize_message
    try:
        msg = deserialize_message(bytes(data), JointState)
    except Exception as error:  # rclpy raises RMWError (a RuntimeError) on bad bytes
        raise ValueError('malformed JointState (%s)' % str(error).splitlines()[0][:120]) from None
    stamp = msg.header.stamp
    check_stamp(stamp.sec, stamp.nanosec)
    names = list(msg.name)
    return JointStateView(stamp.sec, stamp.nanosec, ('rclpy',) + tuple(names),
                          np.asarray(msg.position, dtype=float),
                          np.asarray(msg.velocity, dtype=float),
                          np.asarray(msg.effort, dtype=float), names, msg.header.frame_id)
