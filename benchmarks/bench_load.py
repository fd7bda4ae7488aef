"""``python -m benchmarks.bench_load``: figures of the tip-load estimation.

For every example robot and both cable models: ``estimate_tip_wrench`` cold (from nothing) and
warm (a tracking sequence: the load drifts, every measurement is noisy, each call warm-started by
the previous estimate), median / p99 / max, beside a plain SciPy baseline of the same
measurements in the same run (``scipy.optimize.least_squares`` on the tension or tip residual
of the public solvers, SciPy's own finite differences, no input-noise weighting). Then, on the
3-section robot with real tendons, the force error against the noise of lengths (10-50 um) and
tensions (1-5 %) as a table and, with ``--plot FILE.png``, a figure. Figures, not assertions.
"""
import argparse
import dataclasses
from pathlib import Path
import time

import numpy as np
from scipy.optimize import least_squares

from continuum_statics import ConvergenceError, load_robot
from continuum_statics.core.description.tendons import full_circle_tension
from continuum_statics.core.robot import Robot

#: The example robot files (a source checkout).
CONFIG = Path(__file__).resolve().parents[1] / 'config'
#: Measurement noise of the timing runs: length (m), tension (N), tip position (m).
SIGMA_LENGTH, SIGMA_TENSION, SIGMA_TIP = 20e-6, 0.05, 0.5e-3


def example_robots():
    """(file name, robot) of every example robot file in config/."""
    for path in sorted(CONFIG.glob('*.yaml')):
        if not path.name.endswith('params.yaml'):
            yield path.name, load_robot(path)


def with_model(robot, model):
    """Return the robot with another cable model."""
    return Robot(dataclasses.replace(robot.description, cable_model=model))


def applied(robot, rng, force, sigma_length=SIGMA_LENGTH, sigma_tension=SIGMA_TENSION,
            tensions=None):
    """Measurements (keyword arguments of estimate_tip_wrench) of a robot under ``force``.

    ``sigma_tension`` in N, or a string 'P%'. Cables taut at random tensions (or ``tensions``).
    """
    n = len(robot.cable_names)
    if n == 0:
        shape = robot.solve_bvp(force)
        tip = shape.tip_position + shape.tip_rotation @ robot.tip_marker
        return {'tip_position': tip + rng.normal(0.0, SIGMA_TIP, 3)}, tensions
    if tensions is None:
        low = robot.tendons.tension_limits[:, 0] + robot.tendons.pretension + 0.15
        tensions = low + rng.uniform(0.0, 0.05 * full_circle_tension(robot), n)
    shape = robot.solve_tensions(tensions, force)
    paths = robot.cable_lengths(shape)
    if robot.tendons.is_ideal:
        lengths, measured = paths, tensions
    else:
        free = paths / (1.0 + tensions * robot.tendons.compliance)
        lengths = robot.tendons.lengths_for(free, robot.straight_cable_lengths)
        measured = robot.solve_lengths(lengths, force).tensions
    if isinstance(sigma_tension, str):
        noise = rng.normal(0.0, 1.0, n) * float(sigma_tension[:-1]) / 100.0 * measured
    else:
        noise = rng.normal(0.0, sigma_tension, n)
    return {'lengths': lengths + rng.normal(0.0, sigma_length, n),
            'tensions': np.maximum(measured + noise, 0.0)}, tensions


def random_force(robot, rng):
    """Return a load of 0.1-2 E I / L^2, random direction (0.05-1 N on the examples)."""
    direction = rng.normal(size=3)
    scale = float(robot.c[0]) / robot.length ** 2
    return direction / np.linalg.norm(direction) * rng.uniform(0.1, 2.0) * scale


def scipy_baseline(robot, measurements):
    """Return the force of a plain least_squares over the public solvers."""
    lengths, tensions = measurements.get('lengths'), measurements.get('tensions')
    tip = measurements.get('tip_position')

    def residual(force):
        try:
            return model(force)
        except (ValueError, ConvergenceError):  # no equilibrium there: a wall for SciPy
            return np.full(size, 1e6)

    def model(force):
        if lengths is not None and not robot.tendons.is_ideal:
            solution = robot.solve_lengths(lengths, force)
            parts = [(solution.tensions - tensions) / SIGMA_TENSION]
            shape = solution.shape
        elif tensions is not None:
            shape = robot.solve_tensions(tensions, force)
            parts = [(robot.cable_lengths(shape) - lengths) / SIGMA_LENGTH]
        else:
            shape = robot.solve_bvp(force)
            parts = []
        if tip is not None:
            parts.append((shape.tip_position - tip) / SIGMA_TIP)
        return np.concatenate(parts)

    size = len(model(np.zeros(3)))
    return least_squares(residual, np.zeros(3), method='lm').x


