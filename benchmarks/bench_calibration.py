"""``python -m benchmarks.bench_calibration``: the v6 calibration and error budget.

On the FTDCR v6 robot's recorded runs (``test/data/ftdcr_v6``): the cost of one replay of the
training run by the calibrated robot (the unit of every fit), one Jacobian both ways (exact,
from the implicit-function theorem, against one replay per parameter) and the default fit
both ways, the default fit from the nominal robot file (wall time on every core, train and
held-out tip RMS, and the phases: scan, fit, validate ... with their wall and CPU
seconds), and the error budget on both files (repeatability floor, model-free
baselines, the model). With ``--select NAME ...``: the candidate physics cross-validated
inside the training run (whole motion patterns per fold; the held-out file is only reported,
never used to choose). With ``--fit NAME ...``: a fit of other names instead of the default
one. Figures, not assertions.
"""
import argparse
import time

import numpy as np

from benchmarks.shared import V6_COLUMNS, V6_DATA, V6_ROBOT
from continuum_statics import load_robot
from continuum_statics.calibration.error_budget import format_budget
from continuum_statics.calibration.parameters import DEFAULT_FIT
from continuum_statics.calibration.phases import cpu_seconds, format_phases
from continuum_statics.calibration.replay import replay
from continuum_statics.calibration.runs import calibrate_run, read_run
from continuum_statics.config_paths import config_file

#: The physical names beyond the default fit that the v6 run can see (no gravity recorded:
#: disk masses and, for the point-moment robot, extension and shear change nothing).
EXTRA_NAMES = ('pretension', 'cable_stiffness', 'youngs_modulus', 'gravity', 'tip_marker',
               'section_bending', 'stick_length', 'base_position')


def bench_replay(robot_file, repeats=3):
    """Print the wall time of one replay of the v6 training run (the fit's unit of work)."""
    robot = load_robot(robot_file)
    run = read_run(V6_DATA / 'train.csv', robot, V6_COLUMNS)
    replay(robot, run.subset(np.arange(20)))  # compiled kernels loaded
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        replay(robot, run)
        times.append(time.perf_counter() - start)
    best = min(times)
    print('replay of train.csv (%d rows, %s): %.2f s (%.0f us per row), best of %d'
          % (len(run), robot_file.name, best, best / len(run) * 1e6, repeats))
    return best


def bench_long_run(rows=1600):
    """Print the default fit's wall time on a ``rows``-row run made of the v6 training files.

    train.csv, then tendon_pull.csv, then train.csv again until ``rows``: training data only,
    a timing case (its errors are not a result).
    """
    import tempfile

    lines = (V6_DATA / 'train.csv').read_text().splitlines()
    header, body = lines[0], lines[1:]
    body += (V6_DATA / 'tendon_pull.csv').read_text().splitlines()[1:]
    while len(body) < rows:
        body += lines[1:]
    # the pieces restart their clocks: the rows are renumbered 0.6 s apart, as recorded
    body = ['%.1f,%s' % (0.6 * i, line.split(',', 1)[1]) for i, line in enumerate(body[:rows])]
    with tempfile.TemporaryDirectory() as folder:
        path = '%s/long_run.csv' % folder
        with open(path, 'w', encoding='utf-8') as stream:
            stream.write('\n'.join([header] + body) + '\n')
        start = time.perf_counter()
        summary = calibrate_run(V6_ROBOT, path, list(DEFAULT_FIT), V6_COLUMNS,
                                log=lambda line: None)
    print('default fit on a %d-row run (train, tendon_pull, train again): %.0f s wall, %d '
          'evaluations, RMS %.2f mm' % (rows, time.perf_counter() - start,
                                        summary['optimizer']['evaluations'],
                                        summary['rms_after'] * 1e3))


