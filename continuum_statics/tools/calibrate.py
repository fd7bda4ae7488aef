"""``python -m continuum_statics calibrate``: fit robot-file parameters to measured tip positions.

Each CSV row is one static experiment: a known tip load and the measured tip position, both in
the base frame (header ``tip_force_x,tip_force_y,tip_force_z,tip_x,tip_y,tip_z``; N and m;
optional ``tip_moment_x..z`` in N m; optional one column per cable name with the measured cable
length in m; lines starting with ``#`` are comments). The model tip of a row is the passive
boundary-value solution under that load (``Robot.solve_bvp``) or, when cable lengths are given,
the shape estimated from them (``Robot.estimate_shape``); every solve is warm-started from the
same row's previous solution. ``scipy.optimize.least_squares`` (trust region, bounds) minimises
the tip position errors over the chosen parameters:

- ``youngs_modulus`` (Pa; G follows E when the file gives ``poisson_ratio``)
- ``density`` (kg/m^3)
- ``base_roll``, ``base_pitch``, ``base_yaw`` (deg): an extra base rotation about the base
  frame's fixed x, y, z axes (URDF ``rpy`` order: R = Rz(yaw) Ry(pitch) Rx(roll)) applied on top
  of the file's orientation; right-hand rule, so a positive pitch turns +x toward -z. Fit only
  the ones the data can see: a roll about the rod's own axis changes nothing for a round rod
- ``cable_offset_scale`` (1): factor on every cable hole offset (needs cable length columns)

The calibrated robot file is the input file with the fitted values replaced and a header
comment saying what was fitted from which data.

Recorded runs (a CSV with a ``timestamp`` column or a column map, or a rosbag2 recording) are
fitted by :mod:`continuum_statics.tools.run_calibration` instead: the run is replayed through
``Robot.solve_lengths`` and the registration, hole patterns, zero offsets and tendon parameters
are fitted.
"""
import argparse
import csv
import dataclasses
import datetime
import json
import math
import os
import sys
import time

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation
import yaml

from continuum_statics import ConvergenceError, Robot, load_robot
from continuum_statics.tools import run_calibration
from continuum_statics.tools.recorded_run import (
    add_column_arguments,
    check_tip_units,
    column_map_from_args,
)

FORCE_COLUMNS = ('tip_force_x', 'tip_force_y', 'tip_force_z')
MOMENT_COLUMNS = ('tip_moment_x', 'tip_moment_y', 'tip_moment_z')
TIP_COLUMNS = ('tip_x', 'tip_y', 'tip_z')
#: Model tip error (m, each axis) of a row whose solve fails: large, so the fit moves away.
FAILED_ROW_ERROR = 1.0
#: A long fit prints a progress line this often, s (stderr).
PROGRESS_S = 5.0
#: A parameter whose 1-sigma exceeds this fraction of its bounds' width is not determined.
UNDETERMINED = 0.5
BASE_ANGLES = ('base_roll', 'base_pitch', 'base_yaw')


@dataclasses.dataclass(frozen=True)
class Parameter:
    """A fittable parameter: its unit, bounds and how the optimiser scales it."""

    name: str
    unit: str
    relative: bool   # the optimiser works on value / file value (bounds are ratios too)
    bounds: tuple
    needs_cables: bool = False


PARAMETERS = {p.name: p for p in (
    Parameter('youngs_modulus', 'Pa', True, (0.1, 10.0)),
    Parameter('density', 'kg/m^3', True, (0.1, 10.0)),
    Parameter('base_pitch', 'deg', False, (-30.0, 30.0)),
    Parameter('base_roll', 'deg', False, (-30.0, 30.0)),
    Parameter('base_yaw', 'deg', False, (-30.0, 30.0)),
    Parameter('cable_offset_scale', '1', False, (0.5, 2.0), needs_cables=True),
)}


