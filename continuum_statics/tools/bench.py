"""``python -m continuum_statics bench``: timing and accuracy figures of the numeric core.

Prints, for the paper's rod and the tendon robot: median and p90 time of a shape solve (IVP),
the 6x6 Jacobian, a warm-started shape estimate after a 1 mm cable change and a cold tip-goal
solve 5 cm away; the tip error against a converged reference; a plain SciPy ``solve_ivp``
baseline (RK45, rtol 1e-3, atol 1e-6, the paper's setting) on the same problem in the same run;
and the import + first-call time of fresh processes with and without the numba cache.
Figures, not assertions: nothing here fails on a slow machine.
"""
import argparse
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.integrate import solve_ivp as scipy_solve_ivp

from continuum_statics import load_robot

CONFIG = Path(__file__).resolve().parents[2] / 'config'


def _config(name):
    """Robot file from the repository, or from the installed share directory."""
    if (CONFIG / name).exists():
        return CONFIG / name
    from ament_index_python.packages import get_package_share_directory
    return Path(get_package_share_directory('continuum_statics')) / 'config' / name


def timings(call, repeat, warmup=20):
    """Per-call wall times (s) of ``call()``, after ``warmup`` calls."""
    for _ in range(warmup):
        call()
    times = np.empty(repeat)
    for k in range(repeat):
        start = time.perf_counter()
        call()
        times[k] = time.perf_counter() - start
    return times


def _row(label, times, unit=1e-6):
    median, p90 = np.median(times) / unit, np.percentile(times, 90) / unit
    print('  %-34s median %9.1f us   p90 %9.1f us' % (label, median, p90))
    return median


def scipy_rhs(robot, tip_force):
    """Paper eqs. 1, 2, 8, 9 as a plain Python/NumPy right-hand side for SciPy (the baseline)."""
    c, d, f = robot.c, robot.d, robot.body_force
    e3 = np.array([0.0, 0.0, 1.0])

    def rhs(_, y):
        rot = y[3:12].reshape(3, 3)
        v, u = y[12:15], y[15:18]
        n = d * (v - e3)
        dv = (-rot.T @ f - np.cross(u, n)) / d
        du = (-np.cross(u, c * u) - np.cross(v, n)) / c
        hat = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
        return np.concatenate([rot @ v, (rot @ hat).ravel(), dv, du])

    def initial(u0):
        n0 = tip_force + f * robot.length
        v0 = robot.base_rotation.T @ n0 / d + e3  # eq. 10
        return np.concatenate([robot.base_position, robot.base_rotation.ravel(), v0, u0])

    return rhs, initial


def scipy_tip(robot, u0, tip_force):
    """Tip position from SciPy RK45 at the paper's tolerances."""
    rhs, initial = scipy_rhs(robot, np.asarray(tip_force, dtype=float))
    sol = scipy_solve_ivp(rhs, (0.0, robot.length), initial(u0), method='RK45',
                          rtol=1e-3, atol=1e-6)
    return sol.y[0:3, -1]


