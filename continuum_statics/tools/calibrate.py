"""``python -m continuum_statics calibrate``: fit robot-file parameters to measured tip positions.

Two data kinds, one library (:mod:`continuum_statics.calibration`): static rows of known tip
loads (:mod:`~continuum_statics.calibration.tip_loads`) and recorded runs of cable lengths and a
tracked tip (:mod:`~continuum_statics.calibration.runs`). This module parses the command line and
prints; recorded runs get the error budget (repeatability floor, smooth baselines, the model)
by default, the yardstick the model's RMS is read against (``--no-report`` leaves it out).
"""
import argparse
import json
import os
import sys

import numpy as np

from continuum_statics.calibration.damping import calibrate_damping
from continuum_statics.calibration.error_budget import format_budget
from continuum_statics.calibration.parameters import (
    DEFAULT_FIT,
    RUN_PARAMETERS,
    TIP_LOAD_PARAMETERS,
)
from continuum_statics.calibration.recorded_run import add_column_arguments, column_map_from_args
from continuum_statics.calibration.runs import calibrate_run
from continuum_statics.calibration.summary import unit_label
from continuum_statics.calibration.tip_loads import FORCE_COLUMNS, calibrate_tip_loads


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


def _positive_int(text):
    """Argparse type: an integer >= 1 (0 evaluations cannot fit anything)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError('%r is not an integer' % text)
    if value < 1:
        raise argparse.ArgumentTypeError('must be at least 1, got %d' % value)
    return value


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
                             '%s (default %s); damping: a recorded step or release, alone'
                             % (', '.join(TIP_LOAD_PARAMETERS), ', '.join(RUN_PARAMETERS),
                                ' '.join(DEFAULT_FIT)))
    parser.add_argument('--output', '-o', default=None,
                        help='calibrated robot file to write (default: none, report only)')
    parser.add_argument('--validate', default=None, metavar='FILE',
                        help='recorded runs: held-out run to report the errors on (never fitted)')
    parser.add_argument('--tip-topic', default='tip_pose_measured',
                        help='recorded runs in a bag: the measured tip topic (PoseStamped)')
    parser.add_argument('--max-evaluations', type=_positive_int, default=40,
                        help='recorded runs: most model evaluations of the fit (default 40)')
    parser.add_argument('--select', nargs='+', metavar='PARAM', default=(),
                        help='recorded runs: candidate fit names added to --fit only where they '
                             'lower the error cross-validated inside the run (by motion '
                             'pattern; the --validate file is never used to choose)')
    # on by default: 0.16 s on the v6 run (1019 + 274 rows, 9 cables) beside an 18 s fit, and
    # without it an RMS of 11 mm cannot be told good from bad (issue 44)
    parser.add_argument('--report', action=argparse.BooleanOptionalAction, default=True,
                        help='recorded runs: the error budget (repeatability floor, smooth '
                             'baselines of the motor positions, the model) in the report '
                             '(default on; --no-report leaves it out)')
    parser.add_argument('--model-uncertainty', action='store_true',
                        help="recorded runs: also measure the model's own error on the run "
                             '(unmodelled loads and their correlation time) and write it as '
                             'model_uncertainty, for state estimation with sensors')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    add_column_arguments(parser)
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    try:
        column_map = column_map_from_args(args)
        if args.fit and 'damping' in args.fit:  # a step or release: the rod in motion
            if set(args.fit) != {'damping'}:
                raise ValueError('--fit damping is fitted alone, on a recorded step or release '
                                 '(the static parameters first, on a slow run)')
            summary = calibrate_damping(args.robot, args.data, column_map, args.output,
                                        args.tip_topic)
            print(json.dumps(summary) if args.json else _damping_report(summary))
            return 0
        if is_recorded_run(args.data, column_map):
            log = (lambda text: print(text, file=sys.stderr)) if args.json else print
            summary = calibrate_run(
                args.robot, args.data, args.fit or list(DEFAULT_FIT), column_map, args.output,
                args.validate, args.tip_topic, log, args.max_evaluations, args.report,
                candidates=args.select, uncertainty=args.model_uncertainty)
            print(json.dumps(summary) if args.json else _run_report(summary))
            return 0
        summary = calibrate_tip_loads(args.robot, args.data, args.fit or ['youngs_modulus'],
                                      args.output)
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
            name, f['before'], f['after'], unit_label(f['unit']), f['std'],
            '  AT BOUND' if f['at_bound'] else ''))
    print('tip error before: mean %.3f mm, max %.3f mm' % (summary['mean_before'] * 1e3,
                                                           summary['max_before'] * 1e3))
    print('tip error after:  mean %.3f mm, max %.3f mm' % (summary['mean_after'] * 1e3,
                                                           summary['max_after'] * 1e3))
    if summary['ignored_columns']:
        print('note: ignored columns %s' % ', '.join(summary['ignored_columns']))
    if args.output:
        print('wrote %s' % args.output)
    return 0


def _damping_report(summary):
    fitted = summary['fitted']['damping']
    lines = ['calibrate: damping from %s (%d samples, %d simulations)' % (
        summary['data'], summary['samples'], summary['evaluations']),
        '  rod.damping.bending %.4g -> %.4g N m^2 s (first-mode damping ratio %.4f)' % (
            fitted['before'], fitted['after'], fitted['first_mode_damping_ratio']),
        '  tip displacement rms %.3f mm -> %.3f mm' % (1e3 * summary['rms_before'],
                                                        1e3 * summary['rms_after'])]
    if summary['output']:
        lines.append('wrote %s' % summary['output'])
    return '\n'.join(lines)


def _coupled_notes(fitted):
    """Return notes on fitted values that act only together with another (issue 38)."""
    notes = []
    if 'stick_length' in fitted:
        if 'friction' not in fitted:
            notes.append("stick_length acts only through friction, which was not fitted: it "
                         "is determined only where the file's friction is not 0")
        elif not np.any(np.abs(np.atleast_1d(fitted['friction']['after'])) > 0.0):
            notes.append('stick_length acts only through friction, which was fitted to 0: its '
                         'value is not determined by the data')
    if 'gravity' in fitted:
        notes.append("gravity acts only through the rod's and disks' weight (density times "
                     "g, eqs. 3-4): a gravity fit moves the weight, not g and the density "
                     "apart; check both in the written file against the rod you have")
    return notes


def _run_report(summary):
    """Plain-text report of a recorded-run calibration."""
    lines = ['fitted (%s, %d evaluations, %.0f s):' % (
        summary['optimizer']['message'], summary['optimizer']['evaluations'],
        summary['seconds'])]
    undetermined = []
    for name, value in summary['fitted'].items():
        after, sigma = (np.atleast_1d(np.asarray(value.get(key, np.nan), dtype=float))
                        for key in ('after', 'std'))
        lines.append('  %-17s %s %s (1-sigma %s)' % (
            name, ' '.join('%.5g' % v for v in after), unit_label(value['unit']),
            ' '.join('%.2g' % v for v in sigma)))
        # a value whose 1-sigma reaches its own size: the data do not determine it
        if np.any(~(sigma < np.abs(after))):
            undetermined.append(name)
    if undetermined:
        lines.append('note: the data do not determine %s (1-sigma >= the value): the written '
                     'file carries them, check before using it' % ', '.join(undetermined))
    lines.extend('note: ' + note for note in _coupled_notes(summary['fitted']))
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
    if 'selection' in summary:
        selection = summary['selection']
        lines.append('selection (cross-validated inside the run): base %.2f mm; %s; kept: %s' % (
            selection['base'] * 1e3, ', '.join('+%s %.2f mm' % (name, score * 1e3) for
                                               name, score in selection['candidates'].items()),
            ', '.join(selection['kept']) or 'none'))
    if 'error_budget' in summary:
        lines.append(format_budget(summary['error_budget']))
    else:
        lines.append('note: no error budget (--no-report): without its repeatability floor '
                     'and model-free baselines the tip RMS above has no yardstick')
    if 'model_uncertainty' in summary:
        u = summary['model_uncertainty']
        lines.append("model_uncertainty (the model's own error, tracker sigma %.2g m):"
                     ' tip force %.3g N, tip moment %.3g N m, cable length %.3g mm, base '
                     'offset %.3g mm, correlation time %.3g s' % (
                         u['tracker_noise'], u.get('tip_force', 0.0),
                         u.get('section_moment', 0.0), 1e3 * u.get('cable_length', 0.0),
                         1e3 * u.get('base_position', 0.0), u['correlation_time']))
        if u.get('drift'):
            lines[-1] += ', drift %.3g mm over %.3g s' % (1e3 * u['drift'], u['drift_time'])
        if u.get('point_noise'):
            lines[-1] += ', point noise %.3g mm at the tip' % (1e3 * u['point_noise'])
        if u.get('sensors'):
            lines[-1] += '; measured at the tip and at %s' % ', '.join(u['sensors'])
    if summary['output']:
        lines.append('wrote %s' % summary['output'])
    return '\n'.join(lines)


if __name__ == '__main__':
    sys.exit(main())
