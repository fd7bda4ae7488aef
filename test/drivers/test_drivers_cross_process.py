"""Cross-process: a tip goal reached through emulated Dynamixel servos.

The servo-bus emulator, cable_driver (dynamixel backend), statics and tip_controller each run in
a process of their own, started from the package's entry points; a client asks for the goal.
"""
import os
import subprocess
import sys
import time
import uuid

from conftest import REPO
from nodes_helpers import Collector, pose_xyz, stop_process
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('dynamixel_sdk')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from nav_msgs.srv import GetPlan  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from continuum_statics import load_robot  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


def start(args, cwd=REPO, stdin=None):
    return subprocess.Popen([sys.executable, '-m', *args], cwd=cwd, env=os.environ.copy(),
                            stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def node(name, namespace, *parameters):
    ros_args = ['--ros-args', '-r', '__ns:=/' + namespace]
    for parameter in parameters:
        ros_args += ['-p', parameter]
    return start(['continuum_statics', name, *ros_args])


def request(position, tolerance):
    msg = GetPlan.Request(tolerance=float(tolerance))
    msg.goal.header.frame_id = 'base_link'
    msg.goal.pose.position.x, msg.goal.pose.position.y, msg.goal.pose.position.z = (
        float(v) for v in position)
    msg.goal.pose.orientation.w = 1.0
    return msg


def test_tip_goal_through_emulated_servos_in_other_processes(tmp_path):
    namespace = 'dxl_' + uuid.uuid4().hex[:8]
    link = tmp_path / 'ttyDXL'
    emulator = start(['emulators.dynamixel_bus', '--ids', '1', '2', '3', '4', '--link',
                      str(link)], cwd=REPO / 'test', stdin=subprocess.PIPE)
    processes = [emulator]
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    client = None
    try:
        assert emulator.stdout.readline().startswith('ready'), 'the emulator did not start'
        processes.append(node('cable_driver', namespace, 'backend:=dynamixel',
                              'dynamixel.port:=%s' % link, 'dynamixel.baudrate:=1000000',
                              'dynamixel.ids:=[1,2,3,4]', 'dynamixel.spool_radius:=0.01',
                              'dynamixel.zero_ticks:=[0]', 'dynamixel.timeout_margin:=0.2',
                              'publish_rate:=100.0',
                              'diagnostics_rate:=10.0'))
        processes.append(node('statics', namespace))
        processes.append(node('tip_controller', namespace, 'settled_cable_error:=3.0e-5'))
        client = rclpy.create_node('cross_process_dxl_client', namespace=namespace,
                                   context=context)
        executor.add_node(client)
        states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
        diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
        goal_service = client.create_client(GetPlan, 'tip_goal')
        reset_service = client.create_client(Trigger, 'cable_driver/reset')

        def spin_until(predicate, timeout, what):
            deadline = time.monotonic() + timeout
            while not predicate():
                for process in processes:
                    assert process.poll() is None, 'a process exited: %s' % (
                        process.stdout.read())
                assert time.monotonic() < deadline, 'timed out after %g s: %s' % (timeout, what)
                executor.spin_once(timeout_sec=0.02)

        def driver_status(after=0):
            for array in reversed(diagnostics.messages[after:]):
                for status in array.status:
                    if status.name.endswith('cable_driver'):
                        return status
            return None

        spin_until(lambda: len(states) > 10, 60.0, 'cable_states from the emulated servos')
        np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths,
                                   atol=1e-12)
        spin_until(goal_service.service_is_ready, 30.0, 'the tip_goal service')
        goal = ROBOT.solve_ivp([-1.5, 2.0, 0.0]).tip_position
        future = goal_service.call_async(request(goal, 1e-3))
        spin_until(future.done, 90.0, 'the answer to a reachable goal')
        plan = future.result().plan
        assert len(plan.poses) > 0, 'goal not reached (see the tip_controller diagnostics)'
        assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
        # The servos really moved: the measured lengths left the straight pose.
        assert np.max(np.abs(np.array(states.last.position)
                             - ROBOT.straight_cable_lengths)) > 1e-3

        # A fault on servo 2 in the emulator process: ERROR on diagnostics, reset clears it.
        seen = len(diagnostics)
        emulator.stdin.write('fault 2 0x20\n')
        emulator.stdin.flush()
        spin_until(lambda: driver_status(seen) is not None and
                   driver_status(seen).level == b'\x02', 10.0, 'ERROR for the overload')
        assert 'servo 2 (cable_1) hardware error: overload' in driver_status(seen).message
        spin_until(reset_service.service_is_ready, 10.0, 'the reset service')
        future = reset_service.call_async(Trigger.Request())
        spin_until(future.done, 10.0, 'the reset answer')
        assert future.result().success, future.result().message
        seen = len(diagnostics)
        spin_until(lambda: driver_status(seen) is not None and
                   driver_status(seen).level == b'\x00', 10.0, 'OK after the reset')
    finally:
        executor.shutdown()
        if client is not None:
            client.destroy_node()
        rclpy.try_shutdown(context=context)
        codes = [stop_process(process) for process in reversed(processes[1:])]
        if emulator.poll() is None:
            emulator.stdin.write('quit\n')
            emulator.stdin.flush()
        stop_process(emulator)
    outputs = [process.stdout.read() for process in processes[1:]]
    for code, output in zip(codes, outputs):
        assert code == 0, output
        assert 'Traceback' not in output, output
