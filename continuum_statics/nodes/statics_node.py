"""statics: backbone shape and tip pose from measured cable lengths and a tip-load estimate.

Subscribes ``cable_states`` (sensor_msgs/JointState: measured cable lengths in m by name; best
effort) and ``tip_wrench`` (geometry_msgs/WrenchStamped in the base frame; zero until received
and after ``tip_wrench_timeout``; a ``tip_wrench_estimate`` is kept). Each measurement is
solved, warm-started from the last estimate, and published as ``backbone`` (nav_msgs/Path,
``path_samples`` poses base -> tip) and ``tip_pose`` (geometry_msgs/PoseStamped), both latched,
stamped with the measurement's stamp in the robot's base frame. ``backbone_markers``
(visualization_msgs/MarkerArray) follows at ``marker_rate``, drawn by the thread that published
the shape (:mod:`.shape_markers` says why); ``/diagnostics`` at 1 Hz. Obstacles (the robot
file's and the ``obstacles`` topic's) rest the body in every solve; ``contacts`` goes out with
every shape (:mod:`.statics_obstacles`).

Newest measurement, no backlog: ``cable_states`` is served by a thread of its own from a short
queue (:mod:`~continuum_statics.nodes.dedicated_intake` says why); backbone and tip pose are
serialized from a template (:class:`~continuum_statics.nodes.pose_encoder.PoseSequenceEncoder`).
Sensors, covariances and, with the robot file's ``load_model``, the tip load estimated with the
shape (``tip_wrench_estimate``, ``tip_contact``): :mod:`.sensor_topics`, :mod:`.load_outputs`.

Two residual thresholds (RMS difference between the measured cable lengths and those of the
best-fitting shape, m). Up to ``warn_residual`` the lengths are a shape of the robot. Above it the
best fit is still published, with WARN and the residual on diagnostics: real encoders are noisy,
cables stretch and go slack, so measured lengths are rarely exactly a shape. Only above
``max_residual`` (no shape anywhere near: wrong robot file, broken cable, unhomed encoder), or
with lengths outside the robot file's limits by more than ``length_limit_margin``, is the input
dropped. ``length_noise_std`` (the encoders' noise, m) raises the thresholds to at least 3x
(warn) and 10x (drop) the noise, so noise alone never warns or drops.

A robot file without cables is a passive rod: its shape under gravity and ``tip_wrench`` is
published at start-up and whenever the tip load changes (``cable_states`` is not subscribed);
its /tf frames again at ``diagnostics_rate``, stamped now, for listeners that start later.

Stamps: outputs carry the measurement's stamp, unless it is further than ``max_stamp_offset``
from the node's clock or goes backwards (:mod:`continuum_statics.control.stamps`): then the
arrival time, with a throttled warning and a count on diagnostics. ``frame_prefix`` goes before
every frame on /tf (two arms from one robot file).

Bad input (unknown, repeated or missing names, size mismatch, NaN, an empty or malformed payload,
a stamp with nanosec >= 1e9, a tip wrench in another frame or beyond ``max_tip_force`` /
``max_tip_torque``) is dropped with a throttled warning and counted on diagnostics; the last good
state stays published and nothing non-finite is ever published.
"""
import math
import sys
import time

from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from continuum_statics.control.health import StaticsHealth, load_values
from continuum_statics.control.records import TipLoadInput
from continuum_statics.control.shape_tracking import ShapeTracker, Thresholds, passive_shape
from continuum_statics.control.stamps import StampRule
from continuum_statics.core.description.tendons import full_circle_tension
from continuum_statics.core.rod.backbone_sampling import BackboneSampler
from continuum_statics.core.warmup import warm_up
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.dedicated_intake import make_intake
from continuum_statics.nodes.joint_state_parser import CableStatesReader
from continuum_statics.nodes.node_params import (
    ParameterTable,
    load_robot_file,
    tip_wrench_limits,
    tip_wrench_topic,
)
from continuum_statics.nodes.node_runner import RunnerHooks, run_nodes
from continuum_statics.nodes.parameter_tables import statics_parameters
from continuum_statics.nodes.pose_encoder import PoseSequenceEncoder
from continuum_statics.nodes.qos import LATCHED_QOS, LATEST_SENSOR_QOS, measurement_queue_qos
from continuum_statics.nodes.robot_description import publish_robot_description
from continuum_statics.nodes.ros_conversions import tip_load
from continuum_statics.nodes.sensor_topics import SensorTopics, tip_sigma_mm
from continuum_statics.nodes.shape_markers import ShapeMarkers
from continuum_statics.nodes.statics_obstacles import StaticsObstacles
from continuum_statics.nodes.tf_outputs import republish_tf, tf_outputs
from continuum_statics.nodes.timers import steady_timer