@dataclasses.dataclass(frozen=True)
class Measurements:
    """Rows of a calibration CSV (SI units, base frame)."""

    tip_forces: np.ndarray     # (n, 3) N
    tip_moments: np.ndarray    # (n, 3) N m
    tips: np.ndarray           # (n, 3) m
    cable_lengths: object      # (n, n_cables) m, robot.cable_names order, or None
    ignored_columns: tuple


def read_measurements(path, cable_names):
    """Read a calibration CSV; ``ValueError`` names a missing column or a bad cell.

    :param cable_names: the robot's cable names; their columns are all given or none
    """
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            lines = [line for line in stream if line.strip() and not line.lstrip().startswith('#')]
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError('cannot read data file %s: %s' % (path, error)) from None
    reader = csv.reader(lines)
    try:
        header = [name.strip() for name in next(reader)]
    except StopIteration:
        raise ValueError('data file %s is empty' % path) from None
    missing = [c for c in FORCE_COLUMNS + TIP_COLUMNS if c not in header]
    if missing:
        raise ValueError('data file %s lacks the columns %s (header: %s)'
                         % (path, ', '.join(missing), ','.join(header)))
    cables = [c for c in cable_names if c in header]
    if cables and len(cables) != len(cable_names):
        raise ValueError('data file %s has length columns for cables %s but not for %s: give '
                         'all cables or none' % (path, ', '.join(cables), ', '.join(
                             c for c in cable_names if c not in header)))
    known = set(FORCE_COLUMNS + MOMENT_COLUMNS + TIP_COLUMNS) | set(cable_names)
    rows = []
    for number, row in enumerate(reader, start=2):
        if len(row) != len(header):
            raise ValueError('data file %s, data row %d: %d cells, the header has %d'
                             % (path, number - 1, len(row), len(header)))
        values = {}
        for name, cell in zip(header, row):
            if name not in known:
                continue
            try:
                values[name] = float(cell)
            except ValueError:
                raise ValueError('data file %s, data row %d, column %s: %r is not a number'
                                 % (path, number - 1, name, cell)) from None
            if not math.isfinite(values[name]):
                raise ValueError('data file %s, data row %d, column %s: not finite'
                                 % (path, number - 1, name))
        rows.append(values)
    if not rows:
        raise ValueError('data file %s has a header but no data rows' % path)

    def table(columns, default=None):
        return np.array([[r.get(c, default) for c in columns] for r in rows], dtype=float)

    moments = table(MOMENT_COLUMNS, 0.0)
    return Measurements(
        tip_forces=table(FORCE_COLUMNS), tip_moments=moments, tips=table(TIP_COLUMNS),
        cable_lengths=table(cable_names) if cables else None,
        ignored_columns=tuple(c for c in header if c not in known))


