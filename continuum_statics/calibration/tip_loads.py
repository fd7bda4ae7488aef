"""Calibration from static tip-load rows: known tip loads and measured tip positions.

Each CSV row is one static experiment: a known tip load and the measured tip position, both in
the base frame (header ``tip_force_x,tip_force_y,tip_force_z,tip_x,tip_y,tip_z``; N and m;
optional ``tip_moment_x..z`` in N m; optional one column per cable name with the measured cable
length in m; lines starting with ``#`` are comments). The model tip of a row is the passive
boundary-value solution under that load (``Robot.solve_bvp``) or, when cable lengths are given,
the shape estimated from them (``Robot.estimate_shape``); every solve is warm-started from the
same row's previous solution. Fit names: :data:`parameters.TIP_LOAD_PARAMETERS`.
"""
import csv
import dataclasses
import math
import sys
import time

import numpy as np
from scipy.optimize import least_squares

from continuum_statics.calibration import summary as summaries
from continuum_statics.calibration.parameters import SearchVector, check_names
from continuum_statics.calibration.recorded_run import check_tip_units
from continuum_statics.calibration.replay import FAILED_ROW_ERROR, error_statistics
from continuum_statics.calibration.robot_writer import write_robot_file
from continuum_statics.core.statics.bvp import ConvergenceError

FORCE_COLUMNS = ('tip_force_x', 'tip_force_y', 'tip_force_z')
MOMENT_COLUMNS = ('tip_moment_x', 'tip_moment_y', 'tip_moment_z')
TIP_COLUMNS = ('tip_x', 'tip_y', 'tip_z')
#: A long fit prints a progress line this often, s (stderr).
PROGRESS_S = 5.0
#: Names that need a column per cable.
NEEDS_CABLES = ('cable_offset_scale',)


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

    return Measurements(
        tip_forces=table(FORCE_COLUMNS), tip_moments=table(MOMENT_COLUMNS, 0.0),
        tips=table(TIP_COLUMNS), cable_lengths=table(cable_names) if cables else None,
        ignored_columns=tuple(c for c in header if c not in known))


class TipLoadModel:
    """Candidate robots of a search vector and their tip predictions (warm-started per row)."""

    def __init__(self, robot, fit, data, shear_fixed=False):
        self.robot = robot
        self.vector = SearchVector(robot, fit, shear_fixed)
        self.data = data
        self.warm = [None] * len(data.tips)
        self.evaluations = 0
        self._started = self._reported = time.monotonic()

    def tips(self, robot, remember=True):
        """Model tip positions (n, 3) in m; rows that do not solve get NaN."""
        data = self.data
        tips = np.full(data.tips.shape, np.nan)
        for i in range(len(data.tips)):
            for warm in (self.warm[i], None):
                try:
                    if data.cable_lengths is None:
                        shape = robot.solve_bvp(tip_force=data.tip_forces[i],
                                                tip_moment=data.tip_moments[i], warm_start=warm)
                    else:
                        shape = robot.estimate_shape(
                            data.cable_lengths[i], tip_force=data.tip_forces[i],
                            warm_start=warm, tip_moment=data.tip_moments[i],
                            exact=True).shape  # a fit's model: to the solver's tolerance
                except (ConvergenceError, ValueError):
                    continue
                if np.all(np.isfinite(shape.tip_position)):
                    tips[i] = shape.tip_position
                    if remember:
                        self.warm[i] = shape
                    break
        return tips

    def residuals(self, x):
        """Model minus measured tip positions, flattened (m)."""
        # every evaluation starts from the same warm starts (the file's solutions): a residual
        # that depends on the order of evaluations spoils the finite-difference Jacobian
        errors = self.tips(self.vector.robot_for(x), remember=False) - self.data.tips
        self.evaluations += 1
        now = time.monotonic()
        if now - self._reported >= PROGRESS_S:  # a long fit says it is alive (stderr)
            self._reported = now
            print('calibrate: %d model evaluations of %d rows, %.0f s, tip RMS %.3f mm'
                  % (self.evaluations, len(errors), now - self._started,
                     1e3 * math.sqrt(np.nanmean(np.sum(errors ** 2, axis=1)))),
                  file=sys.stderr, flush=True)
        return np.nan_to_num(errors, nan=FAILED_ROW_ERROR).ravel()


