"""statics' sensor topics and covariance outputs (issue 35, state estimation).

In: ``sensors/<name>`` (geometry_msgs/PoseStamped, or PoseWithCovarianceStamped for a sensor
with ``covariance: true``, whose position covariance is then the reading's noise) for each
sensor of the robot file, and ``tip_pose_measured`` (PoseStamped) for the one at the tip. A
position sensor reads the pose's position (its orientation is ignored); a pose sensor uses the
orientation when its quaternion is a unit one. Readings must be in the robot's base frame (an
empty frame id is taken as the sensor's ``frame_id``, else the base frame). A sensor whose robot
file entry names another ``frame_id`` (a motion-capture frame) is read in that frame and mapped
into the base frame through the newest transforms of /tf and /tf_static (subscribed only then);
a reading whose frame has no chain to the base frame yet, or in a frame neither the sensor's
nor the base frame, is refused and its reason named on /diagnostics. Readings go to the shape
tracker's :class:`~continuum_statics.control.sensor_readings.SensorInbox`.

Out: ``sensors/<name>/accepted`` (PoseStamped), each reading the estimator used, with its
header and pose (in the base frame): statics judges every sensor once, and tip_controller and
tip_load_estimator read the tip tracker from there (:func:`tracker_topic`), so a reading statics
set aside reaches no node.
With ``model_uncertainty``: ``tip_pose_covariance``
(geometry_msgs/PoseWithCovarianceStamped: the tip pose and its 6x6 covariance, ROS order x, y,
z, rotation about x, y, z) and ``backbone_estimate``
(continuum_statics_interfaces/msg/BackboneEstimate: the published backbone's poses with each
point's position covariance, 9 values per pose, row-major). Both latched like ``tip_pose``, at
most ``covariance_rate`` Hz. With the file's ``load_model``: ``tip_wrench_estimate`` and
``tip_contact`` (:mod:`.load_outputs`).
"""
import math
import threading
import time

from geometry_msgs.msg import Pose, PoseStamped, PoseWithCovarianceStamped
import numpy as np

from continuum_statics.control.health import OK, WARN
from continuum_statics.core.rod.rotations import quaternion_to_rotation, rotation_to_quaternion
from continuum_statics.nodes.load_outputs import TipLoadOutputs
from continuum_statics.nodes.obstacle_messages import transforms_of
from continuum_statics.nodes.obstacle_set import FrameTree, frame_name
from continuum_statics.nodes.qos import LATCHED_QOS, LATEST_SENSOR_QOS, TF_QOS, TF_STATIC_QOS
from continuum_statics.nodes.ros_conversions import tracked_pose


class SensorTopics:
    """Subscriptions of a robot's sensors and publishers of the fused estimate's covariance."""

    def __init__(self, node, robot, inbox, rate=0.0, contact=(0.0, 0.2)):
        """``contact``: (contact_threshold N, contact_min_time s) of the file's load_model."""
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
        base = frame_name(self._base)
        self._frames = {sensor.name: frame_name(sensor.frame_id) or base
                        for sensor in robot.sensors}
        # the transforms of /tf and /tf_static arrive on their subscriptions' thread, readings
        # on theirs: the tree is read and written under this lock
        self._tree, self._tree_lock = FrameTree(), threading.Lock()
        if any(frame != base for frame in self._frames.values()):
            from tf2_msgs.msg import TFMessage
            node.create_subscription(TFMessage, '/tf', self._on_tf, TF_QOS)
            node.create_subscription(TFMessage, '/tf_static', self._on_tf, TF_STATIC_QOS)
        for sensor in robot.sensors:
            topics = self._topics[sensor.name] = ['sensors/%s' % sensor.name]
            node.create_subscription(
                PoseWithCovarianceStamped if sensor.covariance else PoseStamped,
                'sensors/%s' % sensor.name, self._reader(sensor), LATEST_SENSOR_QOS)
            if sensor.at_tip and not any(s.at_tip for s in robot.sensors[:robot.sensors.index(
                    sensor)]):
                topics.append('tip_pose_measured')
                node.create_subscription(PoseStamped, 'tip_pose_measured', self._reader(sensor),
                                         LATEST_SENSOR_QOS)
        self._covariance_pub = self._backbone_pub = None
        if robot.model_uncertainty is not None:
            self._covariance_pub = node.create_publisher(PoseWithCovarianceStamped,
                                                         'tip_pose_covariance', LATCHED_QOS)
            message = _backbone_estimate_type()
            if message is not None:
                self._backbone_pub = node.create_publisher(message, 'backbone_estimate',
                                                           LATCHED_QOS)
        self.load = (TipLoadOutputs(node, robot, *contact) if robot.load_model is not None
                     else None)

    def _on_tf(self, msg):
        with self._tree_lock:
            for parent, child, rotation, translation in transforms_of(msg):
                self._tree.set(parent, child, rotation, translation)

    def _in_base_frame(self, sensor, msg):
        """Return (position, rotation, stamp ns, sigma, turn) of a reading, in the base frame.

        ``turn``: the rotation (3, 3) from the reading's frame into the base frame, None when
        it is the base frame.

        :raises ValueError: a frame neither the sensor's nor the base frame, one without a
            transform chain to the base frame yet, a non-finite position
        """
        base, own = frame_name(self._base), self._frames[sensor.name]
        frame = frame_name(msg.header.frame_id) or own
        if frame not in (base, own):
            raise ValueError("frame %r is neither the base frame %r nor the sensor's frame_id "
                             '%r (name it in the robot file)' % (frame, base, own))
        position, rotation, stamp, sigma = tracked_pose(msg, msg.header.frame_id,
                                                        sensor.kind == 'pose')
        if frame == base:
            return position, rotation, stamp, sigma, None
        with self._tree_lock:
            transform = self._tree.lookup(frame, base)
        if transform is None:
            raise ValueError('frame %r has no transform chain to the base frame %r on /tf or '
                             '/tf_static' % (frame, base))
        turn, shift = transform
        return (turn @ position + shift, None if rotation is None else turn @ rotation, stamp,
                sigma, turn)

    def _reader(self, sensor):
        def on_reading(msg):
            now = time.monotonic()
            try:
                position, rotation, stamp, sigma, turn = self._in_base_frame(sensor, msg)
            except ValueError as error:
                self.inbox.reject(sensor.name, str(error), now)
                return
            # the node's max_stamp_offset (read each time: a parameter change holds at once);
            # a reading beyond it is set aside, not re-stamped as cable_states are
            self.inbox.max_offset = self._node.get_parameter('max_stamp_offset').value
            if isinstance(msg, PoseWithCovarianceStamped):  # accepted readings: PoseStamped
                msg = PoseStamped(header=msg.header, pose=msg.pose.pose)
            if turn is not None:  # passed on in the base frame
                msg = PoseStamped(header=msg.header, pose=_pose(position, _turned(
                    msg.pose.orientation, turn)))
                msg.header.frame_id = self._base
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
        if self.load is not None:
            self.load.publish(estimate, header)
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
        if self.load is not None:
            level, message = self.load.diagnose(level, message, values)
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


def _turned(orientation, turn):
    """Return [x, y, z, w] of ``orientation`` turned by ``turn`` (identity: not a unit one)."""
    quaternion = np.array([orientation.x, orientation.y, orientation.z, orientation.w])
    if not (np.all(np.isfinite(quaternion)) and abs(np.linalg.norm(quaternion) - 1.0) < 1e-3):
        return np.array([0.0, 0.0, 0.0, 1.0])
    return rotation_to_quaternion(turn @ quaternion_to_rotation(quaternion))


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
