"""Backbone, tip pose and /tf serialized straight to CDR from a template (no message objects)."""
import math

import numpy as np


class _StampedPoses:
    """A CDR template with stamps and 7-double poses at known offsets, filled per message."""

    def _bind(self, writer, stamps, doubles):
        self._buffer = writer.buffer
        body = memoryview(self._buffer)[4:]
        self._int32 = np.frombuffer(body[:len(body) // 4 * 4], dtype='<i4')
        self._uint32 = np.frombuffer(body[:len(body) // 4 * 4], dtype='<u4')
        self._float64 = np.frombuffer(body[:len(body) // 8 * 8], dtype='<f8')
        self._sec = np.array(stamps, dtype=np.intp) // 4
        self._nanosec = self._sec + 1
        self._poses = np.array(doubles, dtype=np.intp).reshape(-1, 1) // 8 + np.arange(7)
        self._values = np.empty((len(doubles), 7))  # filled per message, checked, then copied

    def _fill(self, sec, nanosec, positions, quaternions):
        positions, quaternions = np.reshape(positions, (-1, 3)), np.reshape(quaternions, (-1, 4))
        values = self._values
        if positions.shape[0] != values.shape[0] or quaternions.shape[0] != values.shape[0]:
            raise ValueError('expected %d poses, got %d' % (values.shape[0], positions.shape[0]))
        values[:, :3] = positions
        values[:, 3:] = quaternions
        if not math.isfinite(values.sum()):  # NaN and inf both propagate into the sum
            raise ValueError('refusing to publish non-finite poses')
        self._int32[self._sec] = sec
        self._uint32[self._nanosec] = nanosec
        self._float64[self._poses] = values
        return bytes(self._buffer)


class PoseSequenceEncoder(_StampedPoses):
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
        self._bind(writer, stamps, doubles)

    def encode(self, sec, nanosec, positions, quaternions):
        """Return the serialized message for one stamp and (count, 3) / (count, 4) arrays.

        :raises ValueError: on a non-finite value or a wrong number of poses
        """
        return self._fill(sec, nanosec, positions, quaternions)


class TransformEncoder(_StampedPoses):
    """Serialize a tf2_msgs/TFMessage of ``parent`` -> each of ``children`` straight to CDR.

    The same template approach as :class:`PoseSequenceEncoder` (a geometry_msgs/Transform has
    the layout of a Pose: translation, then rotation [x, y, z, w]); every transform carries one
    stamp.

    :param parent: frame of every header, e.g. the base frame
    :param children: child frame ids, in the order of the poses given to :meth:`encode`
    """

    def __init__(self, parent, children):
        self.parent = parent
        self.children = tuple(children)
        writer = _CdrTemplate()
        writer.uint32(len(self.children))
        stamps, doubles = [], []
        for child in self.children:
            stamps.append(writer.header(parent))
            writer.string(child)
            doubles.append(writer.pose())
        self._bind(writer, stamps, doubles)

    def encode(self, sec, nanosec, translations, quaternions):
        """Return the serialized TFMessage for one stamp, (n, 3) m and (n, 4) [x, y, z, w].

        :raises ValueError: on a non-finite value or a wrong number of transforms
        """
        return self._fill(sec, nanosec, translations, quaternions)


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
        self.string(frame_id)
        return offset

    def string(self, text):
        """Write a CDR string (length with the terminating NUL, then the bytes)."""
        encoded = text.encode('utf-8') + b'\x00'
        self.uint32(len(encoded))
        self.buffer.extend(encoded)

    def pose(self):
        """Write an identity geometry_msgs/Pose; return the offset of its first double."""
        self._align(8)
        offset = len(self.buffer) - 4
        self.buffer.extend(np.array([0.0] * 6 + [1.0], dtype='<f8').tobytes())
        return offset
