"""tip_load_estimator: the force on the tip from what the robot already measures.

Subscribes ``cable_states`` (lengths m; ``effort`` = cable tensions N where the driver measures
them) and, when a tracker publishes it, ``tip_pose_measured`` (geometry_msgs/PoseStamped of the
robot file's ``tip_marker``, base frame). At up to ``rate`` Hz, on the newest measurements, it
runs :meth:`Robot.estimate_tip_wrench` (warm-started from the previous estimate) and publishes:

- ``tip_wrench_estimate`` (geometry_msgs/WrenchStamped, base frame, the cable_states stamp);
  statics and tip_controller use it with ``tip_wrench_source: estimate``;
- ``/diagnostics``: the force, its standard deviations, the directions the measurements do not
  see (published as zero: never made up), timing; with ``load_model: weight`` (a payload along
  gravity) its mass and standard deviation (``mass_kg``, ``mass_sigma_kg``);
- ``tip_contact`` (std_msgs/Bool, latched): True while the force exceeds ``contact_threshold``
  with 3-sigma confidence (:mod:`continuum_statics.control.contact`), with a WARN diagnostic.

A robot whose cable_states carry no tensions and which has no tracker gives the estimator nothing
that sees a load: it says so on /diagnostics (WARN) and publishes no estimate. Nothing
non-finite is published; a failed estimate keeps the last good one (published again: statics
and tip_controller hold it, not zero load) and is counted.

What is published is decided by :class:`~continuum_statics.control.load_watch.LoadWatch`: a
measurement the model cannot explain (tensions beyond their limits, the chi-square gate, a
capped solve) is set aside with its reason on /diagnostics, never published as a load; an
unchanged measurement gives the same estimate; while the cables move the last estimate at rest
holds; contact needs ``contact_min_time``. Stamps follow :mod:`continuum_statics.control.
stamps` (``max_stamp_offset``); a callback that fails is counted and the node goes on.
"""
import dataclasses
import sys
import time

from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from continuum_statics.control.contact import force_along
from continuum_statics.control.load_watch import Inputs, LoadWatch, Verdict
from continuum_statics.control.stamps import StampRule
from continuum_statics.core.estimation.load_estimation import (
    load_model,
    plausible_tip_load,
    slack_band,
)
from continuum_statics.core.warmup import warm_up
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.joint_state_parser import CableStatesReader
from continuum_statics.nodes.node_params import ParameterTable, load_robot_file
from continuum_statics.nodes.node_runner import RunnerHooks, run_nodes
from continuum_statics.nodes.parameter_tables import tip_load_estimator_parameters
from continuum_statics.nodes.qos import LATCHED_QOS, LATEST_SENSOR_QOS
from continuum_statics.nodes.ros_conversions import ns_to_stamp, tracked_pose
from continuum_statics.nodes.sensor_topics import tracker_topic
from continuum_statics.nodes.timers import steady_timer

NS = 1_000_000_000


