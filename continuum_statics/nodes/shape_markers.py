"""The statics node's ``backbone_markers``: drawn after a published shape, at most ``marker_rate``.

Markers are built by the thread that published the shape, right after it, once ``1/marker_rate``
has passed since the last ones (a timer only draws a shape whose measurements stopped). Built
on the executor's thread instead, the 0.5 ms Python build held the GIL while the intake thread
waited with the next measurement: it alone raised the p99 latency at 1 kHz from 1.2-1.9 ms to
3.1-3.5 ms.

With obstacles (the robot file's or the ``obstacles`` topic's) the array also holds them and the
contacts of the shape (:mod:`.obstacle_markers`), and it is serialized by rclpy (the template
holds the rod only; a contact solve costs far more than that); a changed obstacle set is drawn
at the next period even when no new shape came.
"""
import math
import threading
import time

from builtin_interfaces.msg import Time
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.nodes.marker_geometry import (
    guide_and_cable_points,
    section_layout,
    section_of,
)
from continuum_statics.nodes.markers import BackboneMarkers
from continuum_statics.nodes.obstacle_markers import ObstacleMarkers
from continuum_statics.nodes.qos import LATCHED_QOS
from continuum_statics.nodes.robot_description import disk_diameter
from continuum_statics.nodes.timers import steady_timer


class ShapeMarkers:
    """Draw the newest shape of a statics node as RViz markers.

    :param node: the statics node (publisher, timers, ``robot``, ``base_frame_id``)
    :param tube_diameter: callable returning the tube diameter parameter, m
    :param reject: ``reject(kind, reason)`` for a shape that cannot be drawn
    :param obstacles: the obstacles drawn (``current``, ``version``: an
        :class:`~continuum_statics.nodes.obstacle_topic.ObstacleTopic`), or None
    """

    def __init__(self, node, tube_diameter, reject, obstacles=None):
        self._node, self._tube_diameter, self._reject = node, tube_diameter, reject
        robot = node.robot
        self._markers = BackboneMarkers(node.get_name(), tube_diameter(), disk_diameter(robot))
        self._obstacles = obstacles
        self._obstacle_markers = ObstacleMarkers(node.get_name(), robot.length,
                                                 float(robot.c[0]) / robot.length ** 2)
        self._drawn_version = None
        # Multi-section robots: each cable drawn to its own end disk, the tube by section.
        self._cable_ends, self._section_ends = section_layout(robot)
        self._cable_sections = section_of(self._cable_ends, self._section_ends)
        # (shape, sampler, (sec, nanosec)) of the newest publication, set in one assignment:
        # the timer reads it from another thread; the last one drawn is kept by identity
        self.latest = self._drawn = None
        self._timer = None
        self._period = self._due = math.inf  # s; time.monotonic(), s
        self._lock = threading.Lock()  # the shape's thread or the timer, never both
        self._pub = node.create_publisher(MarkerArray, 'backbone_markers', LATCHED_QOS)

    def set_rate(self, rate):
        """Draw at most ``rate`` Hz (0: never)."""
        if self._timer is not None:
            self._node.destroy_timer(self._timer)
            self._timer = None
        with self._lock:  # not while a draw is setting the next due time
            self._period = 1.0 / rate if rate > 0.0 else math.inf
            self._due = 0.0 if rate > 0.0 else math.inf  # the next shape's are due
        if rate > 0.0:
            self._timer = steady_timer(self._node, self._period, self._flush)

    def published(self, shape, sampler, stamp):
        """Keep a published shape, and draw it when due."""
        self.latest = (shape, sampler, stamp)
        if time.monotonic() >= self._due:
            self._publish()

    def _flush(self):
        """Timer: the markers of a shape that no later measurement has drawn for a period."""
        if time.monotonic() >= self._due + self._period:
            self._publish()

    def _publish(self):
        if not self._lock.acquire(blocking=False):
            return  # the other thread is drawing them
        try:
            self._draw()
        finally:
            self._lock.release()

    def _draw(self):
        latest = self.latest
        obstacles = self._obstacles
        version = None if obstacles is None else obstacles.version
        if latest is None or (latest is self._drawn and version == self._drawn_version):
            return
        self._drawn, self._drawn_version = latest, version
        self._due = time.monotonic() + self._period
        shape, sampler, stamp = latest
        robot = self._node.robot
        frame_id = self._node.base_frame_id
        try:
            guide_points, guide_rotations, cable_points = guide_and_cable_points(
                shape.s, shape.positions, shape.rotations, robot.guides,
                robot.hole_offsets, self._cable_ends)
            positions, quaternions = sampler.sample(shape.positions, shape.rotations)
            self._markers.tube_diameter = self._tube_diameter()
            rod = (positions, quaternions, guide_points, rotation_to_quaternion(guide_rotations),
                   cable_points, section_of(sampler.s, self._section_ends),
                   self._cable_sections)
            header = Header(frame_id=frame_id, stamp=Time(sec=int(stamp[0]),
                                                          nanosec=int(stamp[1])))
            extra = [] if obstacles is None else self._obstacle_markers.markers(
                header, obstacles.current, getattr(shape, 'contacts', ()))
            if extra:  # obstacles drawn or deleted: rclpy serializes the whole array
                array = self._markers.update(header, *rod)
                markers = MarkerArray(markers=list(array.markers) + extra)
            else:
                markers = self._markers.encode(frame_id, *stamp, *rod)
        except ValueError as error:
            self._reject('markers', error)
            return
        self._pub.publish(markers)
