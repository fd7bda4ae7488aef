"""Issue 38 items 1 and 5: a failing callback stops no other node; goals answered at shutdown.

Both failed on main before the fix: ``run_nodes`` ended the whole process when one node's
executor raised, and a move_tip goal running at SIGINT never got a result.
"""
import subprocess
import sys
import textwrap
import threading
import time

from conftest import REPO
from nodes_helpers import wait_until
import pytest
from test_goal_reliability import ROBOT, Bringup, accepted_goals, action_client, send_goal

pytestmark = pytest.mark.ros  # starts DDS or a process

rclpy = pytest.importorskip('rclpy')

# A process of two nodes: ``failing`` raises on its first timer tick, then prints; ``steady``
# prints on every tick. Both must go on printing after the failure.
TWO_NODES = textwrap.dedent("""
    import sys
    from rclpy.node import Node
    from continuum_statics.nodes.node_runner import run_nodes

    class Ticking(Node):
        def __init__(self, name, fail):
            super().__init__(name)
            self.fail = fail
            self.create_timer(0.05, self.tick)

        def tick(self):
            if self.fail:
                self.fail = False
                raise RuntimeError('one bad measurement')
            print(self.get_name(), 'alive', flush=True)

    sys.exit(run_nodes([lambda: Ticking('failing', True), lambda: Ticking('steady', False)],
                       []))
""")


def test_a_callback_that_raises_stops_no_node_and_is_reported(tmp_path):
    out, err = tmp_path / 'out.txt', tmp_path / 'err.txt'
    with open(out, 'wb') as stdout, open(err, 'wb') as stderr:
        process = subprocess.Popen([sys.executable, '-c', TWO_NODES], cwd=str(REPO),
                                   stdout=stdout, stderr=stderr)
    try:
        wait_until(lambda: out.read_text().count('failing alive') >= 3
                   and out.read_text().count('steady alive') >= 3, 30.0,
                   'both nodes alive after the failure: %s' % err.read_text()[-2000:])
        assert process.poll() is None, 'the process ended: %s' % err.read_text()
        text = err.read_text()
        assert "a callback of node 'failing' failed" in text, text
        assert 'one bad measurement' in text and 'restart 1 of' in text, text
        process.send_signal(2)
        assert process.wait(timeout=10.0) == 1  # a failure happened: said in the exit code
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def slow_bringup(tmp_path, namespace):
    """Return (bringup with slow cables: a goal runs for seconds, a client node, its executor)."""
    bringup = Bringup(tmp_path / 'bringup.log', namespace, '-p', 'max_cable_speed:=0.002')
    node = rclpy.create_node('shutdown_client', namespace='/' + namespace,
                             context=bringup.context)
    executor = rclpy.executors.SingleThreadedExecutor(context=bringup.context)
    executor.add_node(node)
    return bringup, node, executor


def test_a_goal_running_at_sigint_gets_a_result_saying_so(tmp_path):
    bringup, node, executor = slow_bringup(tmp_path, 'shutdown38')
    try:
        client = action_client(node)
        threading.Thread(target=executor.spin, daemon=True).start()
        wait_until(client.server_is_ready, 60.0, 'bringup up')
        # a goal answered first, to where the robot already is: the way back is matched (see
        # accepted_goals; sent to the far tip, an unanswered first goal ran there for the 5 s
        # before the next, which then ended at once: CI, Jazzy)
        first = [h.get_result_async() for h in accepted_goals(
            client, ROBOT.solve_ivp([0.0, 0.0, 0.0]).tip_position)]
        wait_until(lambda: all(f.done() for f in first), 30.0, 'the first goal answered')
        handle = send_goal(client, ROBOT.solve_ivp([2.5, 0.0, 0.0]).tip_position)
        wait_until(handle.done, 30.0, 'the slow goal accepted')
        assert handle.result().accepted
        result = handle.result().get_result_async()
        time.sleep(0.5)  # the goal is running (a slow ramp: about 4.4 s)
        ended_before = result.done()
        start = time.monotonic()
        bringup.process.send_signal(2)
        wait_until(result.done, 8.0, 'the result of the goal running at SIGINT: %s'
                   % bringup.output())
        latency = time.monotonic() - start
        answer = result.result()
        assert not ended_before, 'the goal ended before SIGINT: %s' % answer.result.message
        assert answer.status == 6 and 'shutting down' in answer.result.message, answer
        assert not answer.result.reached
        print('result %.2f s after SIGINT' % latency)
        assert bringup.process.wait(timeout=10.0) == 0, bringup.output()
        executor.shutdown()
    finally:
        bringup.close()