def bench_robot(path, repeat):
    """Print the timing table of one robot file."""
    robot = load_robot(path)
    reference_robot = robot.with_solver(steps=4096)
    print('\n%s (%s): %d RK4 steps, %d nodes, %d cables'
          % (robot.name, Path(path).name, robot.solver.steps, len(robot.s_grid),
             len(robot.cable_names)))
    if robot.cable_names:
        force = np.array([0.0, 0.0, -0.05 * 9.81])
        u0 = np.array([3.0, -1.5, 0.0])
    else:
        force = np.array([0.0, 0.0, -0.045 * 9.81])
        u0 = robot.solve_bvp(tip_force=force).u0
    ivp = _row('shape solve (IVP)', timings(lambda: robot.solve_ivp(u0, force), repeat))
    _row('6x6 Jacobian (7 IVPs, one call)', timings(lambda: robot.jacobian(u0, force), repeat))
    baseline = timings(lambda: scipy_tip(robot, u0, force), max(20, repeat // 50), warmup=2)
    scipy_median = _row('SciPy solve_ivp RK45 (1e-3, 1e-6)', baseline)
    reference = reference_robot.solve_ivp(u0, force).tip_position
    ours = robot.solve_ivp(u0, force).tip_position
    theirs = scipy_tip(robot, u0, force)
    print('  speed-up over SciPy: %.0fx;  tip error vs converged (4096 steps): ours %.2e m, '
          'SciPy %.2e m' % (scipy_median / ivp, np.linalg.norm(ours - reference),
                            np.linalg.norm(theirs - reference)))
    if robot.cable_names:
        shape = robot.solve_ivp(u0, force)
        lengths = robot.cable_lengths(shape)
        previous = robot.estimate_shape(lengths, force)
        # a consistent 1 mm change of the most-changed cable: bend a little further
        bending_jac = robot.cable_jacobian(u0, force)[:, :2]
        du = np.zeros(3)
        du[:2] = np.linalg.lstsq(bending_jac, np.eye(len(lengths))[0], rcond=None)[0]
        du *= 1e-3 / np.max(np.abs(robot.cable_jacobian(u0, force) @ du))
        changed = robot.cable_lengths(robot.solve_ivp(u0 + du, force))
        est = robot.estimate_shape(changed, force, u0_guess=previous.u0)
        _row('shape estimate (warm, 1 mm change)', timings(
            lambda: robot.estimate_shape(changed, force, u0_guess=previous.u0), repeat))
        print('  estimate: %d iterations, residual %.1e m, max cable change %.2f mm'
              % (est.iterations, est.residual, 1e3 * np.max(np.abs(changed - lengths))))
        # a reachable goal about 5 cm from the current tip
        goal = robot.solve_ivp(u0 + [0.0, 1.3, 0.0], force).tip_position
        start_tip = shape.tip_position
        sol = robot.solve_tip_goal(goal, force, u0_guess=u0)
        _row('tip-goal solve (cold, goal %.0f mm away)' % (1e3 * np.linalg.norm(goal - start_tip)),
             timings(lambda: robot.solve_tip_goal(goal, force, u0_guess=u0),
                     max(20, repeat // 20), warmup=3), unit=1e-6)
        print('  tip goal: converged %s, error %.1e m, %d iterations'
              % (sol.converged, sol.error, sol.iterations))
    else:
        errors = []
        for mass in np.linspace(0.0, 0.045, 10):
            tip_force = (0.0, 0.0, -9.81 * mass)
            errors.append(np.linalg.norm(robot.solve_bvp(tip_force=tip_force).tip_position
                                         - reference_robot.solve_bvp(tip_force=tip_force)
                                         .tip_position))
        print('  BVP tip error vs converged, tip masses 0-45 g: max %.2e m' % max(errors))


STARTUP = """
import time
t0 = time.perf_counter()
from continuum_statics import load_robot
robot = load_robot(%r)
t1 = time.perf_counter()
robot.solve_ivp([1.0, 0.5, 0.0])
robot.estimate_shape(robot.straight_cable_lengths)
robot.jacobian([1.0, 0.5, 0.0])
t2 = time.perf_counter()
print('%%.3f %%.3f' %% (t1 - t0, t2 - t1))
"""


def bench_startup():
    """Import and first-call time of a fresh process, with and without the numba cache."""
    script = STARTUP % str(_config('tendon_robot.yaml'))
    print('\nfresh process: import + load_robot, then first IVP + estimate + Jacobian')
    with tempfile.TemporaryDirectory() as empty_cache:
        for label, env in (('no numba cache (compiles)', {'NUMBA_CACHE_DIR': empty_cache}),
                           ('numba cache, second process', {'NUMBA_CACHE_DIR': empty_cache}),
                           ('default cache', {})):
            out = subprocess.run([sys.executable, '-c', script], capture_output=True, text=True,
                                 env={**os.environ, **env}, check=True).stdout.split()
            print('  %-30s import %6.2f s   first calls %6.2f s' % (label, *map(float, out)))


def main(argv=None):
    """Run the core benchmark and print its figures."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics bench')
    parser.add_argument('--repeat', type=int, default=2000, help='timed calls per figure')
    parser.add_argument('--no-startup', action='store_true', help='skip the process-start runs')
    args = parser.parse_args(argv)
    print('continuum_statics core benchmark, one core, %d calls per figure' % args.repeat)
    for name in ('jones2009_nitinol_rod.yaml', 'tendon_robot.yaml'):
        bench_robot(_config(name), args.repeat)
    if not args.no_startup:
        bench_startup()
    return 0
