"""Obstacles: contact solves beside today's solve, and clearance goals per robot.

``python -m benchmarks.bench_obstacles [--goals N]``. Contact: the shape under tensions that
press the rod on a ball, warm-started call after call on tensions 0.1 % apart (a control
loop), beside the same call without obstacles; and with four obstacles none of which is
touched. Clearance goals: N goals reachable with clearance (the tips of random tension sets
whose whole body clears a shelf, a post and a wall by the clearance), sent in sequence from
the straight rod as a controller sends them; each answer and the way to it is checked against
the clearance independently of the solver (node gaps at 64 steps of each leg).
"""
import argparse
import time

import numpy as np

from benchmarks.shared import CLEARANCE, scene
from continuum_statics import load_robot
from continuum_statics.core.description.obstacles import parse_obstacles


def _stats(times):
    times = np.asarray(times) * 1e3
    return 'median %.3f ms, p99 %.3f ms, max %.3f ms' % (
        np.median(times), np.percentile(times, 99), times.max())


def _gap(robot, obstacles, shape):
    return min(float(np.min(o.distance(shape.positions)[0])) for o in obstacles) - (
        robot.body_radius)


def contact_timing(robot_file, calls=300):
    """Print warm-started solve_tensions times: free, one contact, four obstacles untouched."""
    robot = load_robot(robot_file)
    ball = parse_obstacles([{'name': 'ball', 'sphere': {'radius': 0.02},
                             'position': [0.04, 0.0, 0.7 * robot.length]}])
    far = parse_obstacles([{**entry, 'position': [0.3, 0.3, 0.5]} if 'position' in entry else
                           {**entry, 'plane': {'normal': [0, 0, 1], 'offset': -0.5}}
                           for entry in scene(robot.length)]
                          + [{'name': 'ball', 'sphere': {'radius': 0.02},
                              'position': [-0.3, 0.0, 0.2]}])
    tensions = np.zeros(len(robot.cable_names))
    tensions[0] = 3.0
    for label, obstacles in (('no obstacles (today)', ()), ('4 obstacles, none touched', far),
                             ('1 active contact', ball)):
        previous, times, contacts = robot.solve_tensions(tensions, obstacles=obstacles), [], 0
        for i in range(calls):
            load = tensions * (1.0 + 1e-3 * np.sin(i))
            start = time.perf_counter()
            previous = robot.solve_tensions(load, obstacles=obstacles, warm_start=previous)
            times.append(time.perf_counter() - start)
            contacts += len(previous.contacts)
        print('  %-28s %s  (contacts per call %.2f)' % (label, _stats(times), contacts / calls))


def clearance_goals(robot_file, count, seed=2):
    """Print the clearance-goal table of one robot."""
    robot = load_robot(robot_file)
    entries = scene(robot.length)
    obstacles = parse_obstacles(entries)
    rng = np.random.default_rng(seed)
    limits = robot.cable_length_limits
    goals = []
    while len(goals) < count:
        tensions = rng.uniform(0, 20, len(robot.cable_names)) * (
            rng.uniform(size=len(robot.cable_names)) < 0.4)
        shape = robot.solve_tensions(tensions, obstacles=())
        lengths = robot.cable_lengths(shape)
        if np.all(lengths >= limits[:, 0]) and np.all(lengths <= limits[:, 1]) and _gap(
                robot, obstacles, shape) >= CLEARANCE:
            goals.append(shape.tip_position.copy())
    previous = None
    reached, refused, plain_hits, around, times, seen = 0, {}, 0, 0, [], []
    for number, goal in enumerate(goals):
        if number % 10 == 0:
            print('    goal %d of %d' % (number, count), flush=True)
        # the plain solver's answer and the way a controller would ramp to it (64 steps)
        plain = robot.solve_tip_goal(goal, obstacles=(), warm_start=previous)
        begin = previous.shape if previous is not None else robot.solve_tensions(
            np.zeros(len(robot.cable_names)), obstacles=())
        plain_hits += min(_gap(robot, obstacles, robot.equilibrium_between(
            begin, plain.shape, fraction).shape) for fraction in np.linspace(0, 1, 65)[1:]) < (
                CLEARANCE)
        start = time.perf_counter()
        solution = robot.solve_tip_goal(goal, obstacles=obstacles, clearance=CLEARANCE,
                                        warm_start=previous)
        times.append(time.perf_counter() - start)
        if not solution.converged:
            name = solution.message.split("obstacle '")[-1].split("'")[0]
            refused[name] = refused.get(name, 0) + 1
            continue
        reached += 1
        around += bool(solution.waypoints)
        begin = previous.shape if previous is not None else robot.solve_tensions(
            np.zeros(len(robot.cable_names)), obstacles=())
        for leg in (*solution.waypoints, solution):
            for fraction in np.linspace(0.0, 1.0, 65)[1:]:
                step = robot.equilibrium_between(begin, leg.shape, fraction)
                seen.append(_gap(robot, obstacles, step.shape))
            begin = leg.shape
        previous = solution
    print('  %s: %d goals; reached %d (%d around an obstacle, with waypoints); refused %s; '
          "the plain solver's answer or its way would pass within the clearance on %d"
          % (robot.name, count, reached, around, refused or 'none', plain_hits))
    print('    closest approach on every way (64 steps a leg): %.2f mm (clearance %.1f mm); '
          'time per goal %s' % (min(seen) * 1e3, CLEARANCE * 1e3, _stats(times)))


def main(argv=None):
    """Print both tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--goals', type=int, default=100)
    parser.add_argument('--robots', nargs='+', default=['config/two_section_robot.yaml',
                                                        'config/three_section_robot.yaml'])
    args = parser.parse_args(argv)
    print('Contact solves, warm-started, tensions 0.1 % apart:')
    for robot_file in ('config/two_section_robot.yaml', 'config/three_section_robot.yaml'):
        print(' ', robot_file)
        contact_timing(robot_file)
    print('Clearance goals (shelf, post, wall; clearance %.1f mm):' % (CLEARANCE * 1e3))
    for robot_file in args.robots:
        clearance_goals(robot_file, args.goals)


if __name__ == '__main__':
    main()
