"""``python -m benchmarks.bench_release``: this checkout beside the first release.

One run: the single-section cases of :mod:`release_cases` in fresh processes, alternately on the
first release (08c3579, its source taken with ``git archive`` into ``build/``, its kernels
cached there) and on this checkout (A B A B, the median of each pair's medians kept), then a
plain SciPy ``solve_ivp`` of the same paper rod; then what the first release cannot run: warm
two-section estimates after 0.5 mm, the slowest of 100 cold two-section tip goals, and the plain
API (``estimate_shape(lengths, warm_start=last)``, no ``Tracking``) on noisy lengths. Median,
p99 and max; each row beside its bar (issue 34). Figures, not assertions.
"""
import argparse
import dataclasses
import json
import os
from pathlib import Path
import subprocess
import sys
import time

import numpy as np

FIRST_RELEASE = '08c3579'
REPO = Path(__file__).resolve().parents[1]
CASES = Path(__file__).with_name('release_cases.py')
#: bar of each single-section case: (ratio to the first release, or None; absolute, s)
BARS = {'shape solve': (1.25, None), 'estimate': (None, 150e-6), 'tip goal': (None, 0.3e-3)}


def _stats(times):
    times = np.asarray(times) * 1e6
    return np.median(times), np.percentile(times, 99), np.max(times)


def release_tree(rev):
    """Return the source tree of ``rev`` under build/ (extracted once with git archive)."""
    tree = REPO / 'build' / ('release-%s' % rev)
    if not (tree / 'continuum_statics').is_dir():
        tree.mkdir(parents=True, exist_ok=True)
        archive = subprocess.run(['git', '-C', str(REPO), 'archive', rev], check=True,
                                 capture_output=True).stdout
        subprocess.run(['tar', '-x', '-C', str(tree)], input=archive, check=True)
    return tree


