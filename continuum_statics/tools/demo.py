"""``python -m continuum_statics demo`` (``make demo``): bringup plus a tip-goal client.

Starts ``bringup`` (statics, tip_controller, simulated cable_driver; by default the tendon robot
with real tendons, which the simulated cables simulate) as a subprocess; this process
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

import numpy as np

from continuum_statics.config_paths import share_dir
from continuum_statics.tools.goal_client import GOAL_BENDINGS, run_client
from continuum_statics.tools.processes import ros_environment, stop

#: The demo's robot: config/tendon_robot.yaml with real tendons, which the simulated driver
#: simulates (slack, stretch, pretension, guide friction, tension limits).
DEMO_ROBOT = 'tendon_robot_real_tendons.yaml'


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
    parser.add_argument('--robot', default=str(share_dir() / 'config' / DEMO_ROBOT),
                        help='robot description YAML (default: the tendon robot with real '
                             'tendons: stretch, pretension, friction, tension limits)')
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