def test_a_service_goal_running_at_sigint_gets_its_answer(tmp_path):
    """The service side of item 5 (answered before the fix as well: a guard)."""
    from nav_msgs.srv import GetPlan

    bringup, node, executor = slow_bringup(tmp_path, 'shutdown38s')
    try:
        service = node.create_client(GetPlan, 'tip_goal')
        threading.Thread(target=executor.spin, daemon=True).start()
        assert service.wait_for_service(timeout_sec=60.0), bringup.output()
        request = GetPlan.Request(tolerance=1e-3)
        request.goal.header.frame_id = 'base_link'
        p = request.goal.pose.position
        p.x, p.y, p.z = (float(v) for v in ROBOT.solve_ivp([2.5, 0.0, 0.0]).tip_position)
        answer = service.call_async(request)
        wait_until(lambda: 'tip_goal service' in bringup.output(), 20.0,
                   'the goal started: %s' % bringup.output())
        assert not answer.done()
        bringup.process.send_signal(2)
        wait_until(answer.done, 8.0, 'the answer of the goal running at SIGINT: %s'
                   % bringup.output())
        assert not answer.result().plan.poses  # not reached: an empty plan, reason logged
        assert bringup.process.wait(timeout=10.0) == 0, bringup.output()
        executor.shutdown()
    finally:
        bringup.close()


def test_a_burst_of_100_goals_is_all_answered_and_the_last_one_at_sigint_too(tmp_path):
    """Issue 44 item 2: 99 goals pre-empted in a burst, the 100th running at SIGINT: 100 results.

    The shutdown waits until every result asked for is sent (before: a fixed 0.2 s after the
    goals ended, and on a loaded machine the client of the goal running at SIGINT got none).
    """
    from test_goal_reliability import action_client, reachable

    bringup, node, executor = slow_bringup(tmp_path, 'burst44')
    try:
        client = action_client(node)
        threading.Thread(target=executor.spin, daemon=True).start()
        wait_until(client.server_is_ready, 60.0, 'bringup up')
        # a goal answered first: the way back is matched (see accepted_goals)
        first = [h.get_result_async() for h in accepted_goals(client, reachable(5, 1)[0])]
        assert first
        results = []

        def ask_result(future):
            if future.result().accepted:
                results.append(future.result().get_result_async())

        handles = [send_goal(client, position) for position in reachable(4, 100)]
        for handle in handles:
            handle.add_done_callback(ask_result)
        # (a handle is done before its done-callback ran: wait for the callbacks' results)
        wait_until(lambda: len(results) == 100, 60.0, 'the 100 goals accepted, results asked')
        wait_until(lambda: sum(r.done() for r in results + first) >= 99 + len(first), 30.0,
                   'the pre-empted results')
        running = [r for r in results if not r.done()]
        assert len(running) == 1  # the last of the burst runs (slow cables)
        assert all(r.result().status == 6 and 'pre-empted' in r.result().result.message
                   for r in results if r.done())
        bringup.process.send_signal(2)
        wait_until(running[0].done, 8.0, 'the last result after SIGINT: %s' % bringup.output())
        assert 'shutting down' in running[0].result().result.message
        assert bringup.process.wait(timeout=10.0) == 0, bringup.output()
        executor.shutdown()
    finally:
        bringup.close()
