"""``python -m benchmarks.bench_noisy``: the shape estimate on real-robot inputs.

Real cable lengths never fit a shape exactly: encoders quantise, cables stretch, motors move in
straight lines between commands. For every example robot file and both cable models this
integrates a motion like a robot's (motors moving linearly at 20 mm/s between far-apart
equilibria, sampled at 1 kHz, so the lengths between the end points fit no shape exactly), adds
Gaussian encoder noise of sigma = 0, 1, 10 and 50 um, and times ``estimate_shape`` as the
statics node calls it (warm-started from the previous estimate, ``max_model_runs`` 32, the warn
threshold of ``length_noise_std`` = sigma): median, p99 and max, with the rod integrations
(IVPs) per call and how many calls were capped by the budget. Cold estimates (no warm start) on
rows far apart, and a plain SciPy baseline (``scipy.optimize.least_squares``, LM, on the same
model residual, from the same warm start) in the same run. Figures, not assertions.
"""
import argparse
import dataclasses
from pathlib import Path
import time

import numpy as np

from benchmarks.shared import motion, scipy_estimate
from continuum_statics import load_robot
from continuum_statics.config_paths import config_file
from continuum_statics.control.shape_tracking import Thresholds
from continuum_statics.core.estimation.shape_estimation import Tracking
from continuum_statics.core.robot import Robot
from continuum_statics.core.rod.tracking import TRACK_RUNS
from continuum_statics.core.warmup import warm_up

ROBOT_FILES = ('jones2009_nitinol_rod.yaml', 'tendon_robot.yaml', 'tendon_robot_real_tendons.yaml',
               'two_section_robot.yaml', 'three_section_robot.yaml',
               'three_section_robot_real_tendons.yaml', 'ftdcr_v6_robot.yaml',
               'ftdcr_v6_calibrated.yaml')
SIGMAS = (0.0, 1e-6, 10e-6, 50e-6)




def _stats(times):
    times = np.asarray(times) * 1e6
    return np.median(times), np.percentile(times, 99), np.max(times)




def bench_robot(robot, label, samples):
    """Print warm, cold and SciPy figures of one robot and cable model."""
    exact = motion(robot, samples)
    rng = np.random.default_rng(1)
    for sigma in SIGMAS:
        measured = exact + rng.normal(0.0, sigma, exact.shape)
        times, runs, capped, previous = [], [], 0, None
        # as statics with length_noise_std = sigma: its budget and its thresholds
        thresholds = Thresholds.with_noise(1e-4, 2e-3, 1e-3, sigma)
        tracking = Tracking(TRACK_RUNS, thresholds.warn, thresholds.motion, thresholds.noise)
        for k, lengths in enumerate(measured):
            start = time.perf_counter()
            previous = robot.estimate_shape(lengths, warm_start=previous, tracking=tracking)
            if k >= 20:
                times.append(time.perf_counter() - start)
                runs.append(previous.model_runs)
                capped += previous.capped
        work = ('IVPs median %2.0f max %3d' % (np.median(runs), max(runs)) if max(runs)
                else 'tendon model (solve_lengths)')
        print('  %-46s sigma %2.0f um  warm median %6.0f  p99 %6.0f  max %6.0f us   %s  '
              'capped %d of %d' % (label, sigma * 1e6, *_stats(times), work, capped,
                                   len(times)), flush=True)
    far = measured[::max(1, samples // 20)]
    cold = []
    for lengths in far:
        start = time.perf_counter()
        robot.estimate_shape(lengths)
        cold.append(time.perf_counter() - start)
    line = '  %-46s sigma 50 um  cold median %6.0f  p99 %6.0f  max %6.0f us' % (label,
                                                                                 *_stats(cold))
    if robot.tendons.is_ideal:
        baseline, previous = [], robot.estimate_shape(measured[0])
        for lengths in measured[1:21]:
            start = time.perf_counter()
            scipy_estimate(robot, lengths, previous.state)
            baseline.append(time.perf_counter() - start)
            previous = robot.estimate_shape(lengths, warm_start=previous)
        line += '   SciPy least_squares warm median %6.0f us' % (np.median(baseline) * 1e6)
    print(line, flush=True)


def main(argv=None):
    """Run the benchmark; returns 0."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_noisy',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=400, help='measurements per case')
    parser.add_argument('--robot', action='append', help='robot file(s) (default: examples)')
    options = parser.parse_args(argv)
    print('continuum_statics estimate on noisy, inconsistent lengths (warm: statics per cycle, '
          'max_model_runs %d)' % TRACK_RUNS)
    for path in options.robot or [config_file(name) for name in ROBOT_FILES]:
        base = load_robot(path)
        if not base.cable_names:
            continue
        for model in ('point_moment', 'distributed'):
            robot = Robot(dataclasses.replace(base.description, cable_model=model))
            warm_up(robot)  # as a node does: no kernel is compiled or loaded while timed
            bench_robot(robot, '%s, %s' % (Path(path).stem, model), options.samples)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