class Model:
    """Robot files of candidate parameter values and their tip predictions (warm-started)."""

    def __init__(self, robot, names, data):
        self.robot = robot
        self.names = list(names)
        self.data = data
        self.warm = [None] * len(data.tips)
        rod = robot.description.rod
        self.file_values = {
            'youngs_modulus': rod.youngs_modulus, 'density': rod.density,
            'base_roll': 0.0, 'base_pitch': 0.0, 'base_yaw': 0.0, 'cable_offset_scale': 1.0}
        self.poisson_given = None  # set by calibrate() from the YAML (G follows E or not)
        self.evaluations = 0
        self._started = self._reported = time.monotonic()

    def values(self, x):
        """Map optimiser variables to parameter values in their units."""
        values = {}
        for name, xi in zip(self.names, x):
            parameter = PARAMETERS[name]
            values[name] = xi * self.file_values[name] if parameter.relative else xi
        return values

    def start(self):
        """Optimiser start: the robot file's values."""
        return np.array([1.0 if PARAMETERS[n].relative else self.file_values[n]
                         for n in self.names])

    def bounds(self):
        """Lower and upper bounds of the optimiser variables."""
        lows = [PARAMETERS[n].bounds[0] for n in self.names]
        highs = [PARAMETERS[n].bounds[1] for n in self.names]
        return np.array(lows), np.array(highs)

    def robot_for(self, values):
        """Return a :class:`Robot` with ``values`` (name -> value) replacing the file's."""
        description = self.robot.description
        rod = description.rod
        changes = {}
        if 'youngs_modulus' in values or 'density' in values:
            youngs = values.get('youngs_modulus', rod.youngs_modulus)
            shear = rod.shear_modulus
            if self.poisson_given is not False:  # G = E / (2 (1 + nu)) keeps nu
                shear = rod.shear_modulus * youngs / rod.youngs_modulus
            changes['rod'] = dataclasses.replace(
                rod, youngs_modulus=youngs, shear_modulus=shear,
                density=values.get('density', rod.density))
        if set(values) & set(BASE_ANGLES):
            changes['base_orientation'] = base_orientation(description.base_orientation,
                                                           *_angles(values))
        if 'cable_offset_scale' in values:
            changes['cable_offsets'] = description.cable_offsets * values['cable_offset_scale']
        return Robot(dataclasses.replace(description, **changes))

    def tips(self, robot, remember=True):
        """Model tip positions (n, 3) in m; rows that do not solve get NaN."""
        data = self.data
        tips = np.full(data.tips.shape, np.nan)
        for i in range(len(data.tips)):
            for guess in (self.warm[i], None):
                try:
                    if data.cable_lengths is None:
                        shape = robot.solve_bvp(tip_force=data.tip_forces[i],
                                                tip_moment=data.tip_moments[i], u0_guess=guess)
                    else:
                        estimate = robot.estimate_shape(
                            data.cable_lengths[i], tip_force=data.tip_forces[i],
                            u0_guess=guess, tip_moment=data.tip_moments[i])
                        shape = estimate.shape
                except (ConvergenceError, ValueError):
                    continue
                if np.all(np.isfinite(shape.tip_position)):
                    tips[i] = shape.tip_position
                    if remember:
                        self.warm[i] = np.array(shape.u0)
                    break
        return tips

    def residuals(self, x):
        """Model minus measured tip positions, flattened (m)."""
        errors = self.tips(self.robot_for(self.values(x))) - self.data.tips
        self.evaluations += 1
        now = time.monotonic()
        if now - self._reported >= PROGRESS_S:  # a long fit says it is alive (stderr)
            self._reported = now
            print('calibrate: %d model evaluations of %d rows, %.0f s, tip RMS %.3f mm'
                  % (self.evaluations, len(errors), now - self._started,
                     1e3 * math.sqrt(np.nanmean(np.sum(errors ** 2, axis=1)))),
                  file=sys.stderr, flush=True)
        return np.nan_to_num(errors, nan=FAILED_ROW_ERROR).ravel()


def _angles(values):
    return [values.get(name, 0.0) for name in BASE_ANGLES]


def base_orientation(quaternion_xyzw, roll_deg, pitch_deg, yaw_deg):
    """Turn a base orientation about the fixed base axes x, y, z (deg, URDF rpy order).

    R = Rz(yaw) Ry(pitch) Rx(roll) R_file; :returns: unit quaternion [x, y, z, w]
    """
    turn = Rotation.from_euler('xyz', [roll_deg, pitch_deg, yaw_deg], degrees=True)
    quaternion = (turn * Rotation.from_quat(quaternion_xyzw)).as_quat()
    return quaternion / np.linalg.norm(quaternion)


def tip_errors(predicted, measured):
    """Euclidean tip errors (n,) in m (NaN rows count as unsolved)."""
    return np.linalg.norm(np.asarray(predicted) - np.asarray(measured), axis=1)


def _error_summary(errors):
    return {'mean_mm': float(np.mean(errors) * 1e3), 'max_mm': float(np.max(errors) * 1e3)}


