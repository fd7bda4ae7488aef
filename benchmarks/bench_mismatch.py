"""``python -m benchmarks.bench_mismatch``: the fused estimate against a truth with other physics.

Issue 43's simulated truth. The truth is ``tendon_robot_sensors.yaml`` with what its file leaves
out: the rod 8 % stiffer, the cables' EA 400 N instead of 2000, each cable homed up to 1.5 mm
off, 10 g on every guide disk. Both move along the same smooth motor path (rows 0.5 s apart,
a new target every few seconds, pulls up to 12 mm), the truth's friction following it as the
model's does. The estimator's file is the nominal one; its ``model_uncertainty`` is measured by
``calibrate``'s :func:`model_uncertainty.measure` on a training run of the truth (its tip
tracker only), then a held-out run of another seed is estimated warm-started through the plain
API with no sensor, the tip tracker, and the tracker plus the EM coil, every row: backbone RMS
error at quarters of the length and how many rows the tip's 95 % ellipsoid holds (NEES).
Figures, not assertions.
"""
import argparse
import dataclasses
import time

import numpy as np

from continuum_statics.calibration import model_uncertainty
from continuum_statics.calibration.recorded_run import RecordedRun
from continuum_statics.config_paths import config_file
from continuum_statics.core.description.sensors import ModelUncertainty, SensorReading
from continuum_statics.core.estimation.gates import chi2_quantile
from continuum_statics.tools.fusion import mismatched_truth, smooth_path

FILE = 'tendon_robot_sensors.yaml'
#: Row period (s), rows between targets, largest pull (m).
PERIOD, HOLD, PULL = 0.5, 8, 0.012
FRACTIONS = (0.25, 0.5, 0.75, 1.0)


def robots(seed=0):
    """Return (the file's robot, the truth's robot)."""
    return mismatched_truth(config_file(FILE), seed)


def path(robot, rows, seed):
    """Return (rows, n) motor lengths: smooth moves between random pulls."""
    return smooth_path(robot, rows, seed, HOLD, PULL)


def truth_run(truth, lengths):
    """Return the truth's shapes along ``lengths`` (warm-started: friction follows the path)."""
    shapes, previous = [], None
    for row in lengths:
        previous = truth.solve_lengths(row, warm_start=previous)
        shapes.append(previous.shape)
    return shapes


def _point(shape, sensor):
    i = int(np.argmin(np.abs(shape.s - sensor.s)))
    at = np.array([np.interp(sensor.s, shape.s, shape.positions[:, k]) for k in range(3)])
    return at + shape.rotations[i] @ sensor.offset, shape.rotations[i]


def main(argv=None):
    """Measure the model uncertainty on a training run, print the held-out table."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_mismatch')
    parser.add_argument('--train', type=int, default=400, help='training rows')
    parser.add_argument('--rows', type=int, default=600, help='held-out rows')
    parser.add_argument('--tracker-only', action='store_true',
                        help='calibrate on the training run without the coil (as before)')
    args = parser.parse_args(argv)
    nominal, truth = robots()
    tracker, coil = nominal.sensors
    rng = np.random.default_rng(3)
    began = time.monotonic()
    lengths = path(nominal, args.train, seed=1)
    shapes = truth_run(truth, lengths)
    seen = [np.array([_point(shape, sensor)[0] for shape in shapes])
            + rng.normal(0.0, sensor.position_sigma, (args.train, 3))
            for sensor in (tracker, coil)]
    run = RecordedRun(times=PERIOD * np.arange(args.train), labels=('',) * args.train,
                      lengths=lengths, tips=seen[0], source='simulated truth',
                      points={} if args.tracker_only else {coil.name: seen[1]})
    bare = nominal.with_model_uncertainty(ModelUncertainty())
    measured, report = model_uncertainty.measure(bare, run)
    print('model_uncertainty from %d training rows (%.0f s): %s' % (
        args.train, time.monotonic() - began,
        ', '.join('%s %.3g' % item for item in dataclasses.asdict(measured).items())))
    robot = nominal.with_model_uncertainty(measured)
    lengths = path(nominal, args.rows, seed=2)
    shapes = truth_run(truth, lengths)
    gate = chi2_quantile(0.95, 3)
    s = np.array(FRACTIONS) * nominal.length
    print('held out, %d rows warm-started (plain API), every sensor every row:' % args.rows)
    print('sensors                 ' + ''.join('  s=%.2fL' % f for f in FRACTIONS)
          + '   tip 95 % holds   NEES median')
    for used in ((), (tracker,), (tracker, coil)):
        errors, nees, previous = [], [], None
        for i, (row, shape) in enumerate(zip(lengths, shapes)):
            readings = {}
            for sensor in used:
                point, rotation = _point(shape, sensor)
                readings[sensor.name] = SensorReading(
                    point + rng.normal(0.0, sensor.position_sigma, 3),
                    rotation if sensor.kind == 'pose' else None, stamp=PERIOD * i)
            previous = robot.estimate_shape(row, warm_start=previous, sensors=readings,
                                            stamp=PERIOD * i)
            est = previous.shape
            errors.append([np.interp(s, est.s, est.positions[:, k])
                           - np.interp(s, shape.s, shape.positions[:, k]) for k in range(3)])
            tip = est.tip_position - shape.tip_position
            nees.append(float(tip @ np.linalg.solve(previous.tip_covariance[:3, :3], tip)))
        rms = 1e3 * np.sqrt(np.mean(np.sum(np.array(errors) ** 2, axis=1), axis=0))
        print('%-24s' % (' + '.join(x.name for x in used) or 'none (model alone)')
              + ''.join('%9.2f' % value for value in rms)
              + '   %6.1f %%        %.2f' % (100 * np.mean(np.array(nees) <= gate),
                                              np.median(nees)))


if __name__ == '__main__':
    main()