def calibrate_tip_loads(robot_file, data_file, fit, output=None):
    """Fit ``fit`` (fit names) to tip-load rows; write ``output``; return the summary (m).

    :raises ValueError: unreadable files, unknown parameters, missing columns, or parameters
        the data do not determine (nothing is written then)
    """
    from continuum_statics import load_robot

    check_names(fit, 'tip_loads')
    robot = load_robot(robot_file)
    data = read_measurements(data_file, robot.cable_names)
    needs_cables = [n for n in fit if n in NEEDS_CABLES]
    if needs_cables and data.cable_lengths is None:
        raise ValueError('%s needs measured cable lengths: the data has no column per cable (%s)'
                         % (', '.join(needs_cables), ', '.join(robot.cable_names) or 'no cables'))
    check_tip_units(data.tips, robot.length, data_file, 'the tip columns are in m')
    names = list(dict.fromkeys(fit))
    distinct = len(np.unique(np.column_stack([
        data.tip_forces, data.tip_moments, data.tips,
        *(() if data.cable_lengths is None else (data.cable_lengths,))]), axis=0))
    if distinct < len(names) + 1:
        raise ValueError('%d distinct row(s) (of %d) cannot determine %d parameter(s) and their '
                         'uncertainty: measure at least %d different tip loads or poses'
                         % (distinct, len(data.tips), len(names), len(names) + 1))
    model = TipLoadModel(robot, names, data, summaries.shear_fixed(robot_file))
    vector = model.vector
    before = model.tips(robot)
    if not np.all(np.isfinite(before)):
        bad = [int(i) + 1 for i in np.flatnonzero(~np.all(np.isfinite(before), axis=1))]
        raise ValueError("the robot file's model does not solve data rows %s" % bad)
    low, high = vector.bounds()
    began = time.monotonic()
    result = least_squares(model.residuals, vector.start(), bounds=(low, high),
                           x_scale='jac', diff_step=1e-5, xtol=1e-10, ftol=1e-12, gtol=1e-12,
                           max_nfev=200)
    fitted = vector.robot_for(result.x)
    after = model.tips(fitted)
    fitted_values = summaries.fitted_values(vector, result.x, result.jac, result.fun,
                                            (low, high))
    summaries.refuse_undetermined(vector, fitted_values, result.jac, result.fun, (low, high))
    summary = {
        'kind': 'tip_loads', 'robot': str(robot_file), 'data': str(data_file),
        'rows': int(len(data.tips)),
        'model': 'estimate_shape (cable lengths)' if data.cable_lengths is not None
        else 'solve_bvp (passive rod)',
        'fit': list(vector.fit), 'fitted': fitted_values,
        **summaries.before_after(before - data.tips, after - data.tips),
        'tip_error_before': summaries.legacy_errors(before - data.tips),
        'tip_error_after': summaries.legacy_errors(after - data.tips),
        'optimizer': {'success': bool(result.success), 'evaluations': int(result.nfev),
                      'message': str(result.message)},
        'seconds': round(time.monotonic() - began, 1),
        'ignored_columns': list(data.ignored_columns),
        'output': None if output is None else str(output),
    }
    if output is not None:
        write_robot_file(output, robot_file, fitted, vector.fit, summaries.header(summary))
        check = load_robot(output)
        written = TipLoadModel(check, names, data).tips(check) - data.tips
        summary['rms_written_file'] = error_statistics(written)['rms']
        summary['tip_error_written_file'] = summaries.legacy_errors(written)
    return summary
