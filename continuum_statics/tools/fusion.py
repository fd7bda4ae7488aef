"""``python -m continuum_statics fusion``: what each sensor buys, measured.

Two protocols (issue 35):

- ``--simulate``: simulated truth with loads the estimator does not know (a tip force, a length
  error per cable and an offset of the whole backbone, drawn from the robot file's
  ``model_uncertainty``), read by the robot file's sensors with their noise. For 0, 1, 2, ...
  sensors (in file order) it prints the backbone error along s against the truth (RMS over the
  cases) and how many cases the tip's 95 % ellipsoid holds (normalised estimation error squared).
- ``--data RUN``: a recorded run replayed with the tip tracker occluded in blocks
  (:mod:`continuum_statics.calibration.occlusion`): error on the occluded rows, fused against the
  model alone and the decayed-residual baseline, and the coverage of the 95 % ellipsoid.
"""
import argparse
import json
import sys

import numpy as np

from continuum_statics.calibration.occlusion import occlusion_replay
from continuum_statics.calibration.recorded_run import add_column_arguments, column_map_from_args
from continuum_statics.calibration.replay import replay
from continuum_statics.calibration.runs import read_run
from continuum_statics.core.description.sensors import SensorReading
from continuum_statics.core.estimation import shape_estimation
from continuum_statics.core.estimation.gates import chi2_quantile
from continuum_statics.core.estimation.state_estimation import (
    prior_scales,
    split_loads,
    white_sigma,
)

#: Arc-length fractions the simulated table reports the backbone error at.
TABLE_S = (0.25, 0.5, 0.75, 1.0)
#: Largest cable pull (fraction of the rod length) of a simulated configuration.
PULL = 0.02


