"""RViz markers: the backbone (tube by section, guide disks, cables) and the workspace."""
from geometry_msgs.msg import Point
import numpy as np
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from continuum_statics.core.statics.workspace import reachable_tips
from continuum_statics.nodes.ros_conversions import set_pose

#: Sentinels of :meth:`BackboneMarkers.encode`'s template: the k-th double is the bit pattern
#: ``base + k`` (finite, about 2**422 or 2**438) and every stamp's sec is the base's own mark. A
#: 4-aligned sec mark cannot lie inside a double sentinel (its halves are k < 2**24 and
#: 0x5A5A5A00 or 0x5B5B5B00). The template is made twice, with each base: rclpy leaves CDR
#: padding unset, so a byte pattern met in one serialization alone is leftover memory.
_DOUBLE_MARKS = (0x5A5A5A0000000000, 0x5B5B5B0000000000)
_SEC_MARKS = (0x5A5A5A5A, 0x5B5B5B5B)
_MARK_MASK = 0xFFFFFFFFFF000000


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

    def encode(self, frame_id, sec, nanosec, positions, quaternions, guide_positions,
               guide_quaternions, cable_points, point_sections=None, cable_sections=None):
        """Return the MarkerArray of :meth:`update` serialized (CDR bytes for ``publish``).

        rclpy takes ~0.3 ms to convert this many Marker objects to C and the objects ~0.15 ms to
        fill: at a 30 Hz marker rate that delays a 1 kHz estimate in the same process. The
        layout only changes with the counts, sections and diameters, so rclpy serializes it once
        with sentinel values, the sentinels' byte offsets are located, and each call writes the
        new doubles and stamps there with numpy (tens of us). The bytes deserialize to the
        message of :meth:`update`; a test checks that.

        :raises ValueError: on a non-finite input
        """
        cable_points = [np.asarray(points, dtype=float).reshape(-1, 3)
                        for points in cable_points]
        positions = np.asarray(positions, dtype=float).reshape(-1, 3)
        quaternions = np.asarray(quaternions, dtype=float).reshape(-1, 4)
        guide_positions = np.asarray(guide_positions, dtype=float).reshape(-1, 3)
        guide_quaternions = np.asarray(guide_quaternions, dtype=float).reshape(-1, 4)
        values = np.concatenate([positions.ravel(), quaternions[-1], guide_positions.ravel(),
                                 guide_quaternions.ravel()] + [c.ravel() for c in cable_points])
        if not np.all(np.isfinite(values)):
            raise ValueError('refusing to publish markers with non-finite points')
        key = (frame_id, len(positions), len(guide_positions),
               tuple(len(c) for c in cable_points), self.tube_diameter,
               None if point_sections is None else tuple(int(k) for k in point_sections),
               None if cable_sections is None else tuple(int(k) for k in cable_sections))
        if key != getattr(self, '_template_key', None):
            self._template = self._make_template(frame_id, positions, guide_positions,
                                                 cable_points, point_sections, cable_sections)
            self._template_key = key
        if self._template is None:  # no clean template (never seen): rclpy serializes it
            from builtin_interfaces.msg import Time
            from rclpy.serialization import serialize_message
            from std_msgs.msg import Header

            return serialize_message(self.update(
                Header(frame_id=frame_id, stamp=Time(sec=int(sec), nanosec=int(nanosec))),
                positions, quaternions, guide_positions, guide_quaternions, cable_points,
                point_sections, cable_sections))
        buffer, doubles, int32, uint32, slots, sources, stamps = self._template
        doubles[slots] = values[sources]
        int32[stamps] = sec
        uint32[stamps + 1] = nanosec
        return bytes(buffer)

    def _make_template(self, frame_id, positions, guide_positions, cable_points, point_sections,
                       cable_sections):
        """Serialize :meth:`update` of sentinel values; return where every value goes.

        Returns (buffer, its float64, int32 and uint32 views, the double slots, the value each
        takes, the stamps' int32 slots), or None when the sentinels are not found exactly once
        per value (twice for the tip position, which is the tube's last point too) in both
        serializations.
        """
        from builtin_interfaces.msg import Time
        from rclpy.serialization import serialize_message
        from std_msgs.msg import Header

        sizes = [positions.size, 4, guide_positions.size, 4 * len(guide_positions)] + [
            c.size for c in cable_points]
        count = sum(sizes)
        found = []
        for base, sec_mark in zip(_DOUBLE_MARKS, _SEC_MARKS):
            marks = (np.uint64(base) + np.arange(count, dtype=np.uint64)).view('<f8')
            parts = np.split(marks, np.cumsum(sizes)[:-1])
            tip_quaternion = np.tile(parts[1], (len(positions), 1))  # only the last is drawn
            self.update(Header(frame_id=frame_id, stamp=Time(sec=sec_mark, nanosec=0)),
                        parts[0].reshape(-1, 3), tip_quaternion, parts[2].reshape(-1, 3),
                        parts[3].reshape(-1, 4), [p.reshape(-1, 3) for p in parts[4:]],
                        point_sections, cable_sections)
            buffer = bytearray(serialize_message(self.array))
            body = memoryview(buffer)[4:]  # after the encapsulation header: CDR alignment
            words = np.frombuffer(body[:len(body) // 8 * 8], dtype='<u8')
            slots = np.flatnonzero(words & np.uint64(_MARK_MASK) == np.uint64(base))
            int32 = np.frombuffer(body[:len(body) // 4 * 4], dtype='<i4')
            found.append((buffer, body, slots, (words[slots] - np.uint64(base)).astype(np.intp),
                          np.flatnonzero(int32 == sec_mark)))
        (buffer, body, slots, sources, stamps), other = found
        if not (np.array_equal(slots, other[2]) and np.array_equal(sources, other[3])
                and np.array_equal(stamps, other[4]) and len(slots) == count + 3
                and len(np.unique(sources)) == count and len(stamps) == len(self.array.markers)):
            return None
        return (buffer, np.frombuffer(body[:len(body) // 8 * 8], dtype='<f8'),
                np.frombuffer(body[:len(body) // 4 * 4], dtype='<i4'),
                np.frombuffer(body[:len(body) // 4 * 4], dtype='<u4'), slots, sources, stamps)

def workspace_markers(frame_id, tips, diameter=0.004):
    """Return a translucent SPHERE_LIST of reachable tip positions (m): RViz click targets."""
    marker = Marker(ns='workspace', id=0, type=Marker.SPHERE_LIST, action=Marker.ADD)
    marker.header.frame_id = frame_id
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = float(diameter)
    marker.color = _color((0.6, 0.6, 0.6, 0.35))
    _set_points(marker, np.reshape(tips, (-1, 3)))
    return MarkerArray(markers=[marker])


def publish_workspace(node, robot, samples, qos):
    """Publish ``samples`` reachable tips of ``robot`` on ``workspace_markers`` (latched ``qos``).

    Nothing for a robot without cables (it reaches nothing). Returns the publisher or None.
    """
    if not robot.cable_names:
        return None
    publisher = node.create_publisher(MarkerArray, 'workspace_markers', qos)
    publisher.publish(workspace_markers(robot.base_frame_id,
                                        reachable_tips(robot, samples, seed=0)))
    return publisher

