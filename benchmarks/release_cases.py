"""Timing cases that run against any release of the package (a script, not a module of it).

``bench_release`` runs this file in a fresh process with a release's source tree first on
``sys.path`` (``--tree``), once for the first release and once for this checkout, and reads the
JSON it prints. Only the public API both releases share is used: ``load_robot``, ``solve_ivp``,
``estimate_shape`` and ``solve_tip_goal`` (warm-started by ``warm_start`` where the release has
it, else by ``u0_guess``, the first release's way). Inputs are like a robot's: base bendings far
apart, lengths alternating between two poses 1 mm apart, goals spread over the workspace.
"""
import argparse
import inspect
import json
import sys
import time


def _times(call, items, warmup=20):
    """Per-call wall times (s) of ``call(item)`` over ``items`` after ``warmup`` calls."""
    for item in items[:warmup]:
        call(item)
    times = []
    for item in items:
        start = time.perf_counter()
        call(item)
        times.append(time.perf_counter() - start)
    return times


def _warm(robot, name):
    """Keyword giving a method of this release its warm start from a previous result."""
    if 'warm_start' in inspect.signature(getattr(robot, name)).parameters:
        return lambda previous: {'warm_start': previous}
    return lambda previous: {'u0_guess': previous.u0}


def cases(config, repeat, seed):
    """Return {case: [seconds per call]} of the single-section cases."""
    import numpy as np

    from continuum_statics import load_robot

    rng = np.random.default_rng(seed)
    out = {}
    for name in ('jones2009_nitinol_rod', 'tendon_robot'):
        robot = load_robot('%s/%s.yaml' % (config, name))
        bendings = rng.normal(0.0, 2.0, (repeat, 3))
        forces = rng.normal(0.0, 0.05, (repeat, 3))
        items = list(zip(bendings, forces))
        out['shape solve (IVP), %s' % name] = _times(lambda a: robot.solve_ivp(*a), items)
    robot = load_robot('%s/tendon_robot.yaml' % config)
    force = np.array([0.02, -0.01, -0.05])
    # two shapes whose cable lengths differ by 1 mm at most (both fit a shape exactly)
    first = robot.cable_lengths(robot.solve_ivp([3.0, -2.0, 0.0], force))
    second = robot.cable_lengths(robot.solve_ivp([3.5, -1.5, 0.0], force))
    pair = (first, first + (second - first) * 1e-3 / np.max(np.abs(second - first)))
    warm = _warm(robot, 'estimate_shape')
    last = [robot.estimate_shape(pair[0], force)]

    def estimate(k):
        last[0] = robot.estimate_shape(pair[k % 2], force, **warm(last[0]))

    out['estimate, lengths alternating 1 mm apart, tendon_robot'] = _times(
        estimate, list(range(repeat // 5)))
    goals = [robot.solve_ivp(u, force).tip_position
             for u in rng.normal(0.0, 3.0, (repeat // 10, 3)) * [1.0, 1.0, 0.0]]
    warm = _warm(robot, 'solve_tip_goal')
    last = [robot.solve_tip_goal(goals[0], force)]

    def goal(target):
        last[0] = robot.solve_tip_goal(target, force, **warm(last[0]))

    out['tip goal (warm, goals far apart), tendon_robot'] = _times(goal, goals, warmup=5)
    return out


def main(argv=None):
    """Print the cases' times as JSON (run with a release's tree first on the path)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--tree', required=True, help="the release's source tree")
    parser.add_argument('--repeat', type=int, default=2000)
    parser.add_argument('--seed', type=int, default=0)
    options = parser.parse_args(argv)
    sys.path.insert(0, options.tree)
    print(json.dumps(cases(options.tree + '/config', options.repeat, options.seed)))
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
