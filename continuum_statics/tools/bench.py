"""``python -m continuum_statics bench``: timing and accuracy figures of the numeric core.

Prints, for the 2- and 3-section robots: the IVP under cable tensions, a plain SciPy
``solve_ivp`` of the same equations (RK45 at the paper's tolerances and at 1e-8), a cold tension
solve, a warm estimate after a 1 mm cable change, a cold tip goal and 100 cold reachable tip
goals (median, p99, slowest). For the paper's rod and the tendon robot: median and p90 time of a
shape solve (IVP), for the 24-step paper rod also the bare kernel call, the Python overhead per
call (solve_ivp minus the kernel call) and the old classical-RK4 kernel (:mod:`rk4_reference`)
in the same run; the 6x6 Jacobian, a warm-started and a cold shape estimate and a cold tip-goal
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
from continuum_statics.config_paths import config_file
from continuum_statics.core.description.layout import MOMENT, POSITION, ROTATION


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


def tracked(robot, lengths, force):
    """Return the estimate a node tracking the robot holds at ``lengths`` (a warm start).

    A cold estimate hands on secant Jacobians that the next call replaces by the model's own;
    a node's every later call starts from an estimate like this one.
    """
    return robot.estimate_shape(lengths, force, warm_start=robot.estimate_shape(lengths, force))


def row(label, times, unit=1e-6):
    """Print one benchmark line (median and 90th percentile); return the median."""
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


def scipy_sections_tip(robot, state, fixed, tip_force, rtol=1e-3, atol=1e-6):
    """Tip of the kernel's equations (module docstring of ``core.rod.kernel``) with SciPy RK45.

    The same model in plain NumPy: state (r, R, M), strains from M and N = F + f (L - s) by
    Newton's method for the distributed model, point moments at the end disks, piecewise
    between disks (where the set of cables changes).
    """
    moments, tensions = robot.loads(state, fixed)
    c, d, f, length = robot.c, robot.d, robot.body_force, robot.length
    offsets, e3 = robot.cable_offsets, np.array([0.0, 0.0, 1.0])
    distributed = robot.cable_model == 'distributed'

    def strains(rot, moment, s, active):
        force = tip_force + f * (length - s)
        ml, nl = rot.T @ moment, rot.T @ force
        u, w = ml / c, nl / d
        if not distributed or not np.any(tensions[active]):
            return u, w
        t, arms = tensions[active], offsets[active]
        for _ in range(8):
            q = w + e3 + np.cross(u, arms)
            norm = np.linalg.norm(q, axis=1)
            tau = q / norm[:, None]
            cross = np.cross(arms, tau)
            jac = np.diag(c).astype(float)
            for tj, lj, aj, nj in zip(t, arms, np.cross(tau, arms), norm):
                jac += tj / nj * ((lj @ lj) * np.eye(3) - np.outer(lj, lj) - np.outer(aj, aj))
            u = u + np.linalg.solve(jac, ml - c * u - t @ cross)
            w = (nl - t @ tau) / d
        return u, w

    def rhs(s, y, active):
        rot, moment = y[3:12].reshape(3, 3), y[12:15]
        u, w = strains(rot, moment, s, active)
        hat = np.array([[0.0, -u[2], u[1]], [u[2], 0.0, -u[0]], [-u[1], u[0], 0.0]])
        dr = rot @ (w + e3)
        return np.concatenate([dr, (rot @ hat).ravel(), -np.cross(dr, tip_force + f * (
            length - s))])

    first = robot.integrate_state(state, tip_force, fixed)[0]  # r(0), R(0), M(0) as the kernel
    y = np.concatenate([first[POSITION], first[ROTATION], first[MOMENT]])  # SciPy's state
    ends = sorted({robot.s_grid[n] for n in robot.section_end_node if n >= 0} | {length})
    start = 0.0
    for end in ends:
        node = int(np.argmin(np.abs(robot.s_grid - end)))
        active = robot.cable_end_node >= node
        y = scipy_solve_ivp(rhs, (start, end), y, method='RK45', rtol=rtol, atol=atol,
                            args=(active,)).y[:, -1]
        if not distributed:
            for k in np.nonzero(robot.section_end_node == node)[0]:
                y[12:15] -= y[3:12].reshape(3, 3) @ moments[k]
        start = end
    return y[0:3]


def bench_sections(path, repeat):
    """Print the timing table of a multi-section robot file."""
    robot = load_robot(path)
    print('\n%s (%s): %d sections, %s model, %d RK4 steps, %d nodes, %d cables'
          % (robot.name, Path(path).name, len(robot.sections), robot.cable_model,
             robot.solver.steps, len(robot.s_grid), len(robot.cable_names)))
    rng = np.random.default_rng(1)
    force = np.array([0.0, 0.0, -0.2])
    tensions = rng.uniform(0.0, 6.0, len(robot.cable_names))
    shape = robot.solve_tensions(tensions, force)
    state, fixed = shape.state, shape.fixed_tensions
    ivp = row('shape solve (IVP, tensions)', timings(
        lambda: robot.integrate_state(state, force, fixed), repeat))
    baseline = timings(lambda: scipy_sections_tip(robot, state, fixed, force),
                       max(5, repeat // 200), warmup=1)
    scipy_median = row('SciPy solve_ivp RK45 (1e-3, 1e-6)', baseline)
    reference = robot.with_solver(steps=4096).solve_tensions(tensions, force).tip_position
    tight = scipy_sections_tip(robot, state, fixed, force, 1e-10, 1e-12)
    print('  speed-up over SciPy: %.0fx; tip vs converged (4096 steps): ours %.1e m, SciPy '
          '%.1e m (at 1e-10: %.1e m)' % (
              scipy_median / ivp, np.linalg.norm(shape.tip_position - reference),
              np.linalg.norm(scipy_sections_tip(robot, state, fixed, force) - reference),
              np.linalg.norm(tight - reference)))
    row('tension solve (cold)', timings(lambda: robot.solve_tensions(tensions, force),
                                        max(20, repeat // 20), warmup=3))
    # warm estimate: a nearby equilibrium of the estimator's own model (section moments, the
    # least tensions that carry them) whose largest cable change is 1 mm
    previous = tracked(robot, robot.cable_lengths(shape), force)
    lengths = robot.cable_lengths(previous.shape)
    direction = robot.passive_state()
    direction[3:] = rng.normal(size=robot.state_size - 3)
    for _ in range(4):
        moved = robot.make_shape(previous.state + direction, force, shape.states)
        nearby = robot.equilibrium_between(moved, moved, 0.0, force, warm_start=previous)
        direction *= 1e-3 / np.max(np.abs(nearby.cable_lengths - lengths))
    changed = nearby.cable_lengths
    est = robot.estimate_shape(changed, force, warm_start=previous)
    row('shape estimate (warm, 1 mm change)', timings(
        lambda: robot.estimate_shape(changed, force, warm_start=previous), repeat))
    print('  estimate: %d iterations, %d IVPs, residual %.1e m, max cable change %.2f mm'
          % (est.iterations, est.model_runs, est.residual,
             1e3 * np.max(np.abs(changed - lengths))))
    goal = robot.solve_tensions(rng.uniform(0.0, 6.0, len(tensions)), force).tip_position
    sol = robot.solve_tip_goal(goal, force)
    row('tip-goal solve (cold, %.0f mm from straight)' % (
        1e3 * np.linalg.norm(goal - robot.solve_bvp(force).tip_position)),
        timings(lambda: robot.solve_tip_goal(goal, force), max(10, repeat // 100),
                warmup=2))
    print('  tip goal: converged %s, error %.1e m, %d iterations'
          % (sol.converged, sol.error, sol.iterations))
    # cold tip goals: 100 random goals the robot reaches inside its length limits, one call each
    limits = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)
    times, failed = [], 0
    while len(times) < 100:
        reached = robot.solve_tensions(rng.uniform(0.0, 6.0, len(tensions)), force)
        lengths = robot.cable_lengths(reached)
        if np.any(lengths < limits[:, 0]) or np.any(lengths > limits[:, 1]):
            continue
        start = time.perf_counter()
        failed += not robot.solve_tip_goal(reached.tip_position, force).converged
        times.append(time.perf_counter() - start)
    times = np.array(times) * 1e3
    print('  100 cold tip goals (reachable): median %.2f ms, p99 %.2f ms, slowest %.2f ms; '
          'not converged %d' % (np.median(times), np.percentile(times, 99), times.max(), failed))


def _kernel_rows(robot, u0, force, ivp, repeat):
    """Print the bare kernel call, the Python overhead of solve_ivp and the old classical RK4."""
    from continuum_statics.tools import rk4_reference

    bare = row('kernel call (Model.integrate_passive)', timings(
        lambda: robot.model.integrate_passive(force, u0), repeat))
    print('  Python overhead per solve_ivp call: %.1f us' % (ivp - bare))
    old = row('old classical RK4 kernel (reference)', timings(
        lambda: rk4_reference.integrate_batch(robot.s_grid, robot.params, force[None],
                                              u0[None]), repeat))
    old_ivp = row('old classical RK4 shape (reference)', timings(
        lambda: rk4_reference.solve_ivp(robot, u0, force), repeat))
    print('  SE(3) RKMK4 / old classical RK4: kernel %.2fx, shape solve %.2fx'
          % (bare / old, ivp / old_ivp))


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
    ivp = row('shape solve (IVP)', timings(lambda: robot.solve_ivp(u0, force), repeat))
    if len(robot.s_grid) == robot.solver.steps + 1:  # no guide breaks: the old kernel's grid
        _kernel_rows(robot, u0, force, ivp, repeat)
    row('6x6 Jacobian (7 IVPs, one call)', timings(lambda: robot.jacobian(u0, force), repeat))
    baseline = timings(lambda: scipy_tip(robot, u0, force), max(20, repeat // 50), warmup=2)
    scipy_median = row('SciPy solve_ivp RK45 (1e-3, 1e-6)', baseline)
    reference = reference_robot.solve_ivp(u0, force).tip_position
    ours = robot.solve_ivp(u0, force).tip_position
    theirs = scipy_tip(robot, u0, force)
    print('  speed-up over SciPy: %.0fx;  tip error vs converged (4096 steps): ours %.2e m, '
          'SciPy %.2e m' % (scipy_median / ivp, np.linalg.norm(ours - reference),
                            np.linalg.norm(theirs - reference)))
    if robot.cable_names:
        shape = robot.solve_ivp(u0, force)
        lengths = robot.cable_lengths(shape)
        previous = tracked(robot, lengths, force)
        # a consistent 1 mm change of the most-changed cable: bend a little further
        bending_jac = robot.cable_jacobian(u0, force)[:, :2]
        du = np.zeros(3)
        du[:2] = np.linalg.lstsq(bending_jac, np.eye(len(lengths))[0], rcond=None)[0]
        du *= 1e-3 / np.max(np.abs(robot.cable_jacobian(u0, force) @ du))
        changed = robot.cable_lengths(robot.solve_ivp(u0 + du, force))
        est = robot.estimate_shape(changed, force, warm_start=previous)
        row('shape estimate (warm, 1 mm change)', timings(
            lambda: robot.estimate_shape(changed, force, warm_start=previous), repeat))
        print('  estimate: %d iterations, %d IVPs, residual %.1e m, max cable change %.2f mm'
              % (est.iterations, est.model_runs, est.residual,
                 1e3 * np.max(np.abs(changed - lengths))))
        cold = robot.estimate_shape(changed, force)
        row('shape estimate (cold)', timings(lambda: robot.estimate_shape(changed, force),
                                             max(100, repeat // 4)))
        print('  cold estimate: %d iterations, %d IVPs, residual %.1e m'
              % (cold.iterations, cold.model_runs, cold.residual))
        # a reachable goal about 5 cm from the current tip
        goal = robot.solve_ivp(u0 + [0.0, 1.3, 0.0], force).tip_position
        start_tip = shape.tip_position
        sol = robot.solve_tip_goal(goal, force, warm_start=previous)
        row('tip-goal solve (cold, goal %.0f mm away)' % (1e3 * np.linalg.norm(goal - start_tip)),
            timings(lambda: robot.solve_tip_goal(goal, force, warm_start=previous),
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


#: Not an example file (issue 22's case): one section, three cables at 120 degrees, ten guide
#: disks (nodes off the 24-step grid) and a 20 g tip load: kernels must be as fast on it.
THREE_CABLE_ROD = {
    'name': 'rod_3c_10_guides',
    'rod': {'length': 0.30, 'diameter': 2.0e-3, 'youngs_modulus': 58.0e9, 'poisson_ratio': 0.33,
            'density': 6450.0},
    'base': {'frame_id': 'base_link', 'position': [0, 0, 0], 'orientation': [0, 0, 0, 1]},
    'gravity': [0.0, 0.0, -9.81],
    'cables': [{'name': 'c%d' % k, 'offset': [0.01 * np.cos(a), 0.01 * np.sin(a), 0.0],
                'length_limits': [0.27, 0.33]}
               for k, a in enumerate(np.radians([0.0, 120.0, 240.0]))],
    'guides': [0.03 * (k + 1) for k in range(10)],
    'solver': {'steps': 24},
}


def bench_three_cable_rod(repeat):
    """Print shape and cold-estimate times of :data:`THREE_CABLE_ROD` (not an example file)."""
    from continuum_statics.core.description.robot_file import parse_robot_description
    from continuum_statics.core.robot import Robot

    robot = Robot(parse_robot_description(THREE_CABLE_ROD, 'bench'))
    force = np.array([0.0, 0.0, -0.02 * 9.81])
    print('\n%s (in bench.py): 1 section, 24 steps + guide breaks = %d nodes, 3 cables, 20 g tip'
          % (robot.name, len(robot.s_grid)))
    u0 = np.array([2.0, -1.0, 0.0])
    row('shape solve (IVP)', timings(lambda: robot.solve_ivp(u0, force), repeat))
    rng = np.random.default_rng(3)
    rows = [robot.cable_lengths(robot.solve_ivp(rng.uniform(-4.0, 4.0, 3) * [1, 1, 0], force))
            for _ in range(50)]
    times = []
    for lengths in rows:  # far apart: every one cold
        start = time.perf_counter()
        robot.estimate_shape(lengths, force)
        times.append(time.perf_counter() - start)
    times = np.array(times[1:]) * 1e6  # (the first integrates the passive rod's Jacobians)
    print('  shape estimate (cold, 49 far-apart shapes) median %.1f us, p99 %.1f us, max %.1f us'
          % (np.median(times), np.percentile(times, 99), times.max()))
    baseline = timings(lambda: scipy_tip(robot, u0, force), max(20, repeat // 50), warmup=2)
    row('SciPy solve_ivp RK45 (1e-3, 1e-6)', baseline)


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
    script = STARTUP % str(config_file('tendon_robot.yaml'))
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
        bench_robot(config_file(name), args.repeat)
    bench_three_cable_rod(args.repeat)
    for name in ('two_section_robot.yaml', 'three_section_robot.yaml'):
        bench_sections(config_file(name), args.repeat)
    if not args.no_startup:
        bench_startup()
    return 0
