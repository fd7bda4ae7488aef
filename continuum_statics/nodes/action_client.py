"""An rclpy ActionClient whose goal, result and cancel futures always complete.

A client that sends goals (``move_tip``) from one thread while an executor spins its node in
another, the usual shape of a test or a lab's script, can get a future that never completes
from the stock client of either tested distribution:

- Jazzy (rclpy 7.1.6) registers a request's future after sending it: a response taken by the
  executor in between is dropped ("Ignoring unexpected goal response", ros2/rclpy#1123);
- Kilted (rclpy 9.1.2) registers it under a lock (ros2/rclpy#1308), then registers a second
  future for the same goal outside it and returns that one (the duplicate ros2/rclpy#1532
  removed): a response taken in between completes the first and the returned one never.

:class:`HandoverActionClient` sends and registers each request under one lock that the
executor's take of the responses holds too, so a response is taken only after its future is
registered, and it returns the future it registered. Use it where ``rclpy.action.ActionClient``
is used.
"""
from contextlib import nullcontext
import threading

from rclpy.action import ActionClient
from rclpy.task import Future


class HandoverActionClient(ActionClient):
    """``rclpy.action.ActionClient`` whose requests are sent and registered in one handover.

    The same arguments; the executor's take of the responses waits for a send in progress.
    """

    def __init__(self, *args, **kwargs):
        self._handover = threading.Lock()
        super().__init__(*args, **kwargs)

    def take_data(self):
        """Take the ready responses (the executor's thread), never inside a send."""
        with self._handover:
            return super().take_data()

    def send_goal_async(self, goal, feedback_callback=None, goal_uuid=None):
        """Send ``goal``; return the future of its goal handle (as the stock client)."""
        if not isinstance(goal, self._action_type.Goal):
            raise TypeError('Expected goal type (%s) but received (%s)'
                            % (self._action_type.Goal, type(goal)))
        request = self._action_type.Impl.SendGoalService.Request()
        request.goal_id = self._generate_random_uuid() if goal_uuid is None else goal_uuid
        request.goal = goal
        future = Future()
        # Kilted's client sends under its own lock too (Jazzy's has none)
        with self._handover, getattr(self, '_lock', nullcontext()):
            sequence_number = self._client_handle.send_goal_request(request)
            if sequence_number in self._pending_goal_requests:
                raise RuntimeError('Sequence (%d) conflicts with pending goal request'
                                   % sequence_number)
            self._pending_goal_requests[sequence_number] = future
            self._goal_sequence_number_to_goal_id[sequence_number] = request.goal_id
            future.add_done_callback(self._remove_pending_goal_request)
            self.add_future(future)  # so the executor is aware
            if feedback_callback is not None:  # before any feedback can be taken
                self._feedback_callbacks[bytes(request.goal_id.uuid)] = feedback_callback
        return future

    def _get_result_async(self, goal_handle):
        with self._handover:
            return super()._get_result_async(goal_handle)

    def _cancel_goal_async(self, goal_handle):
        with self._handover:
            return super()._cancel_goal_async(goal_handle)
