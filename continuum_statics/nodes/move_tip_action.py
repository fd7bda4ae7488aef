"""The ``move_tip`` action (continuum_statics_interfaces/action/MoveTip) of the tip_controller.

Goal: target pose (position in the base frame; with ``use_direction`` its orientation's z axis
is the tip direction goal) and tolerance (m). Feedback at ``FEEDBACK_HZ``: the measured tip, the
distance still to go (-1 while unknown) and the run's phase. Result: reached, error (m; -1 when
no tip was judged, e.g. a rejected goal), the backbone at the reached state, and a message saying
why when not reached. Cancel ends the goal where the cables are (nothing more is commanded); a
newer goal from any source pre-empts it (aborted, "pre-empted"). The GetPlan service
``tip_goal`` stays for existing clients.

Each goal is a coroutine that awaits its end (:mod:`~continuum_statics.nodes.waits`): however
many goals wait, identical or not, none holds an executor thread. The goal, cancel and result
services keep every request of a burst (:data:`~continuum_statics.nodes.qos.ACTION_SERVICE_QOS`,
depth 1000; a client sending bursts of more than 10 goals gives its ActionClient the same), and
a result is kept ``RESULT_TIMEOUT`` after its goal ended (Kilted's default, 10 s, answered results
asked for later with UNKNOWN; Jazzy's is 900 s). The server counts the results it
owes (:mod:`~continuum_statics.nodes.action_results`): shutdown waits until each is sent.
"""
import math
import time

from rclpy.action import CancelResponse, GoalResponse

from continuum_statics.nodes.action_results import AnsweringActionServer
from continuum_statics.nodes.qos import ACTION_SERVICE_QOS
from continuum_statics.nodes.ros_conversions import (
    backbone_path,
    goal_direction,
    goal_position,
    ns_to_stamp,
    set_pose,
)
from continuum_statics.nodes.waits import InFlight

#: Feedback rate while a goal runs, Hz.
FEEDBACK_HZ = 10.0
#: How long the server keeps a result after its goal ended, s.
RESULT_TIMEOUT = 900
#: ``error`` and ``distance`` when no tip was judged, m.
UNKNOWN = -1.0


def load_interface():
    """Return the MoveTip action type, or None when the interfaces package is not built."""
    try:
        from continuum_statics_interfaces.action import MoveTip
    except ImportError:
        return None
    return MoveTip


async def answer_plan(control, goal, base_frame_id):
    """Return the backbone (nav_msgs/Path) of a reached goal's tip, or None (reason logged)."""
    data = await control.backbone_after(goal.tip_stamp)
    if data is None:
        return None
    try:
        return backbone_path(data, base_frame_id)
    except ValueError as error:
        control.reject('backbone', error)
        return None


class MoveTipServer:
    """Serve ``move_tip`` for a tip_controller node.

    :param node: the node that hosts the action server
    :param control: the node's :class:`~continuum_statics.control.tip_control.TipControl`: all
        this server calls
    :param base_frame_id: the robot's base frame
    """

    def __init__(self, node, control, base_frame_id, action_type, callback_group,
                 in_flight=None):
        self.control = control
        self.in_flight = in_flight or InFlight()
        self._tickets = {}  # goal id: its hand-over ticket, from acceptance to execute
        self.base_frame_id = base_frame_id
        self.action_type = action_type
        self.server = AnsweringActionServer(node, action_type, 'move_tip', self._counted,
                                            goal_callback=self._on_goal,
                                            handle_accepted_callback=self._on_accepted,
                                            cancel_callback=lambda _: CancelResponse.ACCEPT,
                                            callback_group=callback_group,
                                            goal_service_qos_profile=ACTION_SERVICE_QOS,
                                            result_service_qos_profile=ACTION_SERVICE_QOS,
                                            cancel_service_qos_profile=ACTION_SERVICE_QOS,
                                            result_timeout=RESULT_TIMEOUT)
        self.in_flight.also(self.server.owed)  # shutdown waits for the results' sends

    def destroy(self):
        """Destroy the action server (node shutdown)."""
        self.server.destroy()

    def _on_goal(self, request):
        p = request.target.pose.position
        values = (p.x, p.y, p.z, request.tolerance)
        if all(map(math.isfinite, values)):
            return GoalResponse.ACCEPT
        # refused before it has a handle: no result carries the reason, the log and count do
        self.control.goal_rejected('move_tip goal with a non-finite number: position '
                                   '(%g, %g, %g), tolerance %g' % values)
        return GoalResponse.REJECT

    def _on_accepted(self, handle):
        # its place in the hand-over now, as the request arrives: execute runs later (under a
        # CPU hog after the twists that followed the goal, and then overtook them); a goal that
        # execute will reject takes none (it must not overtake a valid one)
        request = handle.request
        try:
            self.control.check_goal(goal_position(request.target, self.base_frame_id))
            self.control.checked_tolerance(request.tolerance)
            self._direction(request)
        except ValueError:
            pass  # execute rejects it with the reason
        else:
            self._tickets[bytes(handle.goal_id.uuid)] = self.control.goal_arrived()
        handle.execute()

    @staticmethod
    def _direction(request):
        if not request.use_direction:
            return None
        return goal_direction(request.target, 'use_direction', 'target')

    async def _counted(self, handle):
        with self.in_flight:
            return await self._execute(handle)

    async def _execute(self, handle):
        control, frame = self.control, self.base_frame_id
        request, ticket = handle.request, self._tickets.pop(bytes(handle.goal_id.uuid), None)
        result = self.action_type.Result()
        result.backbone.header.frame_id = frame
        result.error = UNKNOWN
        try:
            goal = await control.start_goal(goal_position(request.target, frame),
                                            control.checked_tolerance(request.tolerance),
                                            'move_tip action', self._direction(request),
                                            ticket)
        except ValueError as error:
            control.goal_rejected(error)
            result.message = 'rejected: %s' % error
            handle.abort()
            return result
        feedback = self.action_type.Feedback()
        feedback.tip.header.frame_id = frame
        while not await control.goal_end(goal, deadline=_next_feedback()):
            if handle.is_cancel_requested:
                control.finish_goal(goal, False, 'cancelled: the cables hold where they are')
                break
            if not handle.is_active:  # the server shut down
                control.finish_goal(goal, False, 'shutting down')
                break
            tip = control.latest_tip()
            if tip is not None:
                set_pose(feedback.tip.pose, tip.position, (0.0, 0.0, 0.0, 1.0))
                ns_to_stamp(tip.stamp_ns, feedback.tip.header.stamp)
            feedback.distance = float(goal.error) if math.isfinite(goal.error) else UNKNOWN
            feedback.phase = control.phase()
            handle.publish_feedback(feedback)
        result.reached = bool(goal.reached)
        result.error = float(goal.error) if math.isfinite(goal.error) else UNKNOWN
        result.message = goal.reason
        if goal.reached:
            plan = await answer_plan(control, goal, frame)
            if plan is not None:
                result.backbone = plan
            handle.succeed()
        elif handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result


def _next_feedback():
    return time.monotonic() + 1.0 / FEEDBACK_HZ