def mismatched_truth(robot_file, seed=0):
    """Return (the file's robot, a truth with physics the file lacks) (issue 43's truth).

    The truth is the file's robot with the rod 8 % stiffer, the cables' EA 400 N, each cable
    homed up to 1.5 mm off (``seed``) and 10 g on every guide disk; a one-section file with
    ``guides`` and ``cables`` at its top level (``tendon_robot_sensors.yaml``).
    """
    import yaml

    from continuum_statics.core.description.robot_file import parse_robot_description
    from continuum_statics.core.robot import Robot

    with open(robot_file, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    rng = np.random.default_rng(seed)
    truth = {key: value for key, value in document.items()
             if key not in ('sensors', 'model_uncertainty', 'guides', 'cables')}
    stiffer = 1.08 * float(document['rod']['youngs_modulus'])  # PyYAML reads 58.0e9 as text
    truth['rod'] = dict(document['rod'], youngs_modulus=stiffer)
    truth['tendons'] = dict(document['tendons'], stiffness=400.0)
    cables = [dict(cable, zero_offset=float(rng.uniform(-1.5e-3, 1.5e-3)))
              for cable in document['cables']]
    truth['sections'] = [{'name': 'all', 'guides': document['guides'], 'cables': cables,
                          'disk_mass': 0.01}]
    return (Robot(parse_robot_description(document)),
            Robot(parse_robot_description(truth)))


def smooth_path(robot, rows, seed, hold=8, pull=0.012):
    """Return (rows, n) motor lengths: smooth moves between random pulls (up to ``pull`` m).

    A new target every ``hold`` rows, each cable pulled with probability 0.6.
    """
    rng = np.random.default_rng(seed)
    n = len(robot.cable_names)
    targets = robot.straight_cable_lengths - rng.uniform(0.0, pull, (rows // hold + 2, n)) * (
        rng.uniform(size=(rows // hold + 2, n)) < 0.6)
    phase = np.arange(rows) / hold
    k = phase.astype(int)
    w = 0.5 - 0.5 * np.cos(np.pi * (phase - k))[:, None]
    return (1.0 - w) * targets[k] + w * targets[k + 1]


def simulated_truth(robot, cases, seed=0):
    """Return rows of {sensors, rms (len(TABLE_S),) m, coverage} for 0..len(robot.sensors).

    Each case: random cable lengths (pulls up to :data:`PULL` L), hidden loads drawn from the
    prior, the truth solved by the model under them, plus the prior's white error
    (``point_noise`` s / L, one draw per arc length: the table's, each sensor's), each sensor
    read with its noise; every estimate is a cold one (the prior is all it knows of the loads).
    """
    rng = np.random.default_rng(seed)
    names, sigma = prior_scales(robot)
    n = len(robot.cable_names)
    s_table = np.array(TABLE_S) * robot.length
    counts = range(len(robot.sensors) + 1)
    errors = {count: [] for count in counts}
    inside = {count: 0 for count in counts}
    gate = chi2_quantile(0.95, 3)
    for _ in range(cases):
        lengths = robot.straight_cable_lengths - rng.uniform(0.0, PULL * robot.length, n) * (
            rng.uniform(size=n) < 0.5)
        hidden = rng.normal(0.0, sigma)
        force, moment, cable = split_loads(robot, hidden)
        # the offset and the drift (its rate moves nothing at one instant) shift the backbone
        offset = np.zeros(3)
        for name, value in zip(names, hidden):
            if name.split('.')[0] in ('base_position', 'drift'):
                offset['xyz'.index(name[-1])] += value
        truth = _truth(robot, lengths - cable, force, moment, offset)
        white = _white_errors(robot, truth, rng, [*s_table, *(x.s for x in robot.sensors)])
        readings = {}
        for sensor in robot.sensors:
            point, rotation = _pose_at(truth, sensor)
            readings[sensor.name] = SensorReading(
                point + white[_arc(sensor.s)] + rng.normal(0.0, sensor.position_sigma, 3),
                rotation if sensor.kind == 'pose' else None)
        truth_table = _at(truth, s_table) + np.array([white[_arc(s)] for s in s_table])
        for count in counts:
            used = {sensor.name: readings[sensor.name] for sensor in robot.sensors[:count]}
            estimate = robot.estimate_shape(lengths, exact=True, sensors=used)
            positions = _at(estimate.shape, s_table)
            errors[count].append(positions - truth_table)
            error = estimate.shape.tip_position - truth_table[-1]
            inside[count] += float(error @ np.linalg.solve(
                estimate.tip_covariance[:3, :3], error)) <= gate
    return [{'sensors': [sensor.name for sensor in robot.sensors[:count]],
             'rms': np.sqrt(np.mean(np.sum(np.array(errors[count]) ** 2, axis=2), axis=0)),
             'coverage': inside[count] / cases} for count in counts]


def _white_errors(robot, shape, rng, arcs):
    """Return {:func:`_arc` (s): (3,) m} the prior's white error at each arc length s.

    Zeros without one; one draw per point (0.75 L and a sensor at 0.225 m are one point).
    """
    noise = robot.model_uncertainty.point_noise
    if not noise:  # no draw: the cases of a file without it stay as they were
        return {_arc(s): np.zeros(3) for s in arcs}
    return {_arc(s): rng.normal(0.0, white_sigma(noise, s, shape.s[-1]), 3) for s in arcs}


def _arc(s):
    """Return arc length ``s`` (m) as a key: to the nanometre (0.75 L and 0.225 are one point)."""
    return round(float(s), 9)


def _truth(robot, lengths, force, moment, offset):
    """Return the true shape: the model's under the hidden loads, moved by the hidden offset."""
    shape = shape_estimation.estimate_shape(robot, lengths, force, moment, None, None, None,
                                            None, None).shape
    states = shape.states.copy()
    states[:, :3] += offset
    return type(shape)(shape.s, states, shape.u0, shape.tip_force, shape.c, shape.d)


def _pose_at(shape, sensor):
    """Return (point, rotation) of ``sensor`` on ``shape`` (nearest node's rotation)."""
    point = _at(shape, np.array([sensor.s]))[0]
    rotation = shape.rotations[int(np.argmin(np.abs(shape.s - sensor.s)))]
    return point + rotation @ sensor.offset, rotation


def _at(shape, s):
    """(len(s), 3) backbone points at arc lengths s (linear between nodes)."""
    return np.stack([np.interp(s, shape.s, shape.positions[:, k]) for k in range(3)], axis=1)


def main(argv=None):
    """Run the tool; return the exit code."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics fusion',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--robot', required=True, help='robot file with sensors and '
                        'model_uncertainty (calibrate --model-uncertainty writes it)')
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument('--simulate', type=int, metavar='CASES',
                      help='simulated truth: this many random cases')
    mode.add_argument('--data', metavar='RUN', help='a recorded run (CSV or bag) to replay')
    parser.add_argument('--blocks', default='1/1,5/5,10/10,40/40,20/40',
                        help='occlusion patterns SEEN/OCCLUDED rows (default %(default)s)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    add_column_arguments(parser)
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    from continuum_statics import load_robot

    try:
        robot = load_robot(args.robot)
        if robot.model_uncertainty is None:
            raise ValueError('%s has no model_uncertainty (calibrate --model-uncertainty)'
                             % args.robot)
        if args.simulate:
            rows = simulated_truth(robot, args.simulate, args.seed)
            result = {'kind': 'simulated', 'cases': args.simulate, 's': list(TABLE_S),
                      'rows': [dict(row, rms=row['rms'].tolist()) for row in rows]}
        else:
            run = read_run(args.data, robot, column_map_from_args(args))
            model_points = replay(robot, run)[0]
            patterns = [tuple(int(x) for x in item.split('/')) for item in
                        args.blocks.split(',')]
            result = {'kind': 'run', 'data': args.data, 'rows': [
                occlusion_replay(robot, run, seen, hidden, model_points).__dict__
                for seen, hidden in patterns]}
    except ValueError as error:
        print('error: %s' % error, file=sys.stderr)
        return 1
    print(json.dumps(result) if args.json else _report(result))
    return 0


def _report(result):
    if result['kind'] == 'simulated':
        lines = ['backbone error against simulated truth, RMS over %d cases (mm); tip 95 %% '
                 'ellipsoid coverage' % result['cases'],
                 '%-28s %s  coverage' % ('sensors', '  '.join('s=%.2fL' % s
                                                              for s in result['s']))]
        for row in result['rows']:
            lines.append('%-28s %s  %5.1f %%' % (
                ', '.join(row['sensors']) or '(none: model alone)',
                '  '.join('%6.2f' % (1e3 * value) for value in row['rms']),
                100 * row['coverage']))
        return '\n'.join(lines)
    lines = ['%s: tip tracker seen/occluded in blocks; errors on the occluded rows (mm)'
             % result['data'],
             'blocks   rows   fused   model  baseline  95%-coverage  estimate median/max (us)']
    for row in result['rows']:
        lines.append('%2d/%-3d %6d  %6.2f  %6.2f  %8.2f  %9.1f %%    %.0f / %.0f' % (
            row['seen'], row['hidden'], row['rows'], 1e3 * row['fused'], 1e3 * row['model'],
            1e3 * row['baseline'], 100 * row['coverage'], row['median_us'], row['max_us']))
    return '\n'.join(lines)
