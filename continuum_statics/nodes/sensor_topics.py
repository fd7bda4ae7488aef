"""statics' sensor topics and covariance outputs (issue 35, state estimation).

In: ``sensors/<name>`` (geometry_msgs/PoseStamped, or PoseWithCovarianceStamped for a sensor
with ``covariance: true``, whose position covariance is then the reading's noise) for each
sensor of the robot file, and ``tip_pose_measured`` (PoseStamped) for the one at the tip. A
position sensor reads the pose's position (its orientation is ignored); a pose sensor uses the
orientation when its quaternion is a unit one. Readings must be in the robot's base frame (an
empty frame id is taken as it): register a tracker's frame before publishing
(doc/state_estimation.md). Readings go to the shape tracker's
:class:`~continuum_statics.control.sensor_readings.SensorInbox`.

Out: ``sensors/<name>/accepted`` (PoseStamped), each reading the estimator used, as it came
(its header and pose): statics judges every sensor once, and tip_controller and
tip_load_estimator read the tip tracker from there (:func:`tracker_topic`), so a reading statics
set aside reaches no node.
With ``model_uncertainty``: ``tip_pose_covariance``
(geometry_msgs/PoseWithCovarianceStamped: the tip pose and its 6x6 covariance, ROS order x, y,
z, rotation about x, y, z) and ``backbone_estimate``
(continuum_statics_interfaces/msg/BackboneEstimate: the published backbone's poses with each
point's position covariance, 9 values per pose, row-major). Both latched like ``tip_pose``, at
most ``covariance_rate`` Hz.
"""
import math
import time

from geometry_msgs.msg import Pose, PoseStamped, PoseWithCovarianceStamped
import numpy as np

from continuum_statics.control.health import OK, WARN
from continuum_statics.nodes.qos import LATCHED_QOS, LATEST_SENSOR_QOS
from continuum_statics.nodes.ros_conversions import tracked_pose


