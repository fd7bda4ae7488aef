"""An action server that counts the results it owes, so that shutdown waits for their sends.

At shutdown the runner released every goal and then waited a fixed 0.2 s for the results to be
sent, by executor tasks that run after each goal's callback returns: on a loaded machine a
result was still unsent when the executor stopped, and the client of a goal running at SIGINT
got none (issue 44). :meth:`AnsweringActionServer.owed` counts result requests not answered
yet, so the runner waits for the sends themselves.

Tried and left out: pacing the results of a burst (four at once, then one per 10 ms) let a client
with rclpy's default QoS (a result reader that keeps 10) receive all 100 results of a burst under
a CPU hog (5 of 5 runs, against 1 of 5 complete before), but four deep-QoS clients on a
two-thread executor then received 643 of 1,000 results (every one was sent). A client sending
bursts of more than 10 goals uses deeper QoS
(:data:`~continuum_statics.nodes.qos.ACTION_SERVICE_QOS`, as ``doc/nodes.md`` says).
"""
import threading

from rclpy.action import ActionServer


class AnsweringActionServer(ActionServer):
    """rclpy's ``ActionServer`` that counts the result requests it has not answered yet.

    Same arguments as ``rclpy.action.ActionServer``. Overrides two of its private methods (the
    result request and the result send), the same in Jazzy (rclpy 7) and Kilted (rclpy 9).
    """

    def __init__(self, *args, **kwargs):
        # before the base registers the server with a node that may already spin
        self._owed = {}  # id(request header) -> header: asked for and not sent yet
        self._owed_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def owed(self):
        """Return how many result requests have not been answered yet."""
        with self._owed_lock:
            return len(self._owed)

    async def _execute_get_result_request(self, request_header_and_message):
        header, request = request_header_and_message
        if bytes(request.goal_id.uuid) in self._goal_handles:  # else answered UNKNOWN at once
            with self._owed_lock:
                self._owed[id(header)] = header
        await super()._execute_get_result_request(request_header_and_message)

    def _send_result_response(self, request_header, future):
        """Send the result (an executor task runs this once the goal's result is set)."""
        try:
            super()._send_result_response(request_header, future)
        finally:
            with self._owed_lock:
                self._owed.pop(id(request_header), None)