def bench_jacobians(fits=(DEFAULT_FIT, DEFAULT_FIT + EXTRA_NAMES)):
    """Print the cost of one Jacobian of train.csv both ways, and the default fit both ways.

    Implicit: :mod:`calibration.sensitivities` (one pass over the rows for every variable);
    differences: one replay per variable, each row started from the base replay's.
    """
    from continuum_statics.calibration.fit import evaluate_all
    from continuum_statics.calibration.pool import default_workers
    from continuum_statics.calibration.run_model import RunModel
    from continuum_statics.calibration.sensitivities import point_sensitivities

    robot = load_robot(config_file('ftdcr_v6_calibrated.yaml'))
    run = read_run(V6_DATA / 'train.csv', robot, V6_COLUMNS)
    workers = default_workers()
    for names in fits:
        model = RunModel(robot, list(names), run)
        x = model.start()
        model.residuals(x, update=True)
        solutions, points = model.solutions, model.replayed
        start = time.perf_counter()
        model.jacobian(x, points, point_sensitivities(model, x, solutions, workers))
        implicit = time.perf_counter() - start
        steps = model.vector.steps()
        start = time.perf_counter()
        evaluate_all(model, [x + steps[i] * np.eye(model.size)[i] for i in range(model.size)],
                     workers, solutions)
        differences = time.perf_counter() - start
        print('one Jacobian of train.csv, %d variables, %d workers: implicit %.2f s, finite '
              'differences %.2f s' % (model.size, workers, implicit, differences))
    for jacobian in ('implicit', 'differences'):
        start = time.perf_counter()
        summary = calibrate_run(V6_ROBOT, V6_DATA / 'train.csv', list(DEFAULT_FIT), V6_COLUMNS,
                                validate=V6_DATA / 'val.csv', log=lambda line: None,
                                jacobian=jacobian)
        print('default fit, %s Jacobians: %.0f s wall, %d evaluations, train %.3f mm, held out '
              '%.3f mm (%.3f aligned)' % (
                  jacobian, time.perf_counter() - start, summary['optimizer']['evaluations'],
                  summary['rms_after'] * 1e3, summary['validate_rms'] * 1e3,
                  summary['validate_rms_aligned'] * 1e3))


def bench_fit(fit, candidates=()):
    """Fit the nominal v6 file to train.csv; print the figures and the error budget."""
    start, cpu = time.perf_counter(), cpu_seconds()
    summary = calibrate_run(V6_ROBOT, V6_DATA / 'train.csv', list(fit), V6_COLUMNS,
                            validate=V6_DATA / 'val.csv', log=lambda line: None, report=True,
                            candidates=candidates)
    wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
    if 'selection' in summary:
        selection = summary['selection']
        print('\nselection, cross-validated inside train.csv (3 folds of whole motion '
              'patterns): base %.2f mm' % (selection['base'] * 1e3))
        for name, score in selection['candidates'].items():
            print('  + %-16s %.2f mm%s' % (name, score * 1e3,
                                           '  kept' if name in selection['kept'] else ''))
        print('  chosen: %s (%.2f mm)' % (' '.join(selection['fit']), selection['selected'] * 1e3))
    print('\nv6 fit (%s): %.1f s wall, %.1f s CPU (this process and its workers), %d '
          'evaluations, %d parameters' % (
              ', '.join(summary['fit']), wall, cpu, summary['optimizer']['evaluations'],
              sum(np.size(v['after']) for v in summary['fitted'].values())))
    print('  phases (the file as given is replayed in a process of its own during scan and '
          'fit; its CPU counts where it ends):')
    print(format_phases(summary['phases']))
    print('  train RMS: file as given %.1f mm -> %.2f mm (%.2f mm aligned)' % (
        summary['rms_before'] * 1e3, summary['rms_after'] * 1e3,
        summary['rms_aligned_after'] * 1e3))
    print('  held-out RMS: %.3f mm (%.3f mm aligned)' % (
        summary['validate_rms'] * 1e3, summary['validate_rms_aligned'] * 1e3))
    print(format_budget(summary['error_budget']))
    return summary


def main(argv=None):
    """Run the benchmark; returns 0."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.bench_calibration')
    parser.add_argument('--fit', nargs='+', default=list(DEFAULT_FIT), metavar='PARAM')
    parser.add_argument('--select', nargs='+', default=(), metavar='PARAM',
                        help='candidate names cross-validated inside train.csv (minutes each)')
    parser.add_argument('--long', action='store_true',
                        help='also time the default fit on a 1600-row run of training data')
    args = parser.parse_args(argv)
    print('continuum_statics calibration benchmark (FTDCR v6, %s)' % V6_DATA)
    bench_replay(config_file('ftdcr_v6_calibrated.yaml'))  # a candidate near the fit's end
    bench_jacobians()
    if args.long:
        bench_long_run()
    bench_fit(args.fit, args.select)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())

