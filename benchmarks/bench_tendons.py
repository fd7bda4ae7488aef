"""``python -m benchmarks.bench_tendons``: figures of the real-tendon statics.

``solve_lengths`` on the 3-section 9-cable robot (ideal cables, and with stretch, pretension and
friction), cold (from nothing) and warm (a tracking sequence: each call warm-started by the
previous result), beside a plain SciPy baseline of the same equations in the same run
(``scipy.optimize.root``, Levenberg-Marquardt with SciPy's own finite differences, on the same
residual). The v6 calibration has its own benchmark (:mod:`.bench_calibration`). Figures, not
assertions.
"""
import argparse
import dataclasses
import time

import numpy as np
from scipy.optimize import root

from continuum_statics import load_robot
from continuum_statics.config_paths import config_file
from continuum_statics.core.description.tendons import Tendons
from continuum_statics.core.robot import Robot
from continuum_statics.core.statics import length_statics
from continuum_statics.tools.bench import row


def with_tendons(robot, stiffness=2000.0, pretension=2.0, friction=0.05):
    """Return the robot with real tendons (N, N, 1) on every cable."""
    n = len(robot.cable_names)
    tendons = dataclasses.replace(Tendons.default(n), stiffness=np.full(n, stiffness),
                                  pretension=np.full(n, pretension),
                                  friction=np.full(n, friction))
    return Robot(dataclasses.replace(robot.description, tendons=tendons))


def tracking_sequence(robot, count, seed=0):
    """Motor lengths of a smooth random tension walk (what a node sees at 1 kHz or so)."""
    rng = np.random.default_rng(seed)
    n = len(robot.cable_names)
    tensions = np.abs(rng.normal(0.0, 1.0, n))
    ideal = Robot(dataclasses.replace(robot.description, tendons=Tendons.default(n)))
    rows = []
    for _ in range(count):
        tensions = np.maximum(tensions + rng.normal(0.0, 0.02, n), 0.0)
        rows.append(ideal.cable_lengths(ideal.solve_tensions(tensions)))
    return np.array(rows)


def scipy_baseline(robot, lengths):
    """Solve the same equilibrium by scipy.optimize.root (LM, SciPy finite differences), cold."""
    n = len(robot.cable_names)
    free = robot.tendons.free_lengths(lengths, robot.straight_cable_lengths)
    problem = length_statics.length_problem(robot, free)
    z0 = np.zeros(3 + n)
    result = root(lambda z: problem.evaluate(z * problem.scale)[0], z0 / problem.scale,
                  method='lm', options={'xtol': 1e-12})
    return result


def bench_solve_lengths(robot, label, count=200):
    """Print warm, cold and SciPy-baseline times of solve_lengths on a tracking sequence."""
    print('\n%s: %d cables, %d sections, %s model' % (label, len(robot.cable_names),
                                                     len(robot.sections), robot.cable_model))
    rows = tracking_sequence(robot, count)
    warm_times, previous = [], robot.solve_lengths(rows[0])
    failures = 0
    for lengths in rows[1:]:
        start = time.perf_counter()
        previous = robot.solve_lengths(lengths, warm_start=previous)
        warm_times.append(time.perf_counter() - start)
        failures += not previous.converged
    cold_times = []
    for lengths in rows[::10]:
        start = time.perf_counter()
        failures += not robot.solve_lengths(lengths).converged
        cold_times.append(time.perf_counter() - start)
    scipy_times, scipy_fail = [], 0
    for lengths in rows[::40]:
        start = time.perf_counter()
        scipy_fail += not scipy_baseline(robot, lengths).success
        scipy_times.append(time.perf_counter() - start)
    row('solve_lengths warm (tracking)', np.array(warm_times))
    row('solve_lengths cold', np.array(cold_times))
    row('SciPy root (LM) cold, same residual', np.array(scipy_times))
    print('  not converged: solve_lengths %d of %d, SciPy %d of %d'
          % (failures, len(warm_times) + len(cold_times), scipy_fail, len(scipy_times)))


def main(argv=None):
    """Run the benchmark; returns 0."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_tendons')
    parser.parse_args(argv)
    print('continuum_statics real-tendon benchmark')
    three = load_robot(config_file('three_section_robot.yaml'))
    bench_solve_lengths(three, 'three_section_9c, ideal cables')
    bench_solve_lengths(with_tendons(three), 'three_section_9c, EA 2 kN, 2 N pretension, '
                                             'mu 0.05')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