def run_cases(tree, repeat):
    """{case: seconds per call} of release_cases.py on a tree, in a fresh process."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tree / '.numba_cache')) if tree != REPO \
        else dict(os.environ)
    out = subprocess.run([sys.executable, str(CASES), '--tree', str(tree), '--repeat',
                          str(repeat)], check=True, capture_output=True, text=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _bar(case, median_then, median_now):
    for key, (ratio, absolute) in BARS.items():
        if case.startswith(key):
            ok = (median_now <= ratio * median_then) if ratio else (median_now <= absolute)
            return ('<= %.2fx' % ratio if ratio else '<= %.0f us' % (absolute * 1e6)), ok
    return '', True


def compare(repeat, rounds):
    """Print the single-section table: first release, now, ratio, bar."""
    first = release_tree(FIRST_RELEASE)
    runs = {'first': [], 'now': []}
    for _ in range(rounds):  # A B A B: a busy machine slows both alike
        runs['first'].append(run_cases(first, repeat))
        runs['now'].append(run_cases(REPO, repeat))
    print('single section, %d rounds A B A B (medians of each round, then their median)'
          % rounds)
    print('  %-58s %27s %27s %7s  %s' % ('', 'first release %s' % FIRST_RELEASE,
                                         'this checkout', 'ratio', 'bar'))
    for case in runs['now'][0]:
        then = np.median([_stats(r[case]) for r in runs['first']], axis=0)
        now = np.median([_stats(r[case]) for r in runs['now']], axis=0)
        bar, ok = _bar(case, then[0] * 1e-6, now[0] * 1e-6)
        print('  %-58s %7.1f /%7.1f /%8.1f  %7.1f /%7.1f /%8.1f  %6.2fx  %s %s'
              % (case, *then, *now, now[0] / then[0], bar, 'met' if ok else 'NOT MET'))
    print('  (median / p99 / max, us)')


def scipy_row(repeat):
    """Print a plain SciPy solve_ivp of the paper rod (the baseline of the same run)."""
    from continuum_statics import load_robot
    from continuum_statics.config_paths import config_file
    from continuum_statics.tools.bench import scipy_tip

    robot = load_robot(config_file('jones2009_nitinol_rod.yaml'))
    rng = np.random.default_rng(0)
    times = []
    for u0, force in zip(rng.normal(0.0, 2.0, (repeat, 3)), rng.normal(0.0, 0.05, (repeat, 3))):
        start = time.perf_counter()
        scipy_tip(robot, u0, force)
        times.append(time.perf_counter() - start)
    print('  %-58s median %7.1f  p99 %7.1f  max %8.1f us' % (
        'SciPy solve_ivp RK45 (1e-3, 1e-6), jones2009_nitinol_rod', *_stats(times)))


def multisection(repeat):
    """Print the two-section rows: warm estimate after 0.5 mm, slowest cold tip goal."""
    from continuum_statics import load_robot
    from continuum_statics.config_paths import config_file
    from continuum_statics.core.robot import Robot
    from continuum_statics.core.warmup import warm_up

    base = load_robot(config_file('two_section_robot.yaml'))
    robot = Robot(dataclasses.replace(base.description, cable_model='distributed'))
    warm_up(robot)
    n = len(robot.cable_names)
    # two equilibria of the robot whose cable lengths differ by 0.5 mm at most
    start = robot.solve_tip_goal(robot.solve_ivp([2.0, -1.0, 0.0]).tip_position)
    goal = robot.solve_tip_goal(robot.solve_ivp([-1.0, 2.5, 0.0]).tip_position)
    fraction = 5e-4 / np.max(np.abs(goal.cable_lengths - start.cable_lengths))
    pair = start.cable_lengths, robot.equilibrium_between(start, goal, fraction).cable_lengths
    last = robot.estimate_shape(pair[0])
    times = []
    for k in range(repeat // 5):
        start = time.perf_counter()
        last = robot.estimate_shape(pair[k % 2], warm_start=last)
        times.append(time.perf_counter() - start)
    print('  %-58s median %7.1f  p99 %7.1f  max %8.1f us   bar median <= 200 us' % (
        'two sections (distributed): warm estimate, 0.5 mm apart', *_stats(times[20:])))
    rng = np.random.default_rng(3)
    goals, times = [], []
    while len(goals) < 100:
        tensions = rng.uniform(0.0, 1.0, n) * rng.uniform(0.2, 2.0)
        goals.append(robot.solve_tensions(tensions).tip_position)
    for goal in goals:
        start = time.perf_counter()
        robot.solve_tip_goal(goal)
        times.append(time.perf_counter() - start)
    print('  %-58s median %7.1f  p99 %7.1f  max %8.1f ms   bar max <= 50 ms' % (
        'two sections (distributed): 100 cold tip goals',
        *(np.array(_stats(times)) / 1e3)))


def plain_api(samples):
    """Print the plain API on noisy lengths: estimate_shape(lengths, warm_start=last)."""
    from benchmarks.shared import motion
    from continuum_statics import load_robot
    from continuum_statics.config_paths import config_file
    from continuum_statics.core.robot import Robot
    from continuum_statics.core.warmup import warm_up

    print('plain API on noisy lengths (warm_start=last, nothing else; bar: median <= 150, '
          'p99 <= 500, max <= 1000 us)')
    for name in ('two_section_robot', 'three_section_robot'):
        base = load_robot(config_file(name + '.yaml'))
        for model in ('point_moment', 'distributed'):
            robot = Robot(dataclasses.replace(base.description, cable_model=model))
            warm_up(robot)
            exact = motion(robot, samples)
            rng = np.random.default_rng(1)
            for sigma in (1e-6, 10e-6, 50e-6):
                measured = exact + rng.normal(0.0, sigma, exact.shape)
                last, times, runs = None, [], []
                for k, lengths in enumerate(measured):
                    start = time.perf_counter()
                    last = robot.estimate_shape(lengths, warm_start=last)
                    if k >= 20:
                        times.append(time.perf_counter() - start)
                        runs.append(last.model_runs)
                median, p99, most = _stats(times)
                ok = median <= 150 and p99 <= 500 and most <= 1000
                print('  %-22s %-13s sigma %2.0f um  median %5.0f  p99 %5.0f  max %5.0f us  '
                      'IVPs max %3d  %s' % (name, model, sigma * 1e6, median, p99, most,
                                            max(runs), 'met' if ok else 'NOT MET'), flush=True)


def main(argv=None):
    """Run the comparison; returns 0."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_release',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=2000, help='calls per IVP case')
    parser.add_argument('--rounds', type=int, default=3, help='A B rounds against the release')
    parser.add_argument('--samples', type=int, default=400, help='noisy lengths per case')
    options = parser.parse_args(argv)
    compare(options.repeat, options.rounds)
    scipy_row(max(20, options.repeat // 50))
    multisection(options.repeat)
    plain_api(options.samples)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
