"""tip_controller: move the tip to a goal position, closed loop on the measured tip pose.

Goals come from the ``move_tip`` action (continuum_statics_interfaces/action/MoveTip: feedback,
cancel; :mod:`~continuum_statics.nodes.move_tip_action`), the ``tip_goal`` service
(nav_msgs/srv/GetPlan: ``goal.pose.position`` in the base frame, ``tolerance`` in m; answered
after arrival or failure), the ``tip_goal_pose`` topic (geometry_msgs/PoseStamped, streaming;
``default_tolerance``) and ``tip_goal_point`` (RViz's Publish Point); ``tip_twist``
(TwistStamped) drives resolved-rate teleoperation instead (:mod:`continuum_statics.control.
teleop`). The decisions are :class:`~continuum_statics.control.goal_run.GoalRun`'s; this node
parses, calls and publishes. For a goal the run

1. estimates the shape from the measured cable lengths and solves the tip goal from it (warm
   start); when the measured lengths are not where the last command put them (a restarted
   driver, a hand-made command, cables that slipped), it first moves the cables onto the
   estimate's own lengths, back onto the model,
2. ramps ``cable_commands`` (sensor_msgs/JointState) from that equilibrium to the goal's through
   the model's own unknowns (``Robot.equilibrium_between``: section moments interpolated, base
   state solved), so every command is the cable-length set of an equilibrium of the robot, never
   a straight line in cable space (a section has two bending freedoms, its cables more); the
   fraction steps are chosen so that no cable moves faster than ``max_cable_speed``,
3. watches ``tip_pose`` (or ``tip_pose_measured``, a registered tracker, while it is fresh and
   ``use_measured_tip``) once the cables have settled and judges the tip on the mean of the
   samples since then (enough of them that the noise of the mean is well inside the tolerance,
   at most ``tip_average_time``); when it is off it corrects the goal by the remaining error
   (integral correction: ``target += goal - mean_tip``, re-solved and ramped the same way)
   until the tip is within the tolerance or ``goal_timeout`` passes.

The service answers with the ``backbone`` at the final state, or an empty plan when the goal was
rejected (non-finite numbers, a frame other than the base frame, a non-positive tolerance, an
unreachable position, no state yet, a robot without cables), not reached in time, or pre-empted by
a newer goal; the reason is logged and on diagnostics. A failed goal leaves no trace: the next one
is accepted as soon as the state is fresh. The service runs in its own reentrant callback group,
so a waiting call never blocks the topics it is waiting for (multi-threaded executor).
"""
from collections import deque
import dataclasses
import math
import struct
import sys
import threading
import time

from geometry_msgs.msg import PointStamped, PoseStamped, TwistStamped, WrenchStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header
from visualization_msgs.msg import MarkerArray

from continuum_statics.control.goal_run import (
    OFF_COMMAND,
    Goal,
    GoalRun,
    RunSettings,
    stale_state,
)
from continuum_statics.control.handover import Handover
from continuum_statics.control.records import (
    Measurement,
    TipLoad,
    TipSample,
    current_load,
    tracked_tip,
)
from continuum_statics.control.teleop import TeleopRun, TeleopSettings, Twist, twist_hold
from continuum_statics.control.tip_source import TipSource, disagreement_bound
from continuum_statics.core.rotations import quaternion_to_rotation
from continuum_statics.core.warmup import warm_up
from continuum_statics.core.workspace import reachable_tips
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.dedicated_intake import make_intake
from continuum_statics.nodes.joint_state_parser import CableStatesReader
from continuum_statics.nodes.markers import workspace_markers
from continuum_statics.nodes.move_tip_action import MoveTipServer, load_interface
from continuum_statics.nodes.node_params import (
    ParameterTable,
    load_robot_file,
    tip_wrench_limits,
    tip_wrench_topic,
)
from continuum_statics.nodes.parameter_tables import tip_controller_parameters
from continuum_statics.nodes.qos import COMMAND_QOS, LATCHED_QOS, LATEST_SENSOR_QOS
from continuum_statics.nodes.ros_conversions import (
    float32_value,
    goal_direction,
    goal_position,
    joint_state,
    pose_position,
    set_pose,
    tip_load,
)
from continuum_statics.nodes.timers import steady_timer
from continuum_statics.nodes.waits import Waits