class SensorTopics:
    """Subscriptions of a robot's sensors and publishers of the fused estimate's covariance."""

    def __init__(self, node, robot, inbox, rate=0.0):
        self.robot = robot
        # the covariance messages are built in Python (~0.15 ms with the backbone's): at most
        # ``rate`` Hz, not at the encoders' 1 kHz (0: with every estimate)
        self._period = 1.0 / rate if rate > 0.0 else 0.0
        self._last_published = -math.inf
        self.inbox = inbox  # the shape tracker's: it fuses what arrives here
        self._base = robot.base_frame_id
        self._clock = node.get_clock()  # the stamps' clock: a reading's age is judged by it
        self._node = node
        self._accepted = {sensor.name: node.create_publisher(
            PoseStamped, 'sensors/%s/accepted' % sensor.name, LATEST_SENSOR_QOS)
            for sensor in robot.sensors}
        self._topics = {}  # sensor name -> the topics its readings come in on
        for sensor in robot.sensors:
            topics = self._topics[sensor.name] = ['sensors/%s' % sensor.name]
            node.create_subscription(
                PoseWithCovarianceStamped if sensor.covariance else PoseStamped,
                topics[0], self._reader(sensor), LATEST_SENSOR_QOS)
            if sensor.at_tip and not any(s.at_tip for s in robot.sensors[:robot.sensors.index(
                    sensor)]):
                topics.append('tip_pose_measured')
                node.create_subscription(PoseStamped, topics[1], self._reader(sensor),
                                         LATEST_SENSOR_QOS)
        self._covariance_pub = self._backbone_pub = None
        if robot.model_uncertainty is not None:
            self._covariance_pub = node.create_publisher(PoseWithCovarianceStamped,
                                                         'tip_pose_covariance', LATCHED_QOS)
            message = _backbone_estimate_type()
            if message is not None:
                self._backbone_pub = node.create_publisher(message, 'backbone_estimate',
                                                           LATCHED_QOS)

    def _reader(self, sensor):
        def on_reading(msg):
            now = time.monotonic()
            try:
                position, rotation, stamp, sigma = tracked_pose(
                    msg, self._base, sensor.kind == 'pose', ' (register the sensor first)')
            except ValueError as error:
                self.inbox.reject(sensor.name, str(error))
                return
            # the node's max_stamp_offset (read each time: a parameter change holds at once);
            # a reading beyond it is set aside, not re-stamped as cable_states are
            self.inbox.max_offset = self._node.get_parameter('max_stamp_offset').value
            if isinstance(msg, PoseWithCovarianceStamped):  # accepted readings: PoseStamped
                msg = PoseStamped(header=msg.header, pose=msg.pose.pose)
            self.inbox.put(sensor.name, position, rotation, stamp * 1e-9 or None, now, sigma,
                           msg, self._clock.now().nanoseconds * 1e-9)
        return on_reading

    def publish(self, estimate, header, points, quaternions, s_samples):
        """Publish the covariance outputs of a published fused ``estimate``.

        ``header``: the backbone's (stamp, base frame); ``points`` (n, 3), ``quaternions``
        (n, 4) the published backbone at arc lengths ``s_samples`` (n,).
        """
        if self._covariance_pub is None or estimate.sensitivity is None:
            return
        now = time.monotonic()
        if now - self._last_published < self._period:
            return
        self._last_published = now
        tip = estimate.tip_covariance
        covariance = estimate.position_covariance
        if not (np.all(np.isfinite(tip)) and np.all(np.isfinite(covariance))):
            return  # never anything non-finite
        message = PoseWithCovarianceStamped()
        message.header = header
        message.pose.pose = _pose(points[-1], quaternions[-1])
        message.pose.covariance = [float(v) for v in tip.ravel()]
        self._covariance_pub.publish(message)
        if self._backbone_pub is None:
            return
        nodes = np.clip(np.searchsorted(estimate.shape.s, s_samples), 0, len(covariance) - 1)
        backbone = self._backbone_pub.msg_type()
        backbone.header = header
        backbone.s = [float(v) for v in s_samples]
        backbone.poses = [_pose(p, q) for p, q in zip(points, quaternions)]
        backbone.position_covariance = [float(v) for v in covariance[nodes].ravel()]
        self._backbone_pub.publish(backbone)

    def values(self):
        """Diagnostic values of every sensor."""
        return {} if self.inbox is None else self.inbox.values(time.monotonic())

    def problems(self):
        """WARN text of the sensors (set aside, silent, two streams), '' when all is well."""
        notes = [self.streams(), '' if self.inbox is None else self.inbox.problems(
            time.monotonic())]
        return '; '.join(note for note in notes if note)

    def streams(self):
        """Name each sensor read from more than one publisher ('' when none is).

        Its readings would be fused one after the other as one sensor's: two trackers on one
        topic, or one on ``sensors/<name>`` and another on ``tip_pose_measured``.
        """
        notes = []
        for name, topics in self._topics.items():
            counts = [(topic, self._node.count_publishers(topic)) for topic in topics]
            if sum(count for _, count in counts) > 1:
                notes.append('sensor %r has %d publishers (%s): two streams of one sensor '
                             'are fused as one; publish one, or name the second sensor in the '
                             'robot file' % (name, sum(count for _, count in counts), ', '.join(
                                 '%s: %d' % pair for pair in counts if pair[1])))
        return '; '.join(notes)

    def diagnose(self, level, message, values, tip_sigma):
        """Add every sensor's values and ``tip_sigma`` (mm) to ``values``; return the status.

        (level, message) as given, or WARN naming a sensor set aside or silent when it was OK.
        """
        values.update(self.values())
        values['tip_sigma_mm'] = tip_sigma
        note = self.problems()
        return (WARN, note) if note and level == OK else (level, message)

    def pass_on(self, estimate):
        """Republish on ``sensors/<name>/accepted`` each reading the estimate used, as judged."""
        verdicts = None if estimate is None else estimate.sensors
        for name, msg in self.inbox.used_sources(verdicts):
            self._accepted[name].publish(msg)


def tracker_topic(robot):
    """Return the topic a node reads the tip tracker from (one judgement of the sensor).

    statics' accepted readings of the robot file's tip sensor, or ``tip_pose_measured`` for a
    robot file without one.
    """
    for sensor in robot.sensors:
        if sensor.at_tip:
            return 'sensors/%s/accepted' % sensor.name
    return 'tip_pose_measured'


def tip_sigma_mm(estimate):
    """Return the fused tip position's standard deviation (mm, largest axis), or nan."""
    tip = None if estimate is None else estimate.tip_covariance
    if tip is None:
        return math.nan
    return 1e3 * math.sqrt(max(float(np.max(np.linalg.eigvalsh(tip[:3, :3]))), 0.0))


def _pose(point, quaternion):
    pose = Pose()
    pose.position.x, pose.position.y, pose.position.z = (float(v) for v in point)
    (pose.orientation.x, pose.orientation.y, pose.orientation.z,
     pose.orientation.w) = (float(v) for v in quaternion)
    return pose


def _backbone_estimate_type():
    """Return the BackboneEstimate message class, or None without the interfaces package."""
    try:
        from continuum_statics_interfaces.msg import BackboneEstimate
    except ImportError:
        return None
    return BackboneEstimate
