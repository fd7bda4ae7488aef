"""Serialized sensor_msgs/JointState read without a Python message (the 1 kHz hot path).

Accepts exactly what rclpy's deserializer accepts, with the same content (differential fuzzing
in ``test/nodes/test_fuzz_joint_state.py``).
"""
import struct

import numpy as np
from sensor_msgs.msg import JointState

from continuum_statics.core.estimation.load_estimation import DEFAULT_NOISE, slack_band
from continuum_statics.nodes.ros_conversions import cable_index


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
#: How far below zero a measured tension is still a slack cable's zero, N: 3 sigma of the
#: default tension noise (0.15 N). Beyond it the effort is not a tension (a signed motor
#: current, a load cell's lost zero).
ZERO_BAND = slack_band(DEFAULT_NOISE['tension'])


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


def header_stamp_ns(data):
    """Return the header stamp (int ns) of any serialized stamped message, reading 12 bytes.

    Every message that starts with a std_msgs/Header (Path, PoseStamped, JointState) has its
    stamp right after the 4-byte encapsulation header, in the byte order that header names.

    :raises ValueError: fewer bytes than a stamp needs
    """
    try:
        byte_order = '<' if data[1:2] == b'\x01' else '>'  # CDR encapsulation header
        sec, nanosec = struct.unpack_from(byte_order + 'iI', data, 4)
    except struct.error:
        raise ValueError('malformed message (%d bytes)' % len(data)) from None
    return sec * 1_000_000_000 + nanosec


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


def check_cable_view(view, index, cable_names):
    """Check a parsed ``cable_states`` against its name ``index`` (one rule for every node).

    Lengths one per name, positive and finite; ``velocity`` and ``effort`` empty or one per
    cable. Raises ``ValueError`` naming what is wrong.
    """
    positions, n_cables = view.position, len(cable_names)
    if positions.shape[0] != index.shape[0]:
        raise ValueError('JointState has %d names but %d positions'
                         % (index.shape[0], positions.shape[0]))
    for what, values in (('velocity', view.velocity), ('effort', view.effort)):
        if values.shape[0] not in (0, n_cables):
            raise ValueError('JointState has %d names but %d %s values'
                             % (n_cables, values.shape[0], what))
    if not (positions > 0.0).all():  # also false for NaN
        raise ValueError('cable length not a positive finite number for %s' % ', '.join(
            cable_names[index[i]] for i in np.flatnonzero(~(positions > 0.0))))


class CableStatesReader:
    """Serialized ``cable_states`` -> checked lengths in robot order, for every node.

    The one rule every node applies to ``cable_states`` (:func:`check_cable_view`: every cable
    named once, a positive finite length each; velocity and effort empty or one per cable).

    Keeps the name index of the last good message, so a driver's stream decodes no names.
    """

    def __init__(self, cable_names):
        self.cable_names = tuple(cable_names)
        self._name_bytes, self.index = None, None

    def read(self, data, out=None):
        """Return (view, lengths (n,) m in robot order); ``ValueError`` says what is wrong.

        :param out: an (n,) array to write the lengths into (none allocated), or None
        """
        try:
            view = parse_joint_state(data, self._name_bytes)
            if view.name_bytes != self._name_bytes:
                self.index = cable_index(view.names, self.cable_names)
                self._name_bytes = view.name_bytes
            check_cable_view(view, self.index, self.cable_names)
        except ValueError:
            self._name_bytes = None
            raise
        lengths = np.empty(len(self.cable_names)) if out is None else out
        lengths[self.index] = view.position
        return view, lengths

    def tensions(self, view, out=None, zero_band=ZERO_BAND):
        """Return (tensions (n,) N in robot order, or None, and why not ('' when given)).

        ``effort`` is a tension only when finite and >= -``zero_band`` N for every cable (a
        signed motor current is not); a slack cable read a hair below zero (a load cell's noise,
        or -0.0) is zero. An empty ``effort`` gives (None, '').
        """
        if not view.effort.shape[0]:
            return None, ''
        tensions = np.empty(len(self.cable_names)) if out is None else out
        tensions[self.index] = view.effort
        if (tensions >= -zero_band).all() and np.isfinite(tensions).all():
            np.maximum(tensions, 0.0, out=tensions)
            return tensions, ''
        return None, 'effort (tensions) not finite and >= %g N: %s' % (
            -zero_band, np.round(tensions, 4).tolist())


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