def calibrate(robot_file, data_file, fit, output=None):
    """Fit ``fit`` (parameter names) to the data; write ``output``; return a result dict.

    :raises ValueError: unreadable files, unknown parameters, missing columns
    """
    unknown = [name for name in fit if name not in PARAMETERS]
    if unknown:
        raise ValueError('unknown parameter(s) %s; fittable: %s'
                         % (', '.join(unknown), ', '.join(PARAMETERS)))
    fit = list(dict.fromkeys(fit))
    robot = load_robot(robot_file)
    with open(robot_file, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    data = read_measurements(data_file, robot.cable_names)
    needs_cables = [n for n in fit if PARAMETERS[n].needs_cables]
    if needs_cables and data.cable_lengths is None:
        raise ValueError('%s needs measured cable lengths: the data has no column per cable (%s)'
                         % (', '.join(needs_cables), ', '.join(robot.cable_names) or 'no cables'))
    check_tip_units(data.tips, robot.length, data_file, 'the tip columns are in m')
    distinct = len(np.unique(np.column_stack([
        data.tip_forces, data.tip_moments, data.tips,
        *(() if data.cable_lengths is None else (data.cable_lengths,))]), axis=0))
    if distinct < len(fit) + 1:
        raise ValueError('%d distinct row(s) (of %d) cannot determine %d parameter(s) and their '
                         'uncertainty: measure at least %d different tip loads or poses'
                         % (distinct, len(data.tips), len(fit), len(fit) + 1))
    model = Model(robot, fit, data)
    model.poisson_given = 'shear_modulus' not in (document.get('rod') or {})
    before = model.tips(robot)
    if not np.all(np.isfinite(before)):
        bad = [int(i) + 1 for i in np.flatnonzero(~np.all(np.isfinite(before), axis=1))]
        raise ValueError("the robot file's model does not solve data rows %s" % bad)
    lows, highs = model.bounds()
    result = least_squares(model.residuals, model.start(), bounds=(lows, highs),
                           x_scale='jac', diff_step=1e-5, xtol=1e-10, ftol=1e-12, gtol=1e-12,
                           max_nfev=200)
    values = model.values(result.x)
    fitted_robot = model.robot_for(values)
    after = model.tips(fitted_robot)
    sigma = _standard_errors(result, model)
    undetermined = [name for i, name in enumerate(fit)
                    if not (sigma[i] <= UNDETERMINED * (highs[i] - lows[i]))]
    if undetermined:  # a meaningless fit is never written
        raise ValueError('the data do not determine %s (1-sigma %s, bounds %s): add rows with '
                         'other tip loads or poses' % (
                             ', '.join(undetermined),
                             ', '.join('%.3g' % sigma[fit.index(n)] for n in undetermined),
                             ', '.join('[%g, %g]' % (lows[fit.index(n)], highs[fit.index(n)])
                                       for n in undetermined)))
    before_errors, after_errors = tip_errors(before, data.tips), tip_errors(after, data.tips)
    summary = {
        'robot': str(robot_file), 'data': str(data_file), 'rows': int(len(data.tips)),
        'model': 'estimate_shape (cable lengths)' if data.cable_lengths is not None
        else 'solve_bvp (passive rod)',
        'fitted': {name: {'before': model.file_values[name], 'after': float(values[name]),
                          'std': float(sigma[i] * (model.file_values[name]
                                                   if PARAMETERS[name].relative else 1.0)),
                          'unit': PARAMETERS[name].unit, 'at_bound': bool(
                              np.isclose(result.x[i], lows[i]) or
                              np.isclose(result.x[i], highs[i]))}
                   for i, name in enumerate(fit)},
        'tip_error_before': _error_summary(before_errors),
        'tip_error_after': _error_summary(after_errors),
        'optimizer': {'success': bool(result.success), 'evaluations': int(result.nfev),
                      'message': str(result.message)},
        'ignored_columns': list(data.ignored_columns),
        'output': None if output is None else str(output),
    }
    if output is not None:
        write_robot_file(output, document, values, robot, summary)
        check = load_robot(output)
        summary['tip_error_written_file'] = _error_summary(
            tip_errors(Model(check, fit, data).tips(check), data.tips))
    return summary


def _standard_errors(result, model):
    """1-sigma uncertainty of the optimiser variables from the Jacobian and the residual RMS."""
    jac = np.asarray(result.jac)
    dof = max(jac.shape[0] - jac.shape[1], 1)
    variance = 2.0 * result.cost / dof
    try:
        covariance = np.linalg.inv(jac.T @ jac) * variance
    except np.linalg.LinAlgError:
        return np.full(len(model.names), np.nan)
    return np.sqrt(np.clip(np.diag(covariance), 0.0, None))


def write_robot_file(output, document, values, robot, summary):
    """Write the input robot file's content with the fitted values and a provenance comment."""
    document = dict(document)
    if 'youngs_modulus' in values or 'density' in values:
        document['rod'] = dict(document['rod'])
        for name in ('youngs_modulus', 'density'):
            if name in values:
                document['rod'][name] = float('%.6g' % values[name])
    if set(values) & set(BASE_ANGLES):
        document['base'] = dict(document['base'])
        quaternion = base_orientation(robot.description.base_orientation, *_angles(values))
        document['base']['orientation'] = [float('%.9f' % q) for q in quaternion]
    if 'cable_offset_scale' in values:
        scale = values['cable_offset_scale']
        for holder in [document] + list(document.get('sections') or []):
            for cable in holder.get('cables') or []:
                cable['offset'] = [float('%.6g' % (v * scale)) for v in cable['offset']]
    fitted = ', '.join('%s %.6g -> %.6g %s (+- %.2g)' % (
        name, f['before'], f['after'], f['unit'], f['std'])
        for name, f in summary['fitted'].items())
    before, after = summary['tip_error_before'], summary['tip_error_after']
    header = [
        'Calibrated by `python -m continuum_statics calibrate` on %s UTC'
        % datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M'),
        'from %s (%s),' % (summary['robot'], robot.name),
        'fitted to %d measured tip positions in %s:' % (summary['rows'], summary['data']),
        fitted + '.',
        'Model: %s. Tip error mean %.3f -> %.3f mm, max %.3f -> %.3f mm.' % (
            summary['model'], before['mean_mm'], after['mean_mm'], before['max_mm'],
            after['max_mm']),
    ]
    text = ''.join('# %s\n' % line for line in header)
    text += yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=99)
    with open(output, 'w', encoding='utf-8') as stream:
        stream.write(text)


