"""Cross-process: the real bringup entry point as a subprocess and an independent client node."""
import os
import subprocess
import sys
import time
import uuid

from conftest import REPO
from nodes_helpers import (
    LATCHED,
    Collector,
    pose_xyz,
    stop_process,
    wait_until,
)
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from nav_msgs.msg import Path  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from continuum_statics import load_robot  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


def start_bringup(*args):
    return subprocess.Popen([sys.executable, '-m', 'continuum_statics', 'bringup', *args],
                            cwd=REPO, env=os.environ.copy(), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def request(position, tolerance):
    msg = GetPlan.Request(tolerance=float(tolerance))
    msg.goal.header.frame_id = 'base_link'
    p = msg.goal.pose.position
    p.x, p.y, p.z = (float(v) for v in position)
    msg.goal.pose.orientation.w = 1.0
    return msg


class BringupClient:
    """The bringup entry point as a subprocess and a client node of our own in its namespace.

    ``with BringupClient(...) as client``: ``client.node`` to subscribe and call with,
    ``client.spin_until`` to wait (failing at once if bringup exits); afterwards
    ``client.code`` and ``client.output`` hold the process's exit code and output.
    """

    def __init__(self, name, namespace, *args):
        self.name, self.namespace = name, namespace
        self.process = start_bringup(*args)
        self.code = self.output = None

    def __enter__(self):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = rclpy.executors.SingleThreadedExecutor(context=self.context)
        self.node = None
        try:
            self.node = rclpy.create_node(self.name, namespace=self.namespace,
                                          context=self.context)
            self.executor.add_node(self.node)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def spin_until(self, predicate, timeout, what):
        deadline = time.monotonic() + timeout
        while not predicate():
            assert self.process.poll() is None, 'bringup exited: %s' % self.process.stdout.read()
            assert time.monotonic() < deadline, 'timed out after %g s: %s' % (timeout, what)
            self.executor.spin_once(timeout_sec=0.02)

    def __exit__(self, *_):
        self.executor.shutdown()
        if self.node is not None:
            self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        self.code = stop_process(self.process)
        self.output = self.process.stdout.read()
        return False


def test_bringup_serves_backbone_and_tip_goals_to_another_process():
    namespace = 'cross_' + uuid.uuid4().hex[:8]
    with BringupClient('cross_process_client', namespace, '--namespace', namespace,
                       '--ros-args', '--params-file',
                       str(REPO / 'config' / 'continuum_robot.params.yaml')) as client:
        backbone = Collector(client.node, Path, 'backbone', LATCHED)
        tip = Collector(client.node, PoseStamped, 'tip_pose', LATCHED)
        service = client.node.create_client(GetPlan, 'tip_goal')
        spin_until = client.spin_until

        spin_until(lambda: len(backbone) > 0 and len(tip) > 0, 30.0, 'backbone and tip_pose')
        # The newest backbone and tip pose of one measurement agree.
        spin_until(lambda: backbone.last.header.stamp == tip.last.header.stamp, 10.0,
                   'a backbone and a tip pose with the same stamp')
        path, pose = backbone.last, tip.last
        assert path.header.frame_id == pose.header.frame_id == 'base_link'
        assert len(path.poses) == 20
        assert path.poses[-1].pose == pose.pose
        np.testing.assert_allclose(pose_xyz(path.poses[0].pose), [0.0, 0.0, 0.0], atol=1e-9)

        spin_until(service.service_is_ready, 10.0, 'the tip_goal service')
        goal = ROBOT.solve_ivp([-1.5, 2.0, 0.0]).tip_position
        future = service.call_async(request(goal, 1e-3))
        spin_until(future.done, 30.0, 'the answer to a reachable goal')
        plan = future.result().plan
        assert len(plan.poses) == 20
        assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3

        started = time.monotonic()
        future = service.call_async(request((2.0, 0.0, 0.3), 1e-3))
        spin_until(future.done, 10.0, 'the answer to an unreachable goal')
        assert time.monotonic() - started < 5.0
        assert len(future.result().plan.poses) == 0
    assert client.code == 0, client.output
    assert 'Traceback' not in client.output, client.output


def test_bringup_rejects_a_missing_robot_file_quickly():
    process = start_bringup('--robot', '/nonexistent/robot.yaml')
    try:
        code = process.wait(30.0)
    finally:
        stop_process(process)
    assert code != 0
    assert 'does not exist' in process.stdout.read()


def test_bringup_reports_a_bad_parameter_instead_of_a_traceback():
    process = start_bringup('--namespace', 'bad_' + uuid.uuid4().hex[:8], '--ros-args', '-p',
                            'path_samples:=1')
    try:
        code = process.wait(60.0)
    finally:
        stop_process(process)
    output = process.stdout.read()
    assert code == 1, output
    assert 'path_samples' in output and 'Traceback' not in output, output


def test_wait_until_fails_with_the_reason():
    with pytest.raises(AssertionError, match='waiting for nothing'):
        wait_until(lambda: False, 0.05, 'nothing')


def test_bringup_with_a_passive_rod_publishes_its_shape_and_rejects_goals():
    rod_file = REPO / 'config' / 'jones2009_nitinol_rod.yaml'
    rod = load_robot(rod_file)
    namespace = 'rod_' + uuid.uuid4().hex[:8]
    with BringupClient('rod_client', namespace, '--robot', str(rod_file),
                       '--namespace', namespace) as client:
        backbone = Collector(client.node, Path, 'backbone', LATCHED)
        service = client.node.create_client(GetPlan, 'tip_goal')
        spin_until = client.spin_until

        spin_until(lambda: len(backbone) > 0, 30.0, 'the passive backbone')
        np.testing.assert_allclose(pose_xyz(backbone.last.poses[-1].pose),
                                   rod.solve_bvp().tip_position, atol=1e-6)
        spin_until(service.service_is_ready, 10.0, 'the tip_goal service')
        started = time.monotonic()
        future = service.call_async(request(rod.solve_bvp().tip_position, 1e-3))
        spin_until(future.done, 10.0, 'the answer')
        assert time.monotonic() - started < 2.0
        assert len(future.result().plan.poses) == 0
        time.sleep(2.5)  # long enough for a repeated warning to show
    output = client.output
    assert client.code == 0, output
    assert 'robot has no cables' in output
    assert 'no cable names in the message' not in output, output
    assert 'Traceback' not in output, output


def test_bringup_with_a_helical_cable_reaches_goals_and_draws_the_helix():
    """The helical example robot with the simulated driver: goals served, the helix drawn.

    config/helical_robot.yaml: three straight cables and a half-turn helix. A goal the helix's
    pull reaches is served, and the helix's marker runs through its holes (at 60 degrees at the
    base disk, at 240 degrees at the tip disk).
    """
    robot_file = REPO / 'config' / 'helical_robot.yaml'
    robot = load_robot(robot_file)
    namespace = 'helix_' + uuid.uuid4().hex[:8]
    with BringupClient('helix_client', namespace, '--robot', str(robot_file),
                       '--namespace', namespace) as client:
        markers = Collector(client.node, MarkerArray, 'backbone_markers', LATCHED)
        tip = Collector(client.node, PoseStamped, 'tip_pose', LATCHED)
        service = client.node.create_client(GetPlan, 'tip_goal')
        spin_until = client.spin_until

        spin_until(service.service_is_ready, 30.0, 'the tip_goal service')
        goal = robot.solve_tensions([0.0, 0.0, 0.0, 2.0]).tip_position
        future = service.call_async(request(goal, 1e-3))
        spin_until(future.done, 30.0, 'the answer to a goal of the helix')
        plan = future.result().plan
        assert len(plan.poses) > 0
        assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
        spin_until(lambda: tip.last is not None
                   and np.linalg.norm(pose_xyz(tip.last.pose) - goal) < 2e-3, 30.0,
                   'the measured tip at the goal')

        def helix_line():
            for array in reversed(markers.messages):
                lines = [m for m in array.markers if m.ns.endswith('cables')]
                if len(lines) == 4:
                    return lines[3]
            return None

        spin_until(lambda: helix_line() is not None, 10.0, 'the cable markers')
        points = np.array([[p.x, p.y, p.z] for p in helix_line().points])
        radius, start = 0.010, np.pi / 3.0
        np.testing.assert_allclose(points[0], [radius * np.cos(start), radius * np.sin(start),
                                               0.0], atol=1e-9)
        assert len(points) == 1 + len(robot.guides)
        # at the tip disk the hole has turned half a turn about the rod: opposite the base's
        pose = tip.last.pose
        quaternion = [pose.orientation.x, pose.orientation.y, pose.orientation.z,
                      pose.orientation.w]
        local = Rotation.from_quat(quaternion).inv().apply(points[-1] - pose_xyz(pose))
        np.testing.assert_allclose(local, [radius * np.cos(start + np.pi),
                                           radius * np.sin(start + np.pi), 0.0], atol=2e-4)
    assert client.code == 0, client.output
    assert 'Traceback' not in client.output, client.output
