"""The calibration summary, one schema for both data kinds (SI units: m, N, Pa, rad).

Keys every summary has: ``kind`` ('run' or 'tip_loads'), ``robot``, ``data``, ``rows``,
``model``, ``fit`` (names), ``fitted`` (name -> {before, after, std, unit, at_bound}; a
number for a one-value name, a list per section or cable otherwise), ``rms_before``,
``rms_after``, ``rms_aligned_after`` (the mean offset removed), ``mean_before``,
``mean_after``, ``max_before``, ``max_after`` (m, Euclidean tip errors), ``optimizer``,
``seconds``, ``output``. Recorded runs add ``registration``, ``unconverged_rows``, ``notes``,
with ``--validate`` ``validate_rms``, ``validate_rms_aligned``, ``validate_max`` and with
``report`` (the command's default) the ``error_budget``. Tip loads add ``tip_error_before`` /
``tip_error_after`` ({mean_mm, max_mm}), kept for scripts written against the first releases.
"""
import numpy as np
import yaml

from continuum_statics.calibration.fit import standard_errors
from continuum_statics.calibration.replay import error_statistics

#: A parameter whose 1-sigma exceeds this fraction of its bounds' width is not determined.
UNDETERMINED = 0.5
#: A capstan coefficient below this changes a tension by < 0.3 % over a half turn: none.
NEGLIGIBLE_FRICTION = 1e-3


def unit_label(unit):
    """Return the unit as a report prints it: 'dimensionless' for a value's ``'1'`` (SI).

    Printed bare, ``friction 7.3e-11 1`` read as a second value (issue 44).
    """
    return 'dimensionless' if unit == '1' else unit


def shear_fixed(robot_file):
    """Tell whether the robot file gives ``rod.shear_modulus`` (G then stays when E is fitted)."""
    with open(robot_file, encoding='utf-8') as stream:
        document = yaml.safe_load(stream) or {}
    return 'shear_modulus' in (document.get('rod') or {})


def fitted_values(vector, x, jacobian, residuals, bounds):
    """Return the summary's ``fitted``: file value, fitted value, 1-sigma, unit, at bound."""
    from continuum_statics.calibration.parameters import UNITS
    before = vector.values(vector.start())
    after = vector.values(x)
    sigma = standard_errors(jacobian, residuals, vector.derivatives(x))
    low, high = bounds
    at_bound = np.isclose(x, low) | np.isclose(x, high)
    out = {}
    for block in vector.blocks:
        index = block.index
        out[block.name] = {
            'before': _plain(before[block.name]), 'after': _plain(after[block.name]),
            'std': _plain(sigma[index]), 'unit': UNITS[block.name],
            'at_bound': _plain(at_bound[index], bool)}
    return out


def refuse_undetermined(vector, fitted, jacobian, residuals, bounds):
    """Raise ``ValueError`` naming the variables whose 1-sigma spans half their bounds or more."""
    sigma = standard_errors(jacobian, residuals)
    low, high = bounds
    bad = [i for i in range(vector.size) if not sigma[i] <= UNDETERMINED * (high[i] - low[i])]
    if not bad:
        return
    names = [b.name for b in vector.blocks for _ in range(b.start.size)]
    raise ValueError('the data do not determine %s (1-sigma %s, bounds %s): add rows with '
                     'other tip loads or poses' % (
                         ', '.join(dict.fromkeys(names[i] for i in bad)),
                         ', '.join('%.3g' % sigma[i] for i in bad),
                         ', '.join('[%g, %g]' % (low[i], high[i]) for i in bad)))


def before_after(errors_before, errors_after):
    """Return the summary's error keys of point errors (n, 3) before and after the fit (m)."""
    before, after = error_statistics(errors_before), error_statistics(errors_after)
    out = {'rms_before': before['rms'], 'rms_after': after['rms'],
           'rms_aligned_after': after['rms_aligned'], 'mean_before': before['mean'],
           'mean_after': after['mean'], 'max_before': before['max'], 'max_after': after['max']}
    return out


def legacy_errors(errors):
    """{mean_mm, max_mm} of point errors (n, 3): the first releases' tip-load keys."""
    stats = error_statistics(errors)
    return {'mean_mm': stats['mean'] * 1e3, 'max_mm': stats['max'] * 1e3}


def notes(fitted):
    """Return notes on fitted values that are not what they look like (e.g. friction ~ 0)."""
    out = []
    friction = fitted.get('friction')
    if friction is not None and friction['after'] < NEGLIGIBLE_FRICTION:
        out.append('friction: the data show none (fitted %.2g; below %g the capstan effect is '
                   'under 0.3 %% per half turn of wrap)' % (friction['after'],
                                                            NEGLIGIBLE_FRICTION))
    return out


def header(summary):
    """Return the written robot file's comment lines: what was fitted from what, the errors."""
    lines = ['from %s, fitted to %d rows of %s (%s);' % (
        summary['robot'], summary['rows'], summary['data'], summary['model'])]
    parts = []
    for name, value in summary['fitted'].items():
        after, std = np.atleast_1d(value['after']), np.atleast_1d(value['std'])
        parts.append('%s %s %s (1-sigma %s)' % (
            name, ' '.join('%.5g' % v for v in after), unit_label(value['unit']),
            ' '.join('%.2g' % v for v in std)))
    names = ', '.join(summary['fit'])
    lines.append('fitted: %s.' % names)
    lines.extend('  %s' % part for part in parts)
    lines.append('Tip RMS %.2f mm (file as given) -> %.2f mm (%.2f mm mean-offset aligned), mean '
                 '%.3f -> %.3f mm, max %.3f -> %.3f mm.' % (
                     summary['rms_before'] * 1e3, summary['rms_after'] * 1e3,
                     summary['rms_aligned_after'] * 1e3, summary['mean_before'] * 1e3,
                     summary['mean_after'] * 1e3, summary['max_before'] * 1e3,
                     summary['max_after'] * 1e3))
    if 'validate_rms' in summary:
        lines.append('Held out %s (%d rows): RMS %.2f mm (%.2f mm aligned).' % (
            summary['validate'], summary['validate_rows'], summary['validate_rms'] * 1e3,
            summary['validate_rms_aligned'] * 1e3))
    uncertainty = summary.get('model_uncertainty')
    if uncertainty and uncertainty.get('cross_validated'):
        lines.append('model_uncertainty from residuals cross-validated inside the run (each '
                     'motion pattern by a fit without it): RMS %.2f mm.' % (
                         uncertainty['residual_rms'] * 1e3))
    return lines


def _plain(values, kind=float):
    values = np.atleast_1d(values)
    return kind(values[0]) if values.size == 1 else [kind(v) for v in values]
