"""tip_controller: move the tip to a goal position, closed loop on the measured tip pose.

Goals come from the ``move_tip`` action (continuum_statics_interfaces/action/MoveTip: feedback,
cancel; :mod:`~continuum_statics.nodes.move_tip_action`), the ``tip_goal`` service
(nav_msgs/srv/GetPlan: ``goal.pose.position`` in the base frame, ``tolerance`` in m; answered
after arrival or failure), the ``tip_goal_pose`` topic (geometry_msgs/PoseStamped, streaming;
``default_tolerance``) and ``tip_goal_point`` (RViz's Publish Point); ``tip_twist``
(TwistStamped) drives resolved-rate teleoperation instead (:mod:`continuum_statics.control.
teleop`). The decisions are :class:`~continuum_statics.control.tip_control.TipControl`'s
(goal intake, teleoperation, outcomes) and its :class:`~continuum_statics.control.goal_run.
GoalRun`'s; this node parses, calls and publishes. For a goal the run

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
is accepted as soon as the state is fresh. Every goal source (service, action, ``tip_goal_pose``,
``tip_goal_point``) runs in a reentrant callback group of its own, never the control timer's, so
a waiting goal never blocks the running goal's ticks or the topics it waits for. Goals keep the
body ``clearance`` from the obstacles (:mod:`~continuum_statics.nodes.controller_obstacles`).
"""
import sys

from geometry_msgs.msg import PointStamped, PoseStamped, TwistStamped, WrenchStamped
from nav_msgs.msg import Path
from nav_msgs.srv import GetPlan
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool, Header

from continuum_statics.control.health import ControllerHealth
from continuum_statics.control.stamps import StampRule
from continuum_statics.control.tip_control import TipControl
from continuum_statics.core.rod.rotations import quaternion_to_rotation
from continuum_statics.core.warmup import warm_up
from continuum_statics.nodes import controller_obstacles as obstacles
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.dedicated_intake import make_intake
from continuum_statics.nodes.joint_state_parser import CableStatesReader, header_stamp_ns
from continuum_statics.nodes.markers import publish_workspace
from continuum_statics.nodes.move_tip_action import MoveTipServer, answer_plan, load_interface
from continuum_statics.nodes.node_params import (
    ParameterTable,
    load_robot_file,
    tip_wrench_limits,
    tip_wrench_topic,
)
from continuum_statics.nodes.node_runner import RunnerHooks, run_nodes
from continuum_statics.nodes.parameter_tables import tip_controller_parameters
from continuum_statics.nodes.qos import COMMAND_QOS, LATCHED_QOS, LATEST_SENSOR_QOS
from continuum_statics.nodes.ros_conversions import (
    base_frame_pose,
    float32_value,
    goal_direction,
    goal_position,
    joint_state,
    set_pose,
    stamp_ns,
    tip_load,
    tracked_pose,
    twist_vectors,
)
from continuum_statics.nodes.sensor_topics import tracker_topic
from continuum_statics.nodes.timers import steady_timer
from continuum_statics.nodes.waits import InFlight, Waits

#: Reachable tips drawn as RViz click targets (workspace_markers).
WORKSPACE_SAMPLES = 400
#: How often waiting goals check their condition (fresh state, the goal's end), s.
WAIT_PERIOD = 0.01
#: What to do about a tracker in another frame.
TRACKER_HINT = ' (register the tracker with calibrate)'