NS = 1_000_000_000


class StaticsNode(RunnerHooks, Node):
    """Shape estimation at the measurement rate: a thin layer over ``Robot.estimate_shape``."""

    EXECUTOR = 'single'

    def __init__(self, node_name='statics', **kwargs):
        super().__init__(node_name, **kwargs)
        specs = statics_parameters()
        self._params = ParameterTable(self, specs)
        self.robot = load_robot_file(self._params['robot_file'], self.get_logger())
        # Compile every kernel now, on this thread, before any input can arrive (numba compiles
        # at first use otherwise: seconds without output, and crashes when two threads compile).
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        diag.publish_starting(self, self._diagnostics, self.robot.name, 'compiling kernels')
        warm_up(self.robot, self.get_logger().info)
        self.cable_names = tuple(self.robot.cable_names)
        self._passive = not self.cable_names
        self._tracker = ShapeTracker(self.robot, self.cable_names, self._params['max_iterations'],
                                     self._params['max_model_runs'],
                                     self._params['sensor_timeout'])
        self.base_frame_id = self.robot.base_frame_id

        # Hot path: the name index of the last good message is kept; no array allocated.
        self._cable_states = CableStatesReader(self.cable_names)
        self._lengths = np.empty(len(self.cable_names))
        self._tensions = np.empty(len(self.cable_names))
        topic = tip_wrench_topic(self._params, self.robot)
        self._tip_load = TipLoadInput(topic, topic == 'tip_wrench_estimate',
                                      self.get_logger().warning, self.get_logger().info)
        self._stamp = None
        self._tip_position = None
        self._tip_sigma = math.nan  # the fused tip's largest standard deviation, mm
        self._path_encoder = PoseSequenceEncoder(self.base_frame_id,
                                                 self._params['path_samples'])
        self._tip_encoder = PoseSequenceEncoder(self.base_frame_id)
        self._sampler = BackboneSampler(self.robot.s_grid, self._params['path_samples'])
        self.health = StaticsHealth(self.cable_names, self.get_logger().warning, self._passive)
        self._problems = self.health.problems
        self._full_circle_tension = full_circle_tension(self.robot)

        self._backbone_pub = self.create_publisher(Path, 'backbone', LATCHED_QOS)
        self._tip_pub = self.create_publisher(PoseStamped, 'tip_pose', LATCHED_QOS)
        self._tf = tf_outputs(self, self.robot, self._params['tip_frame_id'],
                              self._params['tf_disks'], self._params['frame_prefix']) \
            if self._params['publish_tf'] else None
        self._description = publish_robot_description(  # latched URDF, links = the /tf frames
            self, self.robot, self._params['tip_frame_id'], self._params['tf_disks'],
            self._params['frame_prefix'])
        self._stamps = StampRule(self._params['max_stamp_offset'])
        self._obstacles = StaticsObstacles(  # a passive rod re-solves on an obstacle change
            self, self._tracker, (lambda: self._solve_passive(None)) if self._passive else None)
        self._markers = ShapeMarkers(self, lambda: self._params['tube_diameter'],
                                     self._problems.reject, self._obstacles.topic)
        # before the intake starts: its thread reads the sensors from the first message on
        self._sensors = (SensorTopics(self, self.robot, self._tracker.inbox,
                                      self._params['covariance_rate'],
                                      (self._params['contact_threshold'],
                                       self._params['contact_min_time']))
                         if self.robot.sensors or self.robot.model_uncertainty else None)
        self._intake = make_intake(self, self._params['dedicated_intake_thread'])
        self._input = None
        if not self._passive:  # a passive rod has nothing to measure
            self._input = self._intake.add(
                JointState, 'cable_states', self._on_cable_states,
                measurement_queue_qos(self._params['input_queue_depth']), raw=True,
                max_lag=self._params['max_input_lag'], fallback_qos=LATEST_SENSOR_QOS)
            self._intake.start()
        self.create_subscription(WrenchStamped, self._tip_load.topic, self._on_tip_wrench,
                                 LATEST_SENSOR_QOS)
        self._markers.set_rate(self._params['marker_rate'])
        self._passive_load = None
        if self._passive:
            self._solve_passive(None)
        steady_timer(self, 1.0 / self._params['diagnostics_rate'], self._publish_diagnostics)
        self._params.on_change = self._on_parameter_change
        self.get_logger().info('statics: robot %r, %d cables, frame %r, %d path samples%s' % (
            self.robot.name, len(self.cable_names), self.base_frame_id,
            self._params['path_samples'],
            ' (passive rod: shape from gravity and tip_wrench)' if self._passive else ''))

    # -- parameters ------------------------------------------------------------------------
    def _on_parameter_change(self, name, value):
        if name == 'marker_rate':
            self._markers.set_rate(value)
        elif name == 'max_iterations':
            self._tracker.set_max_iterations(value)
        elif name == 'max_model_runs':
            self._tracker.max_model_runs = value

    # -- inputs ----------------------------------------------------------------------------
    def _on_tip_wrench(self, msg):
        force_limit, torque_limit = tip_wrench_limits(self.robot, self._params)
        try:
            load = tip_load(msg, self.base_frame_id, force_limit, torque_limit)
        except ValueError as error:
            self._problems.reject('tip_wrench', error)
            return
        self._tip_load.take(load)
        if self._passive:
            self._solve_passive(msg.header.stamp)

    def _current_tip_load(self):
        return self._tip_load.current(self._params['tip_wrench_timeout'])

    def _thresholds(self):
        """Return the residual thresholds (m) with the encoders' noise floor."""
        params = self._params
        return Thresholds.with_noise(params['warn_residual'], params['max_residual'],
                                     params['length_limit_margin'], params['length_noise_std'])

    def _on_cable_states(self, data):
        """Solve one serialized JointState (raw subscription: parsed without a message object)."""
        start = time.perf_counter()
        self.health.received(data)
        try:
            view, lengths = self._cable_states.read(data, self._lengths)
        except ValueError as error:
            self.health.rejected(error)
            return
        tensions = None
        if self._params['use_measured_tensions']:
            tensions, _ = self._cable_states.tensions(view, self._tensions)  # else unused
        result = self._tracker.update(lengths, tensions,
                                      self._current_tip_load(),
                                      self._thresholds(), self._tension_limit(),
                                      stamp=view.sec + 1e-9 * view.nanosec)
        if self._sensors is not None:
            self._sensors.pass_on(result.estimate)
        if result.load_problem:
            self._problems.reject('tip_wrench', result.load_problem)
            self._tip_load.drop()
        verdict = getattr(result.estimate, 'tensions_verdict', None)  # tension_noise in the file
        if verdict is not None and not verdict.used:
            self._problems.reject('tensions', 'set aside by the estimator: ' + verdict.reason)
        if result.estimate is None:
            self.health.rejected(result.rejection, result.outside_limits)
            return
        self.health.estimated(result, time.perf_counter() - start)
        if not result.rejection and self._publish_shape(result.estimate.shape, view.sec,
                                                        view.nanosec, 'cable_states',
                                                        result.estimate):
            self._tracker.accept(result)
            self.health.published(time.perf_counter() - start)

    def _tension_limit(self):
        """Largest plausible measured tension, N (max_tension, or the full-circle tension)."""
        return self._params['max_tension'] or self._full_circle_tension

    def _solve_passive(self, stamp):
        """Passive rod: solve and publish the shape under gravity and the current tip load."""
        load = self._current_tip_load().copy()
        key = (self._obstacles.version, load.tobytes())  # a new load or new obstacles
        if key == self._passive_load:
            return
        start = time.perf_counter()
        shape, problem = passive_shape(self.robot, load, self._tracker.obstacles)
        if shape is None:
            self._problems.reject('tip_wrench', problem)
            return
        sec, nanosec = (0, 0) if stamp is None else (stamp.sec, stamp.nanosec)
        if self._publish_shape(shape, sec, nanosec, 'tip_wrench'):
            self._passive_load = key
            self.health.published()
            self.health.solved_passive(time.perf_counter() - start)

    def _publish_shape(self, shape, sec, nanosec, stream, estimate=None):
        """Publish backbone and tip pose of ``shape``; return False if it was not finite.

        Stamped with the measurement's stamp (``stream``'s), unless the stamp rule replaces it.
        A fused ``estimate`` also publishes its covariances (:mod:`.sensor_topics`).
        """
        samples = self._params['path_samples']
        sampler = self._sampler
        if not sampler.matches(shape.s, samples):
            sampler = self._sampler = BackboneSampler(shape.s, samples)
        points, quaternions = sampler.sample(shape.positions, shape.rotations)
        stamp_ns, reason = self._stamps.judge(stream, sec * NS + nanosec,
                                              self.get_clock().now().nanoseconds)
        if reason:
            self._problems.reject('stamp', reason)
        sec, nanosec = divmod(stamp_ns, NS)
        if self._path_encoder.count != samples:
            self._path_encoder = PoseSequenceEncoder(self.base_frame_id, samples)
        try:
            backbone = self._path_encoder.encode(sec, nanosec, points, quaternions)
            tip = self._tip_encoder.encode(sec, nanosec, points[-1], quaternions[-1])
            if self._tf is not None:
                publisher, encoder, poses = self._tf
                transforms = encoder.encode(sec, nanosec, *poses.of(shape))
        except ValueError as error:
            self._problems.reject('shape', error)
            return False
        self._backbone_pub.publish(backbone)
        self._tip_pub.publish(tip)
        self._obstacles.published(shape, sec, nanosec, self._problems.reject)
        if self._tf is not None:
            publisher.publish(transforms)
        self._stamp = (sec, nanosec)
        self._tip_position = points[-1]
        if estimate is not None and self._sensors is not None:
            header = Header(frame_id=self.base_frame_id)
            header.stamp.sec, header.stamp.nanosec = int(sec), int(nanosec)
            self._sensors.publish(estimate, header, points, quaternions, sampler.s)
            self._tip_sigma = tip_sigma_mm(estimate)
        self._markers.published(shape, sampler, self._stamp)
        return True

    # -- outputs ---------------------------------------------------------------------------
    def _republish_tf(self):
        """Passive rod: its frames again, stamped now (a listener started later sees them)."""
        latest = self._markers.latest
        if self._tf is not None and latest is not None:
            republish_tf(self._tf, latest[0], self.get_clock().now().nanoseconds,
                         self._problems.reject)

    def _publish_diagnostics(self):
        if self._passive:
            self._solve_passive(None)  # a tip load that expired: back to the unloaded shape
            self._republish_tf()
        thresholds, intake = self._thresholds(), self._input
        level, message, values = self.health.report(
            thresholds.warn, thresholds.drop, 0 if intake is None else max(intake.lost, 0),
            0 if intake is None else intake.skipped, self.count_publishers('cable_states'))
        values['max_tension_n'] = self._tension_limit()
        values.update(self._stamps.values())
        values.update(load_values(
            self._current_tip_load(),  # expires a stale tip load while no measurement comes
            self._tip_load.age(), self._tip_load.expired,
            *tip_wrench_limits(self.robot, self._params)))
        if level == diag.OK and self._tip_load.status():
            level, message = diag.WARN, self._tip_load.status()
        if self._tip_position is not None:
            values['tip_position_m'] = '%.5f %.5f %.5f' % tuple(self._tip_position)
        if self._sensors is not None:
            level, message = self._sensors.diagnose(level, message, values, self._tip_sigma)
        level, message = self._obstacles.diagnose(level, message, values)
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))

    def on_node_failure(self, text):
        """Count a restart by the runner after a callback raised (on diagnostics)."""
        self._problems.add('node', text)

    def destroy_node(self):
        """Stop the intake thread, then destroy the node."""
        self._intake.stop()
        return super().destroy_node()


def main(args=None):
    """Run the statics node (``ros2 run continuum_statics statics``)."""
    return run_nodes([StaticsNode], args)


if __name__ == '__main__':
    sys.exit(main())
