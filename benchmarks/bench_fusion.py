"""``python -m benchmarks.bench_fusion``: the fused estimate at 1 kHz, two sensors.

For each robot file with sensors (and every example robot given a tip tracker and an EM coil at
its middle disk, with the stand-in ``model_uncertainty``; the payload file also carries its
tip load in the fused state), the motion of
:func:`bench_noisy.motion` (motors at 20 mm/s between far-apart equilibria, 1 kHz, encoder noise
10 um) is estimated as the statics node does (warm-started, bounded), with the tip tracker's
readings at 125 Hz and the coil's at 40 Hz (their noise added to the model's own points), and
beside it the model alone (the same robot file without sensors or model_uncertainty) in the
same run: median, p99 and max in us. Figures, not assertions (issue 35's budget: median 150,
p99 500, max 1000 us).
"""
import argparse
import dataclasses
from pathlib import Path
import time

import numpy as np

from benchmarks.shared import motion
from continuum_statics import load_robot
from continuum_statics.config_paths import config_file
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.description.sensors import SensorReading
from continuum_statics.core.estimation.shape_estimation import Tracking
from continuum_statics.core.robot import Robot
from continuum_statics.core.warmup import warm_up

SENSOR_FILES = ('tendon_robot_sensors.yaml', 'tendon_robot_payload.yaml', 'ftdcr_v6_fused.yaml')
PLAIN_FILES = ('tendon_robot.yaml', 'three_section_robot.yaml',
               'three_section_robot_real_tendons.yaml')
#: Encoder noise (m) and the sensors' periods in 1 kHz samples (125 Hz optical, 40 Hz EM).
NOISE, TRACKER_EVERY, COIL_EVERY = 10e-6, 8, 25


def with_two_sensors(path):
    """Return the robot of ``path`` with a tip tracker and an EM coil at its middle disk."""
    import yaml

    with open(path, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    robot = load_robot(path)
    document['sensors'] = [
        {'name': 'tip_tracker', 'at': 'tip', 'kind': 'position', 'noise': {'position': 5e-4}},
        {'name': 'em_coil', 'at': {'disk': len(robot.guides) // 2}, 'kind': 'pose',
         'noise': {'position': 7e-4, 'angle': 0.01}}]
    return Robot(parse_robot_description(document, str(path)))


def _stats(times):
    times = np.asarray(times) * 1e6
    return np.median(times), np.percentile(times, 99), np.max(times)


def bench(robot, label, samples):
    """Print the fused estimate's and the model alone's figures on one motion."""
    plain = Robot(dataclasses.replace(robot.description, sensors=(), model_uncertainty=None,
                                      load=None))
    exact = motion(plain, samples)
    rng = np.random.default_rng(1)
    measured = exact + rng.normal(0.0, NOISE, exact.shape)
    tracking = Tracking(length_noise=NOISE, motion_threshold=3 * NOISE,
                        slack_residual=max(1e-4, 3 * NOISE))
    truth = [plain.estimate_shape(lengths, exact=True).shape for lengths in exact[::COIL_EVERY]]
    figures = []
    for each in (plain, robot):
        times, previous, used = [], None, 0
        for k, lengths in enumerate(measured):
            readings = {}
            for sensor, every in zip(each.sensors, (TRACKER_EVERY, COIL_EVERY)):
                if k % every == 0:
                    shape = truth[min(k // COIL_EVERY, len(truth) - 1)]
                    node = int(np.argmin(np.abs(shape.s - sensor.s)))
                    point = (shape.positions[node] + shape.rotations[node] @ sensor.offset
                             + rng.normal(0.0, sensor.position_sigma, 3))
                    readings[sensor.name] = SensorReading(
                        point, shape.rotations[node] if sensor.kind == 'pose' else None)
            start = time.perf_counter()
            previous = each.estimate_shape(lengths, warm_start=previous, tracking=tracking,
                                           sensors=readings or None, stamp=k * 1e-3)
            elapsed = time.perf_counter() - start
            used += sum(v.used for v in (previous.sensors or {}).values())
            if k >= 20:
                times.append(elapsed)
        figures.append((_stats(times), used))
    (alone, _), (fused, used) = figures
    print('  %-44s model alone %5.0f / %5.0f / %5.0f   fused (2 sensors) %5.0f / %5.0f / %5.0f'
          '   readings used %d' % (label, *alone, *fused, used), flush=True)


def main(argv=None):
    """Run the benchmark; returns 0."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_fusion',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=1500, help='measurements per robot')
    options = parser.parse_args(argv)
    print('fused estimate at 1 kHz (encoders %.0f um, tip tracker 125 Hz, EM coil 40 Hz): '
          'median / p99 / max us' % (NOISE * 1e6))
    robots = [(load_robot(config_file(name)), name) for name in SENSOR_FILES]
    robots += [(with_two_sensors(config_file(name)), name + ' + 2 sensors')
               for name in PLAIN_FILES]
    for robot, name in robots:
        if len(robot.sensors) < 2:  # a file with one sensor: add the coil too
            robot = with_two_sensors(config_file(name))
            name += ' + EM coil'
        warm_up(robot)
        bench(robot, Path(name).stem if name.endswith('.yaml') else name, options.samples)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
