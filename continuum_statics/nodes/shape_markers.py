"""The statics node's ``backbone_markers``: drawn after a published shape, at most ``marker_rate``.

Markers are built by the thread that published the shape, right after it, once ``1/marker_rate``
has passed since the last ones (a timer only draws a shape whose measurements stopped). Built
on the executor's thread instead, the 0.5 ms Python build held the GIL while the intake thread
waited with the next measurement: it alone raised the p99 latency at 1 kHz from 1.2-1.9 ms to
3.1-3.5 ms.
"""
import math
import threading
import time

from visualization_msgs.msg import MarkerArray

from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.nodes.marker_geometry import (
    guide_and_cable_points,
    section_layout,
    section_of,
)
from continuum_statics.nodes.markers import BackboneMarkers
from continuum_statics.nodes.qos import LATCHED_QOS
from continuum_statics.nodes.robot_description import disk_diameter
from continuum_statics.nodes.timers import steady_timer


class ShapeMarkers:
    """Draw the newest shape of a statics node as RViz markers.

    :param node: the statics node (publisher, timers, ``robot``, ``base_frame_id``)
    :param tube_diameter: callable returning the tube diameter parameter, m
    :param reject: ``reject(kind, reason)`` for a shape that cannot be drawn
    """

    def __init__(self, node, tube_diameter, reject):
        self._node, self._tube_diameter, self._reject = node, tube_diameter, reject
        robot = node.robot
        self._markers = BackboneMarkers(node.get_name(), tube_diameter(), disk_diameter(robot))
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
        if latest is None or latest is self._drawn:
            return
        self._drawn = latest
        self._due = time.monotonic() + self._period
        shape, sampler, stamp = latest
        robot = self._node.robot
        try:
            guide_points, guide_rotations, cable_points = guide_and_cable_points(
                shape.s, shape.positions, shape.rotations, robot.guides,
                robot.hole_offsets, self._cable_ends)
            positions, quaternions = sampler.sample(shape.positions, shape.rotations)
            self._markers.tube_diameter = self._tube_diameter()
            markers = self._markers.encode(
                self._node.base_frame_id, *stamp, positions, quaternions,
                guide_points, rotation_to_quaternion(guide_rotations), cable_points,
                section_of(sampler.s, self._section_ends), self._cable_sections)
        except ValueError as error:
            self._reject('markers', error)
            return
        self._pub.publish(markers)