def is_recorded_run(path, column_map):
    """Tell whether ``path`` holds a recorded run.

    A bag, a column map, or a CSV with timestamps and no tip-load columns is one.
    """
    if column_map.cables or os.path.isdir(path) or str(path).endswith('.mcap'):
        return True
    try:
        with open(path, newline='', encoding='utf-8') as stream:
            for line in stream:
                if line.strip() and not line.lstrip().startswith('#'):
                    header = [name.strip() for name in line.split(',')]
                    return 'timestamp' in header and FORCE_COLUMNS[0] not in header
    except (OSError, UnicodeDecodeError):
        return False
    return False


def main(argv=None):
    """Run the calibration; returns the exit code."""
    parser = argparse.ArgumentParser(
        prog='python -m continuum_statics calibrate',
        description='Fit robot-file parameters to measured tip positions (least squares with '
                    'bounds): under known tip loads, or along a recorded run of cable lengths '
                    '(replayed through solve_lengths); writes the calibrated robot file.')
    parser.add_argument('--robot', required=True, help='robot file to start from (YAML)')
    parser.add_argument('--data', required=True,
                        help='CSV: tip_force_x,tip_force_y,tip_force_z,tip_x,tip_y,tip_z '
                             '(N, m, base frame), optional tip_moment_x..z, cable lengths; or a '
                             'recorded run: CSV (timestamp, one length column per cable, tip '
                             'columns; see the column options) or a rosbag2 directory')
    parser.add_argument('--fit', action='extend', nargs='+', metavar='PARAM', default=None,
                        help='parameter(s) to fit: %s (default youngs_modulus); recorded runs: '
                             '%s (default %s)' % (', '.join(PARAMETERS),
                                                  ', '.join(run_calibration.RUN_PARAMETERS),
                                                  ' '.join(run_calibration.DEFAULT_FIT)))
    parser.add_argument('--output', '-o', default=None,
                        help='calibrated robot file to write (default: none, report only)')
    parser.add_argument('--validate', default=None, metavar='FILE',
                        help='recorded runs: held-out run to report the errors on (never fitted)')
    parser.add_argument('--tip-topic', default='tip_pose_measured',
                        help='recorded runs in a bag: the measured tip topic (PoseStamped)')
    parser.add_argument('--max-evaluations', type=int, default=40,
                        help='recorded runs: most model evaluations of the fit (default 40)')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    add_column_arguments(parser)
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        column_map = column_map_from_args(args)
        if is_recorded_run(args.data, column_map):
            log = (lambda text: print(text, file=sys.stderr)) if args.json else print
            summary = run_calibration.calibrate_run(
                args.robot, args.data, args.fit or list(run_calibration.DEFAULT_FIT),
                column_map, args.output, args.validate, args.tip_topic, log,
                args.max_evaluations)
            print(json.dumps(summary) if args.json else _run_report(summary))
            return 0
        summary = calibrate(args.robot, args.data, args.fit or ['youngs_modulus'], args.output)
    except ValueError as error:
        print('error: %s' % error, file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(summary))
        return 0
    print('calibrate: %d rows of %s, model %s' % (summary['rows'], summary['data'],
                                                   summary['model']))
    for name, f in summary['fitted'].items():
        print('  %-20s %14.6g -> %14.6g %-7s (1-sigma %.2g)%s' % (
            name, f['before'], f['after'], f['unit'], f['std'],
            '  AT BOUND' if f['at_bound'] else ''))
    before, after = summary['tip_error_before'], summary['tip_error_after']
    print('tip error before: mean %.3f mm, max %.3f mm' % (before['mean_mm'], before['max_mm']))
    print('tip error after:  mean %.3f mm, max %.3f mm' % (after['mean_mm'], after['max_mm']))
    if summary['ignored_columns']:
        print('note: ignored columns %s' % ', '.join(summary['ignored_columns']))
    if args.output:
        print('wrote %s' % args.output)
    return 0


def _run_report(summary):
    """Plain-text report of a recorded-run calibration."""
    lines = ['fitted (%s, %d evaluations, %.0f s):' % (
        summary['optimizer']['message'], summary['optimizer']['evaluations'],
        summary['seconds'])]
    for name, values in summary['fitted'].items():
        lines.append('  %-17s %s' % (name, ' '.join('%.5g' % v for v in values)))
    lines.append('tip RMS: file as given %.2f mm -> fitted %.2f mm (%.2f mm mean-offset '
                 'aligned), max %.2f mm; %d rows did not converge' % (
                     summary['rms_before'] * 1e3, summary['rms_after'] * 1e3,
                     summary['rms_aligned_after'] * 1e3, summary['max_after'] * 1e3,
                     summary['unconverged_rows']))
    if 'validate_rms' in summary:
        lines.append('held out %s: RMS %.2f mm (%.2f mm aligned), max %.2f mm' % (
            summary['validate'], summary['validate_rms'] * 1e3,
            summary['validate_rms_aligned'] * 1e3, summary['validate_max'] * 1e3))
    lines.extend('note: ' + note for note in summary.get('notes', ()))
    if summary['output']:
        lines.append('wrote %s' % summary['output'])
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())
