"""``python -m continuum_statics demo`` (``make demo``): bringup plus a tip-goal client.

Starts ``bringup`` (statics, tip_controller, simulated cable_driver) as a subprocess; this process
is the client: it sends reachable tip goals (tips of shapes the robot can take) and one goal 2 m
away through the ``tip_goal`` service (nav_msgs/srv/GetPlan), prints goal, reached tip, error and
time for each, and a final line of figures. It also draws the backbone of every answered plan
(the reached state) in one PNG (``--plot``, default ``demo_backbones.png``) and prints where.
The demo runs in a private ROS domain (``--domain-id``, default random in 100-199), so it never
talks to a robot on the user's domain. Exit code 0 when every reachable goal was reached
within the tolerance, the unreachable one was answered with an empty plan, and bringup stopped
cleanly on SIGINT.
"""
import argparse
import math
import os
import random
import subprocess
import sys
import time

import numpy as np

from continuum_statics.nodes.node_params import default_robot_file
from continuum_statics.tools.node_bench import ros_environment, stop

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
    from continuum_statics.nodes.ros_conversions import path_positions
    from continuum_statics.nodes.statics_node import LATCHED_QOS

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


def write_plot(output, robot_file, reached):
    """Draw the backbone of every reached goal with the goals; print the file's path."""
    from continuum_statics import load_robot
    from continuum_statics.tools.plot import plot_backbones

    robot = load_robot(robot_file)
    backbones = [('goal %d' % (i + 1), row['backbone']) for i, row in enumerate(reached)]
    plot_backbones(output, backbones, goals=[row['goal'] for row in reached],
                   frame_id=robot.base_frame_id,
                   title='%s: backbone at each reached goal' % robot.name)
    print('demo: backbone at each reached goal drawn in %s' % os.path.abspath(output),
          flush=True)


def main(argv=None):
    """Run the demo; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics demo',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--robot', default=default_robot_file(), help='robot description YAML')
    parser.add_argument('--namespace', default='continuum', help='bringup namespace')
    parser.add_argument('--goals', type=int, default=5, help='reachable goals (max %d)'
                        % len(GOAL_BENDINGS))
    parser.add_argument('--tolerance', type=float, default=1e-3, help='tip tolerance, m')
    parser.add_argument('--plot', default='demo_backbones.png',
                        help='PNG of the backbone at each reached goal (default %(default)s)')
    parser.add_argument('--domain-id', type=int, default=random.randint(100, 199),
                        help='private ROS_DOMAIN_ID of the demo (default: random in 100-199)')
    options = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    os.environ['ROS_DOMAIN_ID'] = str(options.domain_id)
    ros_environment()
    robot_file = os.path.abspath(options.robot)
    # Compile the kernels here first (or load them from the cache): bringup then loads them
    # from the cache instead of both processes compiling at once on a fresh machine.
    from continuum_statics import load_robot
    from continuum_statics.core.warmup import warm_up

    warm_up(load_robot(robot_file), log=lambda line: print('demo: %s' % line, flush=True))
    print('demo: bringup (simulated cables, robot %s, namespace /%s) + tip_goal client'
          % (os.path.basename(robot_file), options.namespace), flush=True)
    process = subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics', 'bringup', '--robot', robot_file,
         '--driver', 'sim', '--namespace', options.namespace, '--ros-args', '--log-level',
         'warn'])
    try:
        rows = run_client(robot_file, options.namespace, options.goals, options.tolerance,
                          process=process)
    except RuntimeError as error:
        print('demo: %s' % error, file=sys.stderr)
        stop(process)
        return 1
    code = stop(process)
    reachable = [row for row in rows if row['reachable']]
    reached = [row for row in reachable if row['reached']]
    unreachable = [row for row in rows if not row['reachable']]
    errors = np.array([row['error'] for row in reached]) * 1e3
    times = np.array([row['time'] for row in reached])
    print('figures: %d/%d reachable goals reached (tolerance %.1f mm), error median %.3f mm '
          'max %.3f mm, time median %.2f s max %.2f s; unreachable goal answered empty in '
          '%.0f ms; bringup exit code %s' % (
              len(reached), len(reachable), options.tolerance * 1e3,
              np.median(errors) if errors.size else math.nan,
              errors.max() if errors.size else math.nan,
              np.median(times) if times.size else math.nan,
              times.max() if times.size else math.nan,
              unreachable[0]['time'] * 1e3 if unreachable else math.nan, code))
    if options.plot:
        write_plot(options.plot, robot_file, reached)
    ok = (len(reached) == len(reachable) and all(row['tip'] is None for row in unreachable)
          and code == 0)
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
