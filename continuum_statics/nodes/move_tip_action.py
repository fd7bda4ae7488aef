"""The ``move_tip`` action (continuum_statics_interfaces/action/MoveTip) of the tip_controller.

Goal: target pose (position in the base frame; with ``use_direction`` its orientation's z axis
is the tip direction goal) and tolerance (m). Feedback at ``FEEDBACK_HZ``: the measured tip, the
distance still to go and the run's phase. Result: reached, error (m), the backbone at the reached
state, and a message saying why when not reached. Cancel ends the goal where the cables are
(nothing more is commanded); a newer goal from any source pre-empts it (aborted, "pre-empted").
The GetPlan service ``tip_goal`` stays for existing clients.
"""
import math

import numpy as np
from rclpy.action import ActionServer, CancelResponse, GoalResponse

from continuum_statics.core.rotations import quaternion_to_rotation
from continuum_statics.nodes.ros_conversions import goal_position, set_pose

#: Feedback rate while a goal runs, Hz.
FEEDBACK_HZ = 10.0


def load_interface():
    """Return the MoveTip action type, or None when the interfaces package is not built."""
    try:
        from continuum_statics_interfaces.action import MoveTip
    except ImportError:
        return None
    return MoveTip


class MoveTipServer:
    """Serve ``move_tip`` for a tip_controller node (its goal run does the work)."""

    def __init__(self, node, action_type, callback_group):
        self.node = node
        self.action_type = action_type
        self.server = ActionServer(node, action_type, 'move_tip', self._execute,
                                   goal_callback=self._on_goal,
                                   cancel_callback=lambda _: CancelResponse.ACCEPT,
                                   callback_group=callback_group)

    def destroy(self):
        """Destroy the action server (node shutdown)."""
        self.server.destroy()

    @staticmethod
    def _on_goal(request):
        p = request.target.pose.position
        values = (p.x, p.y, p.z, request.tolerance)
        return GoalResponse.ACCEPT if all(map(math.isfinite, values)) else GoalResponse.REJECT

    def _execute(self, handle):
        node = self.node
        request = handle.request
        result = self.action_type.Result()
        result.backbone.header.frame_id = node.base_frame_id
        try:
            position = goal_position(request.target, node.base_frame_id)
            direction = None
            if request.use_direction:
                q = request.target.pose.orientation
                quaternion = np.array([q.x, q.y, q.z, q.w])
                norm = float(np.linalg.norm(quaternion))
                if not abs(norm - 1.0) < 1e-3:
                    raise ValueError('use_direction but the target orientation is not a unit '
                                     'quaternion (norm %.3g)' % norm)
                direction = quaternion_to_rotation(quaternion / norm)[:, 2]
            goal = node.start_goal(position, node.checked_tolerance(request.tolerance),
                                   'move_tip action', direction)
        except ValueError as error:
            node.goal_rejected(error)
            result.message = 'rejected: %s' % error
            result.error = math.nan
            handle.abort()
            return result
        feedback = self.action_type.Feedback()
        feedback.tip.header.frame_id = node.base_frame_id
        while not goal.done.wait(1.0 / FEEDBACK_HZ):
            if handle.is_cancel_requested:
                node.finish_goal(goal, False, 'cancelled: the cables hold where they are')
                break
            if not handle.is_active:  # the server shut down
                node.finish_goal(goal, False, 'shutting down')
                break
            tip = node.latest_tip()
            if tip is not None:
                set_pose(feedback.tip.pose, tip.position, (0.0, 0.0, 0.0, 1.0))
                feedback.tip.header.stamp.sec = int(tip.stamp_ns // 1_000_000_000)
                feedback.tip.header.stamp.nanosec = int(tip.stamp_ns % 1_000_000_000)
            feedback.distance = float(goal.error) if math.isfinite(goal.error) else -1.0
            feedback.phase = node.phase()
            handle.publish_feedback(feedback)
        goal.done.wait(2.0)
        result.reached = bool(goal.reached)
        result.error = float(goal.error) if math.isfinite(goal.error) else -1.0
        result.message = goal.reason
        if goal.reached:
            plan = node.plan_after(goal.tip_stamp)
            if plan is not None:
                result.backbone = plan
            handle.succeed()
        elif handle.is_cancel_requested:
            handle.canceled()
        else:
            handle.abort()
        return result