THROTTLE_S = 2.0
#: Smallest tip_goal tolerance, m: below a micrometre the model's own accuracy decides.
MIN_TOLERANCE = 1e-6
#: A goal starts from the mean of the cable lengths measured in this window, s (at rest it
#: averages the encoder noise; a moving cable lags by at most speed x window).
MEAN_WINDOW_S = 0.05
#: Reachable tips drawn as RViz click targets (workspace_markers).
WORKSPACE_SAMPLES = 400
#: A tip_twist stamped further than this from now is refused, s (or twist_timeout if longer).
MAX_TWIST_STAMP_OFFSET = 1.0
#: How often waiting goals check their condition (fresh state, the goal's end), s.
WAIT_PERIOD = 0.01
#: The cable_driver's /diagnostics status counts this long, s (it publishes at >= 1 Hz).
DRIVER_STATUS_AGE = 5.0


class TipControllerNode(Node):
    """Tip-goal service and streaming goals, closed loop on ``tip_pose``."""

    EXECUTOR = 'multi'

    def __init__(self, node_name='tip_controller', **kwargs):
        super().__init__(node_name, **kwargs)
        specs = tip_controller_parameters()
        self._params = ParameterTable(self, specs)
        self.robot = load_robot_file(self._params['robot_file'])
        # Compile every kernel now, on this thread, before the service is advertised.
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        diag.publish_starting(self, self._diagnostics, self.robot.name, 'compiling kernels')
        warm_up(self.robot, self.get_logger().info)
        self.cable_names = tuple(self.robot.cable_names)
        self.base_frame_id = self.robot.base_frame_id

        self._lock = threading.Lock()  # guards the run: the control loop and goal starts
        self._closing = False
        self._handover = Handover()  # goals and teleoperation: the later arrival wins
        self._tracker = TipSource(self._tracker_bound())
        self._run = GoalRun(self.robot, self._run_settings())
        self._teleop = TeleopRun(self.robot, self._teleop_settings())
        self._twist = None  # the newest Twist
        self._last_tick = None
        self._tips = deque(maxlen=4000)  # recent TipSamples, for the judgement of a goal
        self._recent_lengths = deque(maxlen=64)  # recent Measurements, for a low-noise mean
        self._measurement = None  # newest Measurement (one assignment: always consistent)
        self._tip = None  # newest TipSample
        self._tip_rotation = None  # the model tip's rotation (3, 3) of the newest tip_pose
        self._measured_tips = deque(maxlen=4000)  # recent tracker TipSamples (tip, not marker)
        self._measured_tip = None
        self._tip_source = 'tip_pose'
        self._cable_states = CableStatesReader(self.cable_names)
        self._backbone = None  # (stamp ns, serialized Path) of the newest backbone
        self._load = None  # newest TipLoad
        self._problems = diag.Problems()
        self._counts = {'reached': 0, 'failed': 0, 'rejected': 0, 'preempted': 0}
        self._last_outcome = 'no goal yet'
        self._command_msg = JointState()
        self._driver_status = None  # (refusal or '', monotonic s) of cable_driver's /diagnostics

        self._control_group = MutuallyExclusiveCallbackGroup()
        # Goals from every source are coroutines awaiting their end (no thread held), in a group
        # of their own: never behind or in front of the control timer.
        service_group = ReentrantCallbackGroup()
        self._waits = Waits(self, WAIT_PERIOD, MutuallyExclusiveCallbackGroup())
        self._command_pub = self.create_publisher(JointState, 'cable_commands', COMMAND_QOS)
        # The state topics arrive at the measurement rate (hundreds of Hz): a thread of their own
        # serves them, which costs a tenth of the multi-threaded executor's overhead.
        self._intake = make_intake(self, self._params['dedicated_intake_thread'],
                                   'tip_controller_intake')
        self._intake.add(PoseStamped, 'tip_pose', self._on_tip_pose, LATCHED_QOS)
        # an external tracker (motion capture, EM) registered to the base by calibrate
        self._intake.add(PoseStamped, 'tip_pose_measured', self._on_tip_pose_measured,
                         LATEST_SENSOR_QOS)
        # Kept as bytes: only the backbone that answers a goal is ever decoded.
        self._intake.add(Path, 'backbone', self._on_backbone, LATCHED_QOS, raw=True)
        self._intake.add(JointState, 'cable_states', self._on_cable_states, LATEST_SENSOR_QOS,
                         raw=True)
        self._intake.add(WrenchStamped, tip_wrench_topic(self._params), self._on_tip_wrench,
                         LATEST_SENSOR_QOS)
        # the driver says when it refuses commands (inactive, faulted, disconnected)
        self._driver_status_name = '%s/%s' % (self.get_namespace().rstrip('/'),
                                              self._params['cable_driver_name'])
        self._driver_status_name = self._driver_status_name.lstrip('/')
        self._intake.add(diag.DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self._contact_since = None  # monotonic s tip_contact turned true, None without contact
        self._intake.add(Bool, 'tip_contact', self._on_tip_contact, LATCHED_QOS)
        self._intake.start()
        self.create_subscription(TwistStamped, 'tip_twist', self._on_twist, COMMAND_QOS,
                                 callback_group=self._control_group)
        # RViz's Publish Point tool: a click on the workspace markers is a 3-D tip goal
        self.create_subscription(PointStamped, 'tip_goal_point', self._on_goal_point,
                                 COMMAND_QOS, callback_group=service_group)
        if self.cable_names:
            workspace = self.create_publisher(MarkerArray, 'workspace_markers', LATCHED_QOS)
            workspace.publish(workspace_markers(
                self.base_frame_id, reachable_tips(self.robot, WORKSPACE_SAMPLES, seed=0)))
        # every goal taken, from any source, for recordings and plots (latched)
        self._active_goal_pub = self.create_publisher(PoseStamped, 'tip_goal_active',
                                                      LATCHED_QOS)
        self.create_subscription(PoseStamped, 'tip_goal_pose', self._on_goal_pose, COMMAND_QOS,
                                 callback_group=service_group)
        self.create_service(GetPlan, 'tip_goal', self._on_tip_goal, callback_group=service_group)
        action = load_interface()
        self._action = None if action is None else MoveTipServer(self, action, service_group)
        if action is None:
            self.get_logger().warning('continuum_statics_interfaces is not built: no move_tip '
                                      'action (scripts/build_interfaces.sh, or colcon build)')
        self._timer = steady_timer(self, 1.0 / self._params['control_rate'], self._on_control,
                                   callback_group=self._control_group)
        self._timer.cancel()  # runs only while a goal does
        steady_timer(self, 1.0 / self._params['diagnostics_rate'], self._publish_diagnostics,
                     callback_group=self._control_group)
        self._params.on_change = self._on_parameter_change
        self.get_logger().info('tip_controller: robot %r, frame %r, max cable speed %g m/s' % (
            self.robot.name, self.base_frame_id, self._params['max_cable_speed']))

    def _run_settings(self):
        params = self._params
        return RunSettings(**{name: params[name] for name in RunSettings.__dataclass_fields__
                              if name != 'max_correction'},
                           max_correction=self._tracker_bound())

    def _tracker_bound(self, value=None):
        """tracker_max_disagreement in m (0: a tenth of the rod length)."""
        value = self._params['tracker_max_disagreement'] if value is None else value
        return disagreement_bound(self.robot.length, value)

    def _teleop_settings(self):
        params = self._params
        return TeleopSettings(max_tip_speed=params['max_tip_speed'],
                              max_tip_rate=params['max_tip_rate'],
                              twist_timeout=params['twist_timeout'],
                              max_cable_speed=params['max_cable_speed'])

    def _on_parameter_change(self, name, value):
        # called before the table stores the new value
        with self._lock:  # goals reset/cancel the timer under the same lock
            if name in RunSettings.__dataclass_fields__:
                self._run.settings = dataclasses.replace(self._run.settings, **{name: value})
            if name == 'tracker_max_disagreement':
                self._tracker.bound = self._tracker_bound(value)
                self._run.settings = dataclasses.replace(self._run.settings,
                                                         max_correction=self._tracker.bound)
            if name in TeleopSettings.__dataclass_fields__:
                self._teleop.settings = dataclasses.replace(self._teleop.settings,
                                                            **{name: value})
            elif name == 'control_rate':
                self.destroy_timer(self._timer)
                # idle, it ticks once and stops itself (_on_control)
                self._timer = steady_timer(self, 1.0 / value, self._on_control,
                                           callback_group=self._control_group)

    # -- state inputs ----------------------------------------------------------------------
    def _reject(self, kind, reason):
        self._problems.add(kind, reason)
        self.get_logger().warning('dropped %s: %s' % (kind, reason),
                                  throttle_duration_sec=THROTTLE_S)

    def _on_tip_pose(self, msg):
        if msg.header.frame_id != self.base_frame_id:
            self._reject('tip_pose', 'frame %r is not the base frame %r'
                         % (msg.header.frame_id, self.base_frame_id))
            return
        position = pose_position(msg.pose)
        if not np.all(np.isfinite(position)):
            self._reject('tip_pose', 'non-finite position')
            return
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self._tip = TipSample(position, stamp, time.monotonic())
        self._tips.append(self._tip)
        q = msg.pose.orientation
        self._tip_rotation = quaternion_to_rotation(np.array([q.x, q.y, q.z, q.w]))

    def _on_tip_pose_measured(self, msg):
        if msg.header.frame_id != self.base_frame_id:
            self._reject('tip_pose_measured', 'frame %r is not the base frame %r (register the '
                         'tracker with calibrate)' % (msg.header.frame_id, self.base_frame_id))
            return
        position = pose_position(msg.pose)
        if not np.all(np.isfinite(position)):
            self._reject('tip_pose_measured', 'non-finite position')
            return
        if self._tip_rotation is None:
            return  # the marker's offset needs the model's tip frame: wait for tip_pose
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        tip = tracked_tip(position, self._tip_rotation, self.robot.tip_marker)
        self._measured_tip = TipSample(tip, stamp, time.monotonic())
        self._measured_tips.append(self._measured_tip)

    def _on_backbone(self, data):
        # Only the stamp is read here (decoding every Path costs ~0.2 ms); the whole message
        # is decoded and checked when a goal answers with it (_plan_after).
        try:
            byte_order = '<' if data[1:2] == b'\x01' else '>'  # CDR encapsulation header
            sec, nanosec = struct.unpack_from(byte_order + 'iI', data, 4)
        except struct.error:
            self._reject('backbone', 'malformed Path (%d bytes)' % len(data))
            return
        self._backbone = (sec * 1_000_000_000 + nanosec, data)

    def _on_cable_states(self, data):
        try:
            view, measured = self._cable_states.read(data)
        except ValueError as error:
            self._reject('cable_states', error)
            return
        self._measurement = Measurement(measured, view.sec * 1_000_000_000 + view.nanosec,
                                        time.monotonic())
        self._recent_lengths.append(self._measurement)

    def _on_tip_wrench(self, msg):
        try:
            wrench = tip_load(msg, self.base_frame_id,
                              *tip_wrench_limits(self.robot, self._params))
        except ValueError as error:
            self._reject('tip_wrench', error)
            return
        self._load = TipLoad(wrench, time.monotonic())

    def _on_diagnostics(self, msg):
        name = self._driver_status_name
        for status in msg.status:
            if status.name == name:
                values = {kv.key: kv.value for kv in status.values}
                if 'accepts_commands' in values:  # a driver of this package
                    refusal = ('' if values['accepts_commands'] == 'True'
                               else values.get('refusal') or status.message)
                    self._driver_status = (refusal, time.monotonic())

    def _on_tip_contact(self, msg):
        if not msg.data:
            self._contact_since = None
        elif self._contact_since is None:
            self._contact_since = time.monotonic()

    def driver_refusal(self):
        """Why cable_driver refuses cable_commands now (its fresh /diagnostics), or ''."""
        status = self._driver_status
        if status is None or time.monotonic() - status[1] > DRIVER_STATUS_AGE:
            return ''
        return status[0]

    def _current_tip_load(self):
        return current_load(self._load, time.monotonic(), self._params['tip_wrench_timeout'])

    # -- goals -----------------------------------------------------------------------------
    async def _on_tip_goal(self, request, response):
        header = Header(frame_id=self.base_frame_id, stamp=self.get_clock().now().to_msg())
        response.plan = Path(header=header)
        try:
            return await self._serve_tip_goal(request, response)
        except Exception as error:  # never let one request take the executor down
            self.get_logger().error('tip_goal failed: %r' % (error,))
            self.goal_rejected('internal error: %r' % (error,))
            response.plan = Path(header=header)
            return response

    def checked_tolerance(self, tolerance):
        """Return a goal tolerance (m) if usable; ValueError says why not."""
        if not (math.isfinite(tolerance) and MIN_TOLERANCE <= tolerance <= self.robot.length):
            raise ValueError('tolerance must be between %g m and the rod length %g m, got %r'
                             % (MIN_TOLERANCE, self.robot.length, tolerance))
        return tolerance

    def latest_tip(self):
        """Return the newest TipSample (or None)."""
        return self._tip

    def phase(self):
        """Return what the controller does now: a goal run's phase or 'teleoperation'."""
        return 'teleoperation' if self._teleop.active else self._run.phase.value

    async def _serve_tip_goal(self, request, response):
        # GetPlan's tolerance is a float32
        tolerance = float32_value(request.tolerance)
        try:
            tolerance = self.checked_tolerance(tolerance)
            goal = await self.start_goal(goal_position(request.goal, self.base_frame_id),
                                         tolerance, 'tip_goal service',
                                         self._goal_direction(request.goal))
        except ValueError as error:
            self.goal_rejected(error)
            return response
        await self.goal_end(goal)
        if goal.reached:
            plan = await self.plan_after(goal.tip_stamp)
            if plan is not None:
                response.plan = plan
        return response

    def wait_until(self, condition, deadline):
        """Future (``await`` it) of ``condition()`` once it holds or ``deadline`` passes.

        The awaiting coroutine holds no executor thread (:mod:`~continuum_statics.nodes.waits`).
        """
        return self._waits.until(lambda: self._closing or condition(), deadline)

    async def goal_end(self, goal, deadline=None):
        """Wait for ``goal`` to end (True) or ``deadline`` (False), holding no thread.

        Past the goal's own deadline (plus a margin for the last judgement) or at shutdown the
        goal is ended here.
        """
        limit = goal.deadline + 5.0
        await self.wait_until(goal.done.is_set, limit if deadline is None
                              else min(deadline, limit))
        if not goal.done.is_set() and (self._closing or time.monotonic() >= limit):
            self.finish_goal(goal, False, 'shutting down' if self._closing else 'timed out')
        return goal.done.is_set()

    async def _on_goal_point(self, msg):
        pose = PoseStamped(header=msg.header)
        pose.pose.position = msg.point
        pose.pose.orientation.w = 1.0
        await self._on_goal_pose(pose)

    async def _on_goal_pose(self, msg):
        try:
            await self.start_goal(goal_position(msg, self.base_frame_id),
                                  self._params['default_tolerance'], 'tip_goal_pose',
                                  self._goal_direction(msg))
        except ValueError as error:
            self.goal_rejected(error)
        except Exception as error:  # never let one message take the node down
            self.get_logger().error('tip_goal_pose failed: %r' % (error,))
            self.goal_rejected('internal error: %r' % (error,))

    # -- teleoperation ---------------------------------------------------------------------
    def _on_twist(self, msg):
        try:
            frame = msg.header.frame_id
            if frame not in ('', self.base_frame_id):
                raise ValueError('frame %r is not the base frame %r' % (frame, self.base_frame_id))
            linear = np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z])
            angular = np.array([msg.twist.angular.x, msg.twist.angular.y, msg.twist.angular.z])
            if not (np.all(np.isfinite(linear)) and np.all(np.isfinite(angular))):
                raise ValueError('non-finite velocity')
            if angular.any() and self._params['goal_orientation'] != 'direction':
                angular = np.zeros(3)  # the tip direction is not controlled
            self._check_twist_stamp(msg.header.stamp)
            now, previous = time.monotonic(), self._twist
            timeout = self._params['twist_timeout']
            self._twist = Twist(linear, angular, now, twist_hold(
                None if previous is None else previous.received, now, timeout))
            if self._teleop.active or not (linear.any() or angular.any()):
                return
            self._start_teleop()
        except ValueError as error:
            self._reject('tip_twist', error)
        except Exception as error:  # never let one message take the node down
            self.get_logger().error('tip_twist failed: %r' % (error,))
            self._reject('tip_twist', 'internal error: %r' % (error,))

    def _check_twist_stamp(self, stamp):
        """ValueError for a twist stamped far from now (a replay, a sender's wrong clock).

        Stamp 0 (unstamped) is taken on arrival, and so is everything while the node's own
        clock reads 0 (simulated time before the first /clock).
        """
        stamp_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        now_ns = self.get_clock().now().nanoseconds
        if stamp_ns == 0 or now_ns == 0:
            return
        offset = (now_ns - stamp_ns) * 1e-9
        limit = max(MAX_TWIST_STAMP_OFFSET, self._params['twist_timeout'])
        if abs(offset) > limit:
            raise ValueError('stamped %.3g s %s now (more than %.3g s): a replayed command or '
                             'a sender with another clock; unstamped twists (stamp 0) are '
                             'taken on arrival' % (abs(offset), 'before' if offset > 0
                                                   else 'after', limit))

    def _start_teleop(self):
        """Take over from any goal and follow the twists from the current equilibrium."""
        now = time.monotonic()
        no_lengths = ('no cable_states from cable_driver yet' if self._measurement is None
                      else self._stale_state(now, need_tip=False))
        if no_lengths:
            raise ValueError(no_lengths)
        ticket = self._handover.take('teleoperation (tip_twist)')
        with self._lock:
            goal = self._run.goal
            if goal is not None and self._run.finish(goal, False, 'pre-empted by teleoperation'):
                self._report(goal)
            state, commanded, warm = self._run.snapshot()
        measured = self._mean_lengths(self._measurement)
        if state is None or commanded is None or float(
                np.max(np.abs(measured - commanded))) > OFF_COMMAND:
            load = self._current_tip_load()
            state = self.robot.estimate_shape(measured, tip_force=load[:3],
                                              tip_moment=load[3:], warm_start=warm)
            commanded = self.robot.cable_lengths(state.shape)
        with self._lock:
            if not self._handover.holds(ticket):  # a goal arrived meanwhile: it wins
                self.get_logger().info('tip_twist not followed: %s arrived after it'
                                       % self._handover.holder)
                return
            self._teleop.start(state, commanded)
            self._last_tick = now
            self._timer.reset()
        self.get_logger().info('teleoperation: following tip_twist (dead-man %.3g s)'
                               % self._params['twist_timeout'])

    def _end_teleop(self, reason):
        """Stop teleoperation (under the lock); the goal run starts from where it left off."""
        teleop = self._teleop
        if teleop.active:
            teleop.stop(reason)
        if teleop.state is not None:
            self._run.adopt(teleop.state, teleop.commanded)
            teleop.state = None
            self.get_logger().info('teleoperation ended: %s' % teleop.reason)

    def goal_rejected(self, error):
        """Count and report a goal rejected before it started."""
        self._counts['rejected'] += 1
        self._last_outcome = 'rejected: %s' % error
        self._problems.add('tip_goal', error)
        self.get_logger().warning('tip goal rejected: %s' % error)

    def _goal_direction(self, pose_stamped):
        """Tip direction goal (unit z axis of the goal orientation), or None when ignored."""
        if self._params['goal_orientation'] != 'direction':
            return None
        return goal_direction(pose_stamped, 'goal_orientation is direction')

    async def start_goal(self, position, tolerance, source, direction=None):
        """Solve the goal and make it the active one; ValueError says why it is rejected.

        Returns the running :class:`Goal` (the same goal again attaches to it); a goal that
        teleoperation or a newer goal overtook while it was being solved comes back finished
        ('pre-empted ... before it started'): whichever arrives later wins.
        """
        if not self.cable_names:
            raise ValueError('robot has no cables: %r is a passive rod, nothing to move'
                             % self.robot.name)
        # the infinity norm: no overflow for a goal at 1e308 m
        reach = float(np.max(np.abs(position - self.robot.base_position)))
        if reach > self.robot.length:
            raise ValueError('the tip goal (%.4g, %.4g, %.4g) m is unreachable: %.3g m from '
                             'the base along an axis, the rod is %.3g m long'
                             % (*position, reach, self.robot.length))
        ticket = self._handover.take('a newer goal')
        # Right after start-up, or while a driver or statics restarts, the state may be missing
        # or old for a moment: wait up to state_wait for fresh state before answering.
        await self.wait_until(
            lambda: not (self._missing_state() or self._stale_state(time.monotonic())
                         or self.driver_refusal()),
            time.monotonic() + self._params['state_wait'])
        no_lengths = ('no cable_states from cable_driver yet' if self._measurement is None
                      else self._stale_state(time.monotonic(), need_tip=False))
        if no_lengths:
            raise ValueError('%s (waited %.3g s)' % (no_lengths, self._params['state_wait']))
        refusal = self.driver_refusal()
        if refusal:
            raise ValueError('cable_driver refuses cable_commands: %s' % refusal)
        # Fresh lengths but no fresh tip pose: statics drops the lengths (they fit no shape, e.g.
        # after a hand-made command or a removed tip load). Start from the measured lengths'
        # nearest shape and move the cables onto it: statics then follows again.
        tip_lost = self._missing_state() or self._stale_state(time.monotonic())
        if tip_lost:
            self.get_logger().warning('goal without a fresh tip pose (%s): moving the cables '
                                      'onto the model from the measured lengths first' % tip_lost)
        with self._lock:
            running = self._run.goal
            if running is not None and running.tolerance == tolerance and np.array_equal(
                    running.position, position) and np.array_equal(running.direction, direction):
                return running  # the same goal again (a stream repeats it): it goes on
            if not self._handover.holds(ticket):
                return self._overtaken(position, tolerance, source, direction)
            self._end_teleop('pre-empted by a tip goal')
            snapshot = self._run.snapshot()
        load = self._current_tip_load()
        plan = self._run.plan(position, tolerance, direction,
                              self._mean_lengths(self._measurement), load, not tip_lost,
                              snapshot)
        now = time.monotonic()
        goal = Goal(position=position, tolerance=tolerance, source=source, started=now,
                    deadline=now + self._params['goal_timeout'], direction=direction)
        with self._lock:
            # teleoperation or a newer goal came while this one was solved: they win
            if not self._handover.holds(ticket):
                return self._overtaken(position, tolerance, source, direction)
            previous = self._run.begin(goal, plan, now)
            if previous is not None:
                self._report(previous)
            self._tracker.reset()
            self._last_tick = now
            self._timer.reset()
        active = PoseStamped()
        active.header.frame_id = self.base_frame_id
        active.header.stamp = self.get_clock().now().to_msg()
        set_pose(active.pose, position, (0.0, 0.0, 0.0, 1.0))
        self._active_goal_pub.publish(active)
        self.get_logger().info('tip goal (%.4f, %.4f, %.4f) m, tolerance %.2g m from %s%s' % (
            *position, tolerance, source, '' if plan.recover is None
            else ' (cables off the last command: onto the model first)'))
        return goal

    def _overtaken(self, position, tolerance, source, direction):
        """Return a goal that lost the hand-over before it started, finished (under the lock)."""
        now = time.monotonic()
        goal = Goal(position=position, tolerance=tolerance, source=source, started=now,
                    deadline=now, direction=direction)
        self._run.finish(goal, False, 'pre-empted by %s before it started'
                         % self._handover.holder)
        self._report(goal)
        return goal

    def _mean_lengths(self, newest):
        """Mean of the measurements of the last MEAN_WINDOW_S s: encoder noise averaged out."""
        recent = [m.lengths for m in list(self._recent_lengths)
                  if newest.received - m.received <= MEAN_WINDOW_S]
        return np.mean(recent, axis=0) if recent else newest.lengths.copy()

    def finish_goal(self, goal, reached, reason):
        """End ``goal`` (cancel, shutdown, a caller's timeout) and report it."""
        with self._lock:
            if self._run.finish(goal, reached, reason):
                self._report(goal)

    def _report(self, goal):
        """Count, log and put on diagnostics a goal that ended (under the lock)."""
        key = goal.outcome
        self._counts[key] += 1
        self._last_outcome = '%s (%.4f, %.4f, %.4f): %s' % (key, *goal.position, goal.reason)
        if goal.reached:
            self.get_logger().info('tip goal reached: %s' % goal.reason)
        elif key == 'preempted':  # streaming goals pre-empt each other all the time: no warning
            self.get_logger().info('tip goal (%.4f, %.4f, %.4f) m %s'
                                   % (*goal.position, goal.reason))
        else:
            self._problems.add('tip_goal', goal.reason)
            self.get_logger().warning('tip goal (%.4f, %.4f, %.4f) m not reached: %s'
                                      % (*goal.position, goal.reason))

    def _missing_state(self):
        """Return which state has never arrived, or '' when both have."""
        missing = [what for what, state in (('cable_states from cable_driver', self._measurement),
                                            ('tip_pose from statics', self._tip))
                   if state is None]
        return ('no %s yet' % ' and no '.join(missing)) if missing else ''

    def _stale_state(self, now, need_tip=True):
        return stale_state(now, self._measurement, self._tip, self._params['max_state_age'],
                           need_tip)

    async def plan_after(self, tip_stamp, wait=0.5):
        """Return the newest backbone, waiting briefly for the one of the reached tip pose."""
        def arrived():
            return self._backbone is not None and (tip_stamp is None
                                                   or self._backbone[0] >= tip_stamp)

        await self.wait_until(arrived, time.monotonic() + wait)
        backbone = self._backbone
        if backbone is None:
            return None
        try:
            plan = deserialize_message(backbone[1], Path)
        except Exception as error:  # rclpy raises RMWError on bad bytes
            self._reject('backbone', 'malformed Path: %s' % error)
            return None
        points = [(p.pose.position.x, p.pose.position.y, p.pose.position.z,
                   p.pose.orientation.x, p.pose.orientation.y, p.pose.orientation.z,
                   p.pose.orientation.w) for p in plan.poses]
        if (not points or plan.header.frame_id != self.base_frame_id
                or not np.all(np.isfinite(points))):
            self._reject('backbone', 'unusable Path: %d poses, frame %r'
                         % (len(points), plan.header.frame_id))
            return None
        return plan

    # -- control loop ----------------------------------------------------------------------
    def _on_control(self):
        with self._lock:
            now = time.monotonic()
            elapsed, self._last_tick = max(now - self._last_tick, 0.0), now
            if self._teleop.active or self._teleop.state is not None:
                # a late tick catches up (the cable speed limit still bounds the step)
                commanded = self._teleop.tick(now, min(elapsed, self._params['twist_timeout']),
                                              self._twist, self._current_tip_load())
                if self._teleop.stopped:
                    self._problems.add('tip_twist', self._teleop.stopped)
                if not self._teleop.active:
                    self._end_teleop(self._teleop.reason)
            else:
                commanded = self._control_goal(
                    now, min(elapsed, 3.0 / self._params['control_rate']))
            if self._run.goal is None and not self._teleop.active:
                # Nothing to control: the timer stops itself. Only ever here, in its own
                # callback and under the lock that goal starts reset it under: a timer that
                # another thread cancels between the executor's wait and its call raises in the
                # executor (Jazzy's rclpy: "timer is canceled") and stops the node.
                self._timer.cancel()
        if commanded is not None:
            self._publish_command(commanded)

    def _control_goal(self, now, dt):
        """One tick of the goal run (under the lock); the command to publish or None."""
        goal = self._run.goal
        if goal is None:
            return None
        refusal = self.driver_refusal()
        if refusal:
            self._run.finish(goal, False, 'cable_driver refuses cable_commands: %s' % refusal)
            self._report(goal)
            return None
        contact = self._contact_since
        if self._params['stop_on_contact'] and contact is not None and contact >= goal.started:
            self._run.finish(goal, False, 'stopped on contact: tip_contact turned true %.2f s '
                             'into the goal (stop_on_contact)' % (contact - goal.started))
            self._report(goal)
            measurement = self._measurement  # hold where the cables are
            return None if measurement is None else measurement.lengths.copy()
        tip, tips, self._tip_source, warning = self._tracker.judged(
            now, self._measured_tip, self._measured_tips, self._tip, self._tips,
            self._params['max_state_age'], self._params['use_measured_tip'])
        if warning:
            self._problems.add('tip_pose_measured', warning)
            self.get_logger().warning(warning)
        commanded = self._run.tick(now, dt, self._measurement, tip, tips,
                                   self._current_tip_load())
        for note in self._run.notes:
            self._problems.add('ramp', note)
            self.get_logger().warning(note)
        self._run.notes.clear()
        if goal.done.is_set():
            self._report(goal)
        return commanded

    def _publish_command(self, lengths):
        limits = self._run.limits
        lengths = np.clip(lengths, limits[:, 0], limits[:, 1])
        try:
            msg = joint_state(self.cable_names, lengths, self.get_clock().now().to_msg(),
                              msg=self._command_msg)
        except ValueError as error:
            self._reject('cable_commands', error)
            return
        self._command_pub.publish(msg)

    # -- diagnostics and shutdown ----------------------------------------------------------
    def _publish_diagnostics(self):
        with self._lock:
            run = self._run
            goal, phase = run.goal, run.phase.value
            corrections, fraction, moved = run.corrections, run.fraction, run.moved_onto_model
        level, message = diag.OK, 'idle' if goal is None else 'moving to a goal (%s)' % phase
        if self._teleop.active:
            message = 'teleoperation (tip_twist)'
            if self._teleop.stopped:
                level, message = diag.WARN, 'teleoperation ' + self._teleop.stopped
        missing = self._missing_state()
        if missing:
            message = diag.STARTING + 'waiting for state: ' + missing
        if self._problems.recent(5.0):
            level, message = diag.WARN, self._problems.last_reason
        publishers = self.count_publishers(self._command_pub.topic_name)
        if publishers > 1:  # e.g. two bringups in one namespace: two loops fight over the cables
            level, message = diag.WARN, (
                'another node also publishes %s (%d publishers): two controllers in one '
                'namespace?' % (self._command_pub.topic_name, publishers))
        values = {
            'state': 'starting' if missing else 'ready',
            'phase': phase,
            'teleoperation': self._teleop.active,
            'goals_reached': self._counts['reached'],
            'goals_failed': self._counts['failed'],
            'goals_rejected': self._counts['rejected'],
            'goals_preempted': self._counts['preempted'],
            'moved_onto_model_total': moved,
            'last_outcome': self._last_outcome,
            'have_tip_pose': self._tip is not None,
            'tip_source': self._tip_source,
            'have_tip_pose_measured': self._measured_tip is not None,
            'have_cable_states': self._measurement is not None,
        }
        if goal is not None:
            values['goal_m'] = '%.5f %.5f %.5f' % tuple(goal.position)
            values['tip_error_mm'] = goal.error * 1e3
            values['corrections'] = corrections
            values['ramp_fraction'] = fraction
        values.update(self._problems.values())
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))

    def release_waiters(self):
        """End the goal in progress so that a waiting service call returns (shutdown)."""
        self._closing = True
        self._waits.release_all()
        with self._lock:
            goal = self._run.goal
            if goal is not None and self._run.finish(goal, False, 'shutting down'):
                self._report(goal)

    def destroy_node(self):
        """Release waiting service calls, stop the intake thread, then destroy the node."""
        self.release_waiters()
        if self._action is not None:
            self._action.destroy()
        self._intake.stop()
        return super().destroy_node()


def main(args=None):
    """Run the tip_controller node (``ros2 run continuum_statics tip_controller``)."""
    from continuum_statics.nodes.node_runner import run_nodes
    return run_nodes([TipControllerNode], args)


if __name__ == '__main__':
    sys.exit(main())
