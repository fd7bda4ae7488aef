"""A tip-goal client for the tools and tests: reachable goals, sent through ``tip_goal``."""
import math
import time

import numpy as np

#: Base bending u(0) (1/m) of the demo's goal shapes: reachable tips, all around the robot.
GOAL_BENDINGS = [(2.0, 0.0), (0.0, 2.5), (-1.5, 1.5), (-2.0, -1.0), (1.0, -2.5), (0.5, 0.5),
                 (-2.5, 0.0), (0.0, -1.5)]


def tip_goals(robot, count):
    """Return ``count`` reachable tip goals (m, base frame) and one 2 m away from the base."""
    goals = []
    for ux, uy in GOAL_BENDINGS[:count]:
        goals.append((robot.solve_ivp([ux, uy, 0.0]).tip_position.copy(), True))
    far = np.asarray(robot.solve_ivp([0.0, 0.0, 0.0]).tip_position) + np.array([2.0, 0.0, 0.0])
    goals.append((far, False))
    return goals


def run_client(robot_file, namespace, goals=5, tolerance=1e-3, print_rows=True, process=None,
               timeout=60.0, ready_timeout=600.0):
    """Send the goals through ``<namespace>/tip_goal``; return one dict per goal.

    Waits until bringup is ready (service advertised, which its nodes do only once their
    kernels are compiled, and a first tip pose), up to ``ready_timeout`` s while ``process``
    lives: a cold numba cache on a busy 2-core machine takes a minute or more.

    :param process: the bringup subprocess, to stop waiting early if it dies
    :param timeout: longest wait for one goal's answer, s
    :raises RuntimeError: when bringup is not ready within ``ready_timeout`` or a goal is not
        answered within ``timeout``
    """
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.srv import GetPlan
    import rclpy

    from continuum_statics import load_robot
    from continuum_statics.nodes.qos import LATCHED_QOS
    from continuum_statics.nodes.ros_conversions import path_positions

    robot = load_robot(robot_file)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('tip_goal_client', namespace=namespace, context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    tips = []
    node.create_subscription(PoseStamped, 'tip_pose', tips.append, LATCHED_QOS)
    client = node.create_client(GetPlan, 'tip_goal')
    rows = []
    try:
        started = time.monotonic()
        next_note = started + 10.0
        while not (client.service_is_ready() and tips):
            if process is not None and process.poll() is not None:
                raise RuntimeError('bringup exited with code %s' % process.returncode)
            now = time.monotonic()
            if now > started + ready_timeout:
                raise RuntimeError('bringup not ready within %g s (no tip_goal service and '
                                   'tip_pose)' % ready_timeout)
            if print_rows and now > next_note:
                next_note = now + 10.0
                print('demo: waiting for bringup to be ready (%.0f s; a first run compiles the '
                      'kernels)' % (now - started), flush=True)
            executor.spin_once(timeout_sec=0.05)
        if print_rows:
            print('%-28s %-28s %9s %7s  %s' % ('goal x y z [mm]', 'reached tip x y z [mm]',
                                             'error[mm]', 'time[s]', 'result'))
        for position, reachable in tip_goals(robot, goals):
            request = GetPlan.Request(tolerance=float(tolerance))
            request.goal.header.frame_id = robot.base_frame_id
            request.goal.pose.position.x, request.goal.pose.position.y, \
                request.goal.pose.position.z = (float(v) for v in position)
            request.goal.pose.orientation.w = 1.0
            if print_rows and not reachable:  # before the controller's WARN about it
                print('(last: a goal 2 m away on purpose; the controller WARNs that it is '
                      'unreachable)', flush=True)
            start = time.monotonic()
            future = client.call_async(request)
            executor.spin_until_future_complete(future, timeout_sec=timeout)
            elapsed = time.monotonic() - start
            if not future.done():
                raise RuntimeError('tip_goal did not answer within %g s' % timeout)
            plan = future.result().plan
            tip = path_positions(plan)[-1] if plan.poses else None
            error = math.nan if tip is None else float(np.linalg.norm(tip - position))
            reached = tip is not None and error <= tolerance * (1.0 + 1e-6)
            rows.append({'goal': position, 'tip': tip, 'error': error, 'time': elapsed,
                         'reachable': reachable, 'reached': reached,
                         'backbone': path_positions(plan) if plan.poses else None})
            if print_rows:
                print('%-28s %-28s %9s %7.2f  %s' % (
                    _mm(position), '(empty plan)' if tip is None else _mm(tip),
                    '-' if tip is None else '%.3f' % (error * 1e3), elapsed,
                    ('reached' if reached else 'NOT REACHED') if reachable else
                    ('rejected as unreachable' if tip is None else 'UNEXPECTEDLY REACHED')),
                    flush=True)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    return rows


def _mm(position):
    millimetres = np.asarray(position, dtype=float) * 1e3
    return '%7.1f %7.1f %7.1f' % tuple(np.where(np.abs(millimetres) < 0.05, 0.0, millimetres))