def _stats(seconds):
    ms = np.asarray(seconds) * 1e3
    return '%7.2f %7.2f %7.2f' % (np.median(ms), np.percentile(ms, 99), np.max(ms))


def timing(cold_cases, warm_calls, seed=0):
    """Print cold and warm estimate times per example robot and model, with SciPy's."""
    print('tip-load estimation time (ms): median p99 max; noise %g um, %g N, tip %g mm'
          % (SIGMA_LENGTH * 1e6, SIGMA_TENSION, SIGMA_TIP * 1e3))
    print('%-38s %-12s %-23s %-23s %-23s' % ('robot', 'model', 'cold', 'warm',
                                             'SciPy least_squares cold'))
    for name, base in example_robots():
        for model in ('point_moment', 'distributed'):
            robot = with_model(base, model)
            rng = np.random.default_rng(seed)
            cold, baseline = [], []
            for _ in range(cold_cases):
                measurements, _ = applied(robot, rng, random_force(robot, rng))
                start = time.perf_counter()
                robot.estimate_tip_wrench(**measurements)
                cold.append(time.perf_counter() - start)
                start = time.perf_counter()
                scipy_baseline(robot, measurements)
                baseline.append(time.perf_counter() - start)
            warm, estimate = [], None
            force, tensions = random_force(robot, rng), None
            drift = random_force(robot, rng) * 0.002
            for _ in range(warm_calls):
                force = force + drift
                measurements, tensions = applied(robot, rng, force, tensions=tensions)
                start = time.perf_counter()
                estimate = robot.estimate_tip_wrench(warm_start=estimate, **measurements)
                warm.append(time.perf_counter() - start)
            print('%-38s %-12s %s %s %s' % (name, model, _stats(cold), _stats(warm[5:]),
                                            _stats(baseline)), flush=True)


def accuracy(cases, plot=None, seed=1):
    """Print the force error against the noise levels on the 3-section real-tendon robot."""
    robot = load_robot(CONFIG / 'three_section_robot_real_tendons.yaml')
    lengths_um, percents = (10, 20, 50), (1, 2, 5)
    print('\nforce error (RMS of x, y; z along the rod is barely seen) against the noise, '
          '%s, %d loads of 0.05-1 N each' % (robot.name, cases))
    print('%-16s' % 'sigma length' + ''.join('  tension %d%% (sigma)  ' % p for p in percents))
    table = np.zeros((len(lengths_um), len(percents)))
    for i, sigma_length in enumerate(lengths_um):
        row = []
        for j, percent in enumerate(percents):
            rng = np.random.default_rng(seed)
            errors, sigmas = [], []
            for _ in range(cases):
                force = random_force(robot, rng)
                measurements, _ = applied(robot, rng, force, sigma_length * 1e-6,
                                          '%g%%' % percent)
                estimate = robot.estimate_tip_wrench(
                    noise={'length': sigma_length * 1e-6, 'tension': '%g%%' % percent},
                    **measurements)
                errors.append(estimate.force[:2] - force[:2])
                sigmas.append(estimate.sigma[:2])
            table[i, j] = float(np.sqrt(np.mean(np.square(errors))))
            row.append('%8.4f N (%.4f)' % (table[i, j], float(np.median(sigmas))))
        print('%-16s' % ('%d um' % sigma_length) + '  '.join(row), flush=True)
    if plot:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt

        figure, axes = plt.subplots(figsize=(6, 4))
        for j, percent in enumerate(percents):
            axes.plot(lengths_um, table[:, j] * 1e3, 'o-', label='tension noise %d %%' % percent)
        axes.set_xlabel('cable length noise (um)')
        axes.set_ylabel('lateral force error, RMS (mN)')
        axes.set_title('%s: tip-load estimate' % robot.name)
        axes.grid(True, alpha=0.3)
        axes.legend()
        figure.tight_layout()
        figure.savefig(plot, dpi=120)
        print('figure: %s' % plot)


def main(argv=None):
    """Run the benchmark; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_load',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--cold', type=int, default=20, help='cold cases per robot and model')
    parser.add_argument('--warm', type=int, default=100, help='warm calls per robot and model')
    parser.add_argument('--accuracy', type=int, default=40, help='loads per noise level')
    parser.add_argument('--plot', default=None, metavar='FILE.png',
                        help='draw the force error against the noise into this PNG')
    args = parser.parse_args(argv)
    timing(args.cold, args.warm)
    accuracy(args.accuracy, args.plot)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
