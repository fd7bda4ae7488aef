"""statics: backbone shape and tip pose from measured cable lengths and a tip-load estimate.

Subscribes ``cable_states`` (sensor_msgs/JointState: measured cable lengths in m by name; best
effort) and ``tip_wrench``
(geometry_msgs/WrenchStamped in the base frame; zero until received and after it is older than
``tip_wrench_timeout``). Every measurement is solved with the numeric core, warm-started from the
last estimate, and published as ``backbone`` (nav_msgs/Path, ``path_samples`` poses base -> tip)
and ``tip_pose`` (geometry_msgs/PoseStamped), both latched, stamped with the measurement's stamp in
the robot's base frame. ``backbone_markers`` (visualization_msgs/MarkerArray) follows at
``marker_rate``; ``/diagnostics`` at 1 Hz.

Newest measurement, no backlog: ``cable_states`` is served by a thread of its own
(:mod:`~continuum_statics.nodes.dedicated_intake`) from a short queue (``input_queue_depth``) that
absorbs millisecond scheduling stalls; as soon as the oldest queued measurement is older than
``max_input_lag`` the queue is drained and only the newest is solved. (With depth 1, stalls of a
few ms on a loaded 2-core machine lost 5-10 % of a 1 kHz stream.) Without the dedicated thread the
subscription is depth 1 on the executor.

Backbone and tip pose are published as serialized bytes filled from a template
(:class:`~continuum_statics.nodes.ros_conversions.PoseSequenceEncoder`): converting a Path
object costs rclpy ~0.2 ms, which matters at 1 kHz.

Bad input (unknown, repeated or missing names, size mismatch, NaN, a tip wrench in another frame)
is dropped with a throttled warning and counted on diagnostics; the last good state stays
published and nothing non-finite is ever published.
"""
import math
import sys
import time

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped, WrenchStamped
from nav_msgs.msg import Path
import numpy as np
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

from continuum_statics.core.backbone_sampling import BackboneSampler
from continuum_statics.core.rotations import rotation_to_quaternion
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.dedicated_intake import make_intake
from continuum_statics.nodes.marker_geometry import guide_and_cable_points
from continuum_statics.nodes.node_params import (
    ParameterTable,
    ParamSpec,
    diagnostics_rate_spec,
    load_robot_file,
    robot_file_spec,
)
from continuum_statics.nodes.ros_conversions import (
    BackboneMarkers,
    PoseSequenceEncoder,
    cable_index,
    parse_joint_state,
    tip_load,
)

#: Newest measurement only: best effort, keep last 1 (a slow cycle never builds a backlog).
LATEST_SENSOR_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                               reliability=ReliabilityPolicy.BEST_EFFORT,
                               durability=DurabilityPolicy.VOLATILE)
#: Latched state (backbone, tip_pose, markers): reliable, depth 1, transient local.
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
THROTTLE_S = 2.0