class TipLoadEstimatorNode(RunnerHooks, Node):
    """Intrinsic force sensing at up to ``rate`` Hz: a thin layer over ``estimate_tip_wrench``."""

    EXECUTOR = 'single'

    def __init__(self, node_name='tip_load_estimator', **kwargs):
        super().__init__(node_name, **kwargs)
        self._params = ParameterTable(self, tip_load_estimator_parameters())
        self.robot = load_robot_file(self._params['robot_file'], self.get_logger())
        if self.robot.load_model is not None:  # two estimates of one load on one topic
            raise ValueError('robot file %r names load_model: statics estimates the tip load '
                             'with the shape and publishes tip_wrench_estimate and '
                             'tip_contact; run tip_load_estimator with a robot file without '
                             'it' % self._params['robot_file'])
        self._load = self._load_model()
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        diag.publish_starting(self, self._diagnostics, self.robot.name, 'compiling kernels')
        warm_up(self.robot, self.get_logger().info)
        self.cable_names = tuple(self.robot.cable_names)
        self.base_frame_id = self.robot.base_frame_id
        self._cable_states = CableStatesReader(self.cable_names)
        self._inputs = Inputs()  # the newest measurements
        self._stamps = StampRule(self._params['max_stamp_offset'])
        self._stamp_ns = 0  # of the newest cable_states (judged)
        self._fresh = False  # a measurement arrived since the last estimate
        self._published = None  # the last published WrenchEstimate
        self._watch = LoadWatch(self.robot, self._contact_threshold(),
                                self._params['contact_min_time'])
        self._problems = diag.Problems(self.get_logger().warning)
        self._failures = 0
        self._times = diag.TimingWindow()
        self._rate = diag.RateMeter()
        self._no_input = ''
        self._wrench_pub = self.create_publisher(WrenchStamped, 'tip_wrench_estimate', 10)
        self._contact_pub = self.create_publisher(Bool, 'tip_contact', LATCHED_QOS)
        self._contact_pub.publish(Bool(data=False))
        self.create_subscription(JointState, 'cable_states', self._on_cable_states,
                                 LATEST_SENSOR_QOS, raw=True)
        self.create_subscription(PoseStamped, tracker_topic(self.robot), self._on_tip_pose,
                                 LATEST_SENSOR_QOS)
        steady_timer(self, 1.0 / self._params['rate'], self._on_timer)
        steady_timer(self, 1.0 / self._params['diagnostics_rate'], self._publish_diagnostics)
        self._params.on_change = self._on_parameter_change
        self.get_logger().info('tip_load_estimator: robot %r, %d cables, up to %g Hz, contact '
                               'above %.3g N' % (self.robot.name, len(self.cable_names),
                                                 self._params['rate'],
                                                 self._watch.contact.threshold))

    # -- parameters and inputs -------------------------------------------------------------
    def _contact_threshold(self):
        """contact_threshold (N), or E I / L^2 of the rod when 0."""
        return self._params['contact_threshold'] or plausible_tip_load(self.robot)[0] / 10.0

    def _load_model(self):
        """Return the ``load`` argument of estimate_tip_wrench (checked: a bad one stops here)."""
        name = self._params['load_model']
        if self._params['estimate_moment'] and name not in ('force', 'wrench'):
            raise ValueError("estimate_moment is load_model 'wrench'; it cannot go with "
                             'load_model %r' % name)
        load = 'wrench' if self._params['estimate_moment'] else name
        if load == 'direction':
            load = ('direction', tuple(self._params['load_direction']))
        load_model(self.robot, load)  # e.g. 'weight' on a robot file without gravity
        return load

    def _on_parameter_change(self, name, value):
        if name == 'contact_threshold':
            self._watch.contact.threshold = value or plausible_tip_load(self.robot)[0] / 10.0
        elif name == 'contact_min_time':
            self._watch.contact.min_time = value
        elif name == 'max_stamp_offset':
            self._stamps.max_offset = value

    def _noise(self):
        params = self._params
        tension = (params['noise_tension'] if params['noise_tension_percent'] <= 0.0
                   else '%g%%' % params['noise_tension_percent'])
        return {'length': params['noise_length'], 'tension': tension,
                'tip_position': params['noise_tip_position'],
                'tip_angle': params['noise_tip_angle']}

    def _on_cable_states(self, data):
        try:
            view, lengths = self._cable_states.read(data)
        except ValueError as error:
            self._problems.reject('cable_states', error)
            return
        # a slack cable read within 3 sigma of its noise below zero is zero (the estimate went
        # stale on each such message before: issue 43)
        tensions, problem = self._cable_states.tensions(
            view, zero_band=slack_band(self._noise()['tension']))
        if problem:
            self._problems.reject('cable_states', problem)
        self._stamp_ns, taken = self._judged('cable_states', view.sec * NS + view.nanosec)
        self._inputs = dataclasses.replace(self._inputs, lengths=lengths, tensions=tensions,
                                           cables_received=taken)
        self._fresh = True

    def _judged(self, stream, stamp_ns):
        """Return (the stamp to use, ns; when it was taken, monotonic s: freshness).

        The message's stamp, or its arrival when the stamp is not trusted (warned, counted).
        """
        stamp_ns, age, reason = self._stamps.judge_age(stream, stamp_ns,
                                                       self.get_clock().now().nanoseconds)
        if reason:
            self._problems.reject('stamp', reason)
        return stamp_ns, time.monotonic() - age

    def _on_tip_pose(self, msg):
        try:
            position, rotation, stamp, _ = tracked_pose(msg, self.base_frame_id,
                                                        self._params['use_tip_orientation'])
        except ValueError as error:
            self._problems.reject('tip_pose_measured', error)
            return
        _, taken = self._judged('tip_pose_measured', stamp)
        self._inputs = dataclasses.replace(self._inputs, tip_position=position,
                                           tip_rotation=rotation, tip_received=taken)
        self._fresh = True

    # -- estimation: the decisions are the LoadWatch's -------------------------------------
    def _on_timer(self):
        if not self._fresh:
            return
        self._fresh = False
        now = time.monotonic()
        try:  # one bad measurement or failed solve never stops the node
            self._estimate_once(now)
        except Exception as error:
            self._failures += 1
            self._problems.reject('estimate', 'internal error (the last estimate is kept): %r'
                                  % (error,))

    def _estimate_once(self, now):
        params = self._params
        kwargs, self._no_input = self._watch.measurements(
            self._inputs, now, params['input_timeout'], params['use_tip_pose'])
        if kwargs is None:
            return
        start = time.perf_counter()
        outcome = self._watch.step(kwargs, self._noise(), now, self._solve)
        if outcome.verdict is Verdict.SET_ASIDE:
            self._failures += 1
            self._problems.reject('estimate', outcome.reason)
            if outcome.estimate is None:
                return
        if outcome.verdict is Verdict.PUBLISH:
            self._times.add(time.perf_counter() - start)
        self._publish(outcome.estimate, outcome.contact_changed)

    def _solve(self, warm_start, **kwargs):
        return self.robot.estimate_tip_wrench(noise=self._noise(), load=self._load,
                                              warm_start=warm_start, **kwargs)

    def _publish(self, estimate, contact_changed):
        msg = WrenchStamped()
        ns_to_stamp(self._stamp_ns, msg.header.stamp)
        msg.header.frame_id = self.base_frame_id
        force, moment = estimate.force, estimate.moment
        msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = (float(v) for v in force)
        msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z = (
            float(v) for v in moment)
        self._wrench_pub.publish(msg)
        self._rate.tick()
        self._published = estimate
        if contact_changed:
            contact = self._watch.contact
            self._contact_pub.publish(Bool(data=contact.in_contact))
            magnitude, sigma = force_along(force, estimate.covariance)
            if contact.in_contact:
                self.get_logger().warning('contact on the tip: %.3g N (sigma %.2g N) above '
                                          'contact_threshold %.3g N' % (
                                              magnitude, sigma, contact.threshold))
            else:
                self.get_logger().info('contact ended: %.3g N' % magnitude)

    def on_node_failure(self, text):
        """Count a restart by the runner after a callback raised (on diagnostics)."""
        self._failures += 1
        self._problems.add('node', text)

    # -- diagnostics ---------------------------------------------------------------------------
    def _publish_diagnostics(self):
        count, median, maximum = self._times.report()
        rate = self._rate.report()
        estimate = self._published
        level, message = diag.OK, 'estimating'
        values = {'state': 'ready' if estimate is not None else 'starting',
                  'load_model': self._params['load_model'],
                  'estimate_rate_hz': rate, 'estimates': count,
                  'estimate_time_median_ms': median, 'estimate_time_max_ms': maximum,
                  'failures_total': self._failures,
                  'contact_threshold_n': self._watch.contact.threshold,
                  'in_contact': self._watch.contact.in_contact}
        if self._no_input:
            level, message = diag.WARN, self._no_input
        elif estimate is None:
            message = 'waiting for cable_states or tip_pose_measured'
        else:
            sigma = estimate.sigma
            values.update({
                'force_n': ' '.join('%.4g' % v for v in estimate.force),
                'force_sigma_n': ' '.join('%.3g' % v for v in sigma[:3]),
                'converged': estimate.converged,
                'chi2': estimate.chi2,
                'unseen_directions': '; '.join(' '.join('%.2f' % v for v in d)
                                               for d in estimate.unseen) or 'none',
                'estimate_message': estimate.message or 'none',
            })
            if estimate.mass is not None:
                values['mass_kg'] = '%.5g' % estimate.mass
                values['mass_sigma_kg'] = '%.3g' % estimate.mass_sigma
            if len(sigma) == 6:
                values['moment_nm'] = ' '.join('%.4g' % v for v in estimate.moment)
                values['moment_sigma_nm'] = ' '.join('%.3g' % v for v in sigma[3:])
            if self._watch.contact.in_contact:
                magnitude, _ = force_along(estimate.force, estimate.covariance)
                level, message = diag.WARN, 'contact on the tip: %.3g N' % magnitude
            elif len(estimate.unseen):
                message = 'estimating (%d direction(s) not seen)' % len(estimate.unseen)
        if level == diag.OK and self._problems.recent(2.0):
            level, message = diag.WARN, 'rejected ' + self._problems.last_reason
        values.update(self._problems.values())
        values.update(self._stamps.values())
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))


def main(args=None):
    """Run the tip_load_estimator node (``ros2 run continuum_statics tip_load_estimator``)."""
    return run_nodes([TipLoadEstimatorNode], args)


if __name__ == '__main__':
    sys.exit(main())