class TipControllerNode(RunnerHooks, Node):
    """Tip-goal service and streaming goals, closed loop on ``tip_pose``.

    Every decision is :attr:`control`'s (:class:`~continuum_statics.control.tip_control.
    TipControl`): this node parses messages, calls it and publishes what it returns.
    """

    EXECUTOR = 'multi'

    def __init__(self, node_name='tip_controller', **kwargs):
        super().__init__(node_name, **kwargs)
        self._params = ParameterTable(self, tip_controller_parameters())
        self.robot = load_robot_file(self._params['robot_file'])
        # Compile every kernel now, on this thread, before the service is advertised.
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        diag.publish_starting(self, self._diagnostics, self.robot.name, 'compiling kernels')
        warm_up(self.robot, self.get_logger().info)
        self.cable_names = tuple(self.robot.cable_names)
        self.base_frame_id = self.robot.base_frame_id
        # Goals from every source are coroutines awaiting their end (no thread held), in a group
        # of their own: never behind or in front of the control timer (nor is their waiting).
        self._control_group = MutuallyExclusiveCallbackGroup()
        self.goal_group = ReentrantCallbackGroup()
        self._waits = Waits(self, WAIT_PERIOD, MutuallyExclusiveCallbackGroup())
        self.goals_in_flight = InFlight()  # goals still to answer (the runner waits at shutdown)
        self.control = TipControl(self.robot, obstacles.ControlParameters(self._params),
                                  self.get_logger(), self._waits.until)
        self._obstacles = obstacles.follow_obstacles(self, self.control)
        self.control.on_goal_started = self._publish_active_goal
        self.health = ControllerHealth(self.control)
        self._stamps = StampRule(self._params['max_stamp_offset'])
        self._cable_states = CableStatesReader(self.cable_names)
        self._command_msg = JointState()
        self._command_pub = self.create_publisher(JointState, 'cable_commands', COMMAND_QOS)
        # The state topics arrive at the measurement rate (hundreds of Hz): a thread of their own
        # serves them, which costs a tenth of the multi-threaded executor's overhead.
        self._intake = make_intake(self, self._params['dedicated_intake_thread'],
                                   'tip_controller_intake')
        self._intake.add(PoseStamped, 'tip_pose', self._on_tip_pose, LATCHED_QOS)
        self._intake.add(PoseStamped, tracker_topic(self.robot), self._on_tip_pose_measured,
                         LATEST_SENSOR_QOS)
        # Kept as bytes: only the backbone that answers a goal is ever decoded.
        self._intake.add(Path, 'backbone', self._on_backbone, LATCHED_QOS, raw=True)
        self._intake.add(JointState, 'cable_states', self._on_cable_states, LATEST_SENSOR_QOS,
                         raw=True)
        self._intake.add(WrenchStamped, tip_wrench_topic(self._params), self._on_tip_wrench,
                         LATEST_SENSOR_QOS)
        # the driver says when it refuses commands (inactive, faulted, disconnected)
        self._driver_status_name = ('%s/%s' % (self.get_namespace().rstrip('/'),
                                               self._params['cable_driver_name'])).lstrip('/')
        self._intake.add(diag.DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        self._intake.add(Bool, 'tip_contact', lambda msg: self.control.on_contact(msg.data),
                         LATCHED_QOS)
        self._intake.start()
        self.create_subscription(TwistStamped, 'tip_twist', self._on_twist, COMMAND_QOS,
                                 callback_group=self._control_group)
        # RViz's Publish Point tool: a click on the workspace markers is a 3-D tip goal
        self.create_subscription(PointStamped, 'tip_goal_point', self._on_goal_point,
                                 COMMAND_QOS, callback_group=self.goal_group)
        publish_workspace(self, self.robot, WORKSPACE_SAMPLES, LATCHED_QOS)
        # every goal taken, from any source, for recordings and plots (latched)
        self._active_goal_pub = self.create_publisher(PoseStamped, 'tip_goal_active',
                                                      LATCHED_QOS)
        self.create_subscription(PoseStamped, 'tip_goal_pose', self._on_goal_pose, COMMAND_QOS,
                                 callback_group=self.goal_group)
        self.create_service(GetPlan, 'tip_goal', self._on_tip_goal,
                            callback_group=self.goal_group)
        action = load_interface()
        self._action = None if action is None else MoveTipServer(
            self, self.control, self.base_frame_id, action, self.goal_group,
            self.goals_in_flight)
        if action is None:
            self.get_logger().warning('continuum_statics_interfaces is not built: no move_tip '
                                      'action (scripts/build_interfaces.sh, or colcon build)')
        self._timer = self._control_timer(self._params['control_rate'])
        steady_timer(self, 1.0 / self._params['diagnostics_rate'], self._publish_diagnostics,
                     callback_group=self._control_group)
        self._params.on_change = self._on_parameter_change
        self.get_logger().info('tip_controller: robot %r, frame %r, max cable speed %g m/s' % (
            self.robot.name, self.base_frame_id, self._params['max_cable_speed']))

    def _control_timer(self, rate):
        timer = steady_timer(self, 1.0 / rate, self._on_control,
                             callback_group=self._control_group)
        timer.cancel()  # runs only while a goal or teleoperation does
        self.control.set_timer(timer)
        return timer

    def _on_parameter_change(self, name, value):
        # called before the table stores the new value
        self.control.on_parameter_change(name, obstacles.control_value(name, value))
        if name == 'control_rate':
            old, self._timer = self._timer, self._control_timer(value)
            self.destroy_timer(old)

    # -- state inputs: parse, then hand to the control ----------------------------------------
    def _on_tip_pose(self, msg):
        try:
            position, quaternion, stamp = base_frame_pose(msg, self.base_frame_id, 'tip_pose')
        except ValueError as error:
            self.control.reject('tip_pose', error)
            return
        self.control.on_tip_pose(position, quaternion_to_rotation(quaternion), stamp)

    def _on_tip_pose_measured(self, msg):
        try:  # an external tracker (motion capture, EM) registered to the base by calibrate
            position, _, stamp, _ = tracked_pose(msg, self.base_frame_id, hint=TRACKER_HINT)
        except ValueError as error:
            self.control.reject('tip_pose_measured', error)
            return
        # a stamp far from the clock (1970) or backwards: arrival, warned and counted
        stamp, age, reason = self._stamps.judge_age('tip_pose_measured', stamp,
                                                    self.get_clock().now().nanoseconds)
        if reason:
            self.control.reject('stamp', reason)
        self.control.on_tip_pose_measured(position, stamp, age)

    def _on_backbone(self, data):
        # Only the stamp is read here (decoding every Path costs ~0.2 ms); the whole message
        # is decoded and checked when a goal answers with it (answer_plan).
        try:
            self.control.on_backbone(header_stamp_ns(data), data)
        except ValueError as error:
            self.control.reject('backbone', 'malformed Path: %s' % error)

    def _on_cable_states(self, data):
        try:
            view, measured = self._cable_states.read(data)
        except ValueError as error:
            self.control.reject('cable_states', error)
            return
        self.control.on_cable_states(measured, stamp_ns(view))

    def _on_tip_wrench(self, msg):
        try:
            wrench = tip_load(msg, self.base_frame_id,
                              *tip_wrench_limits(self.robot, self._params))
        except ValueError as error:
            self.control.reject('tip_wrench', error)
            return
        self.control.on_tip_wrench(wrench)

    def _on_diagnostics(self, msg):
        refusal = diag.driver_refusal(msg, self._driver_status_name)
        if refusal is not None:
            self.control.on_driver_status(refusal)

    # -- goals ---------------------------------------------------------------------------------
    def _direction(self, pose_stamped):
        """Tip direction goal (unit z axis of the goal orientation), or None when ignored."""
        if not self.control.wants_direction:
            return None
        return goal_direction(pose_stamped, 'goal_orientation is direction')

    async def _on_tip_goal(self, request, response):
        with self.goals_in_flight:
            return await self._answer_tip_goal(request, response)

    async def _answer_tip_goal(self, request, response):
        header = Header(frame_id=self.base_frame_id, stamp=self.get_clock().now().to_msg())
        response.plan = Path(header=header)
        control = self.control
        try:
            # GetPlan's tolerance is a float32
            tolerance = control.checked_tolerance(float32_value(request.tolerance))
            goal = await control.start_goal(goal_position(request.goal, self.base_frame_id),
                                            tolerance, 'tip_goal service',
                                            self._direction(request.goal))
            await control.goal_end(goal)
            if goal.reached:
                response.plan = await answer_plan(control, goal, self.base_frame_id) or \
                    response.plan
        except ValueError as error:
            control.goal_rejected(error)
        except Exception as error:  # never let one request take the executor down
            self.get_logger().error('tip_goal failed: %r' % (error,))
            control.goal_rejected('internal error: %r' % (error,))
            response.plan = Path(header=header)
        return response

    async def _on_goal_point(self, msg):
        pose = PoseStamped(header=msg.header)
        pose.pose.position = msg.point
        pose.pose.orientation.w = 1.0
        await self._on_goal_pose(pose)

    async def _on_goal_pose(self, msg):
        try:
            await self.control.start_goal(goal_position(msg, self.base_frame_id),
                                          self._params['default_tolerance'], 'tip_goal_pose',
                                          self._direction(msg))
        except ValueError as error:
            self.control.goal_rejected(error)
        except Exception as error:  # never let one message take the node down
            self.get_logger().error('tip_goal_pose failed: %r' % (error,))
            self.control.goal_rejected('internal error: %r' % (error,))

    def _on_twist(self, msg):
        try:
            linear, angular = twist_vectors(msg, self.base_frame_id)
            self.control.twist(linear, angular, stamp_ns(msg.header.stamp),
                               self.get_clock().now().nanoseconds)
        except ValueError as error:
            self.control.reject('tip_twist', error)
        except Exception as error:  # never let one message take the node down
            self.get_logger().error('tip_twist failed: %r' % (error,))
            self.control.reject('tip_twist', 'internal error: %r' % (error,))

    def _publish_active_goal(self, goal):
        active = PoseStamped()
        active.header.frame_id = self.base_frame_id
        active.header.stamp = self.get_clock().now().to_msg()
        set_pose(active.pose, goal.position, (0.0, 0.0, 0.0, 1.0))
        self._active_goal_pub.publish(active)

    # -- control loop --------------------------------------------------------------------------
    def _on_control(self):
        lengths = self.control.tick()
        if lengths is None:
            return
        try:
            msg = joint_state(self.cable_names, lengths, self.get_clock().now().to_msg(),
                              msg=self._command_msg)
        except ValueError as error:
            self.control.reject('cable_commands', error)
            return
        self._command_pub.publish(msg)

    # -- diagnostics and shutdown --------------------------------------------------------------
    def _publish_diagnostics(self):
        level, message, values = self.health.report(self.count_publishers,
                                                    self._command_pub.topic_name)
        level, message = self._obstacles.diagnose(level, message, values)
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))

    def release_waiters(self):
        """End the goal in progress so that a waiting service call returns (shutdown)."""
        self.control.closing = True
        self._waits.release_all()
        self.control.release()

    def destroy_node(self):
        """Release waiting service calls, stop the intake thread, then destroy the node."""
        self.release_waiters()
        if self._action is not None:
            self._action.destroy()
        self._intake.stop()
        return super().destroy_node()


def main(args=None):
    """Run the tip_controller node (``ros2 run continuum_statics tip_controller``)."""
    return run_nodes([TipControllerNode], args)


if __name__ == '__main__':
    sys.exit(main())