class StaticsNode(Node):
    """Shape estimation at the measurement rate: a thin layer over ``Robot.estimate_shape``."""

    EXECUTOR = 'single'

    def __init__(self, node_name='statics', **kwargs):
        super().__init__(node_name, **kwargs)
        specs = [
            robot_file_spec('rod, base frame, cables, guides'),
            diagnostics_rate_spec(),
            ParamSpec('path_samples', 20, 'poses in each backbone Path, base to tip', 2, 500),
            ParamSpec('marker_rate', 30.0, 'backbone_markers rate, Hz (0: off)', 0.0, 200.0),
            ParamSpec('tip_wrench_timeout', 1.0, 'a tip_wrench estimate older than this is '
                      'replaced by zero, s (0: never expires)', 0.0, 3600.0),
            ParamSpec('max_residual', 1e-4, 'an estimate whose cable-length residual (RMS) is '
                      'above this is rejected and the last good shape kept, m', 0.0, 1.0),
            ParamSpec('tube_diameter', 0.006, 'diameter of the rod drawn in RViz, m', 1e-4, 0.2),
            ParamSpec('dedicated_intake_thread', True, 'serve cable_states from a thread of its '
                      'own instead of the executor (~0.3 ms less per message)', read_only=True),
            ParamSpec('input_queue_depth', 10, 'cable_states queue (dedicated intake thread '
                      'only; the executor path keeps depth 1): absorbs scheduling stalls', 1, 100,
                      read_only=True),
            ParamSpec('max_input_lag', 0.005, 'when the oldest queued cable_states was received '
                      'longer ago than this, skip to the newest, s', 0.0, 1.0, read_only=True),
        ]
        self._params = ParameterTable(self, specs)
        self.robot = load_robot_file(self._params['robot_file'])
        self.cable_names = tuple(self.robot.cable_names)
        self.base_frame_id = self.robot.base_frame_id
        self._disk_diameter = 2.0 * float(np.max(np.linalg.norm(
            np.asarray(self.robot.cable_offsets, dtype=float).reshape(-1, 3), axis=1),
            initial=0.005)) + 0.006

        # Hot-path state: the serialized name list of the last good message and its index map.
        self._name_bytes = None
        self._index = None
        self._lengths = np.empty(len(self.cable_names))
        self._u0 = None
        self._shape = None
        self._shape_is_new = False
        self._tip_load = np.zeros(6)
        self._wrench_time = None
        self._wrench_expired = False
        self._stamp = None
        self._tip_position = None
        self._path_encoder = PoseSequenceEncoder(self.base_frame_id,
                                                 self._params['path_samples'])
        self._tip_encoder = PoseSequenceEncoder(self.base_frame_id)
        # Compiles (or loads from the numba cache) now rather than on the first measurement.
        straight = self.robot.solve_ivp(np.zeros(3))
        self._sampler = BackboneSampler(straight.s, self._params['path_samples'])
        self._sampler.sample(straight.positions, straight.rotations)
        rotation_to_quaternion(straight.rotations[:1])
        self._markers = BackboneMarkers(self.get_name(), self._params['tube_diameter'],
                                        self._disk_diameter)
        self._last = {'residual': math.nan, 'iterations': 0, 'converged': False,
                      'message': 'waiting for cable_states', 'time': None}
        self._solve_times = diag.TimingWindow()
        self._cycle_times = diag.TimingWindow()
        self._input_rate = diag.RateMeter()
        self._output_rate = diag.RateMeter()
        self._problems = diag.Problems()
        self._not_converged = 0

        self._backbone_pub = self.create_publisher(Path, 'backbone', LATCHED_QOS)
        self._tip_pub = self.create_publisher(PoseStamped, 'tip_pose', LATCHED_QOS)
        self._marker_pub = self.create_publisher(MarkerArray, 'backbone_markers', LATCHED_QOS)
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        input_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST,
                               depth=self._params['input_queue_depth'],
                               reliability=ReliabilityPolicy.BEST_EFFORT,
                               durability=DurabilityPolicy.VOLATILE)
        self._intake = make_intake(self, self._params['dedicated_intake_thread'])
        self._input = self._intake.add(JointState, 'cable_states', self._on_cable_states,
                                       input_qos, raw=True, max_lag=self._params['max_input_lag'],
                                       fallback_qos=LATEST_SENSOR_QOS)
        self._intake.start()
        self.create_subscription(WrenchStamped, 'tip_wrench', self._on_tip_wrench,
                                 LATEST_SENSOR_QOS)
        self._marker_timer = None
        self._set_marker_timer(self._params['marker_rate'])
        self.create_timer(1.0 / self._params['diagnostics_rate'], self._publish_diagnostics)
        self._params.on_change = self._on_parameter_change
        self.get_logger().info('statics: robot %r, %d cables, frame %r, %d path samples' % (
            self.robot.name, len(self.cable_names), self.base_frame_id,
            self._params['path_samples']))

    # -- parameters ------------------------------------------------------------------------
    def _on_parameter_change(self, name, value):
        if name == 'marker_rate':
            self._set_marker_timer(value)

    def _set_marker_timer(self, rate):
        if self._marker_timer is not None:
            self.destroy_timer(self._marker_timer)
            self._marker_timer = None
        if rate > 0.0:
            self._marker_timer = self.create_timer(1.0 / rate, self._publish_markers)

    # -- inputs ----------------------------------------------------------------------------
    def _reject(self, kind, reason):
        self._problems.add(kind, reason)
        self.get_logger().warning('dropped %s: %s' % (kind, reason),
                                  throttle_duration_sec=THROTTLE_S)

    def _on_tip_wrench(self, msg):
        try:
            load = tip_load(msg, self.base_frame_id)
        except ValueError as error:
            self._reject('tip_wrench', error)
            return
        self._tip_load = load
        self._wrench_time = time.monotonic()
        if self._wrench_expired:
            self._wrench_expired = False
            self.get_logger().info('tip_wrench received again')

    def _current_tip_load(self, now):
        timeout = self._params['tip_wrench_timeout']
        if self._wrench_time is None or self._wrench_expired:
            return self._tip_load
        if timeout > 0.0 and now - self._wrench_time > timeout:
            self._wrench_expired = True
            self._tip_load = np.zeros(6)
            self.get_logger().warning(
                'tip_wrench estimate is older than %.3g s: using zero tip load' % timeout)
        return self._tip_load

    def _on_cable_states(self, data):
        """Solve one serialized JointState (raw subscription: parsed without a message object)."""
        start = time.perf_counter()
        self._input_rate.tick()
        try:
            view = parse_joint_state(data, self._name_bytes)
            if view.name_bytes != self._name_bytes:
                index = cable_index(view.names, self.cable_names)
                self._name_bytes, self._index = view.name_bytes, index
            positions = view.position
            if positions.shape[0] != self._index.shape[0]:
                raise ValueError('JointState has %d names but %d positions'
                                 % (self._index.shape[0], positions.shape[0]))
            if not (positions > 0.0).all():  # also false for NaN
                raise ValueError('cable length not a positive finite number for %s' % ', '.join(
                    self.cable_names[self._index[i]]
                    for i in np.flatnonzero(~(positions > 0.0))))
        except ValueError as error:
            self._reject('cable_states', error)
            return
        self._lengths[self._index] = positions
        load = self._current_tip_load(time.monotonic())
        try:
            estimate = self.robot.estimate_shape(self._lengths, load[:3], u0_guess=self._u0,
                                                 tip_moment=load[3:])
        except ValueError as error:
            self._reject('cable_states', error)
            return
        solved = time.perf_counter()
        self._solve_times.add(solved - start)
        self._last.update(residual=float(estimate.residual), iterations=estimate.iterations,
                          converged=bool(estimate.converged), message=estimate.message,
                          time=time.monotonic())
        if not estimate.converged:
            self._not_converged += 1
        if not estimate.residual <= self._params['max_residual']:
            # lengths no shape of this robot explains (slack cable, wrong robot file, bad
            # encoder): keep the last good shape rather than publish a best fit of nonsense
            self._reject('cable_states', 'cable lengths fit no shape: RMS residual %.3g m > '
                         'max_residual %.3g m%s' % (
                             estimate.residual, self._params['max_residual'],
                             '' if estimate.converged else ' (%s)' % estimate.message))
            return
        shape = estimate.shape
        samples = self._params['path_samples']
        sampler = self._sampler
        if not sampler.matches(shape.s, samples):
            sampler = self._sampler = BackboneSampler(shape.s, samples)
        points, quaternions = sampler.sample(shape.positions, shape.rotations)
        sec, nanosec = view.sec, view.nanosec
        if sec == 0 and nanosec == 0:  # unstamped measurement: stamp it on arrival
            now = self.get_clock().now().to_msg()
            sec, nanosec = now.sec, now.nanosec
        if self._path_encoder.count != samples:
            self._path_encoder = PoseSequenceEncoder(self.base_frame_id, samples)
        try:
            backbone = self._path_encoder.encode(sec, nanosec, points, quaternions)
            tip = self._tip_encoder.encode(sec, nanosec, points[-1], quaternions[-1])
        except ValueError as error:
            self._reject('shape', error)
            return
        self._backbone_pub.publish(backbone)
        self._tip_pub.publish(tip)
        self._u0 = estimate.u0
        self._stamp = (sec, nanosec)
        self._tip_position = points[-1]
        self._shape, self._shape_is_new = shape, True
        self._output_rate.tick()
        self._cycle_times.add(time.perf_counter() - start)

    # -- outputs ---------------------------------------------------------------------------
    def _publish_markers(self):
        if not self._shape_is_new:
            return
        self._shape_is_new = False
        shape, sampler = self._shape, self._sampler
        try:
            guide_points, guide_rotations, cable_points = guide_and_cable_points(
                shape.s, shape.positions, shape.rotations, self.robot.guides,
                self.robot.cable_offsets)
            positions, quaternions = sampler.sample(shape.positions, shape.rotations)
            self._markers.tube_diameter = self._params['tube_diameter']
            markers = self._markers.update(
                Header(frame_id=self.base_frame_id,
                       stamp=Time(sec=self._stamp[0], nanosec=self._stamp[1])),
                positions, quaternions,
                guide_points, rotation_to_quaternion(guide_rotations), cable_points)
        except ValueError as error:
            self._reject('markers', error)
            return
        self._marker_pub.publish(markers)

    def _publish_diagnostics(self):
        now = time.monotonic()
        self._current_tip_load(now)  # expire a stale tip load even while no measurement comes
        last = self._last
        input_rate = self._input_rate.report()
        output_rate = self._output_rate.report()
        solves, solve_median, solve_max = self._solve_times.report()
        _, cycle_median, cycle_max = self._cycle_times.report()
        level, message = diag.OK, 'estimating the shape'
        if last['time'] is None or now - last['time'] > 1.0:
            level, message = diag.WARN, 'no cable_states for over 1 s'
        if self._problems.recent(2.0):
            level, message = diag.WARN, 'rejected ' + self._problems.last_reason
        if last['time'] is not None and not last['converged'] and not (
                last['residual'] <= self._params['max_residual']):
            level, message = diag.WARN, 'estimate did not converge: %s' % last['message']
        wrench_age = math.inf if self._wrench_time is None else now - self._wrench_time
        values = {
            'status': message,
            'input_rate_hz': input_rate,
            'output_rate_hz': output_rate,
            'solves': solves,
            'received_total': self._input_rate.total,
            'published_total': self._output_rate.total,
            'input_skipped_total': self._input.skipped,
            'input_lost_total': self._input.lost,
            'solve_time_median_ms': solve_median,
            'solve_time_max_ms': solve_max,
            'cycle_time_median_ms': cycle_median,
            'cycle_time_max_ms': cycle_max,
            'residual_m': last['residual'],
            'iterations': last['iterations'],
            'converged': last['converged'],
            'not_converged_total': self._not_converged,
            'tip_force_n': ' '.join('%.4g' % f for f in self._tip_load[:3]),
            'tip_moment_nm': ' '.join('%.4g' % f for f in self._tip_load[3:]),
            'tip_wrench_age_s': wrench_age,
            'tip_wrench_expired': self._wrench_expired,
        }
        if self._tip_position is not None:
            values['tip_position_m'] = '%.5f %.5f %.5f' % tuple(self._tip_position)
        values.update(self._problems.values())
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))


    def destroy_node(self):
        """Stop the intake thread, then destroy the node."""
        self._intake.stop()
        return super().destroy_node()


def main(args=None):
    """Run the statics node (``ros2 run continuum_statics statics``)."""
    from continuum_statics.nodes.node_runner import run_nodes
    return run_nodes([StaticsNode], args)


if __name__ == '__main__':
    sys.exit(main())
