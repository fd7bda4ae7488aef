"""How much of a calibrated model's tip error is the robot's, how much the model's.

Three figures side by side, for a training run and a held-out run:

- **repeatability floor**: pairs of rows whose motor positions agree within ``tolerance`` (every
  cable, m) yet whose tips differ. No function of the motor positions predicts both, so a model
  of the motor positions alone cannot get below about sqrt(mean |d|^2 / 2) per row;
- **smooth baselines**: the best a model-free function of the motor positions reaches, trained
  on the training run and evaluated on the held-out one (k nearest neighbours; ridge regression
  on polynomials of the lengths). Their settings (k; degree, ridge) are chosen by
  cross-validation inside the training run, split by motion pattern, never on the held-out run;
- **the physical model** (the calibrated robot's errors, given by the caller).

The model's own share is then about sqrt(model^2 - floor^2).
"""
from itertools import combinations_with_replacement
import re

import numpy as np
from scipy.spatial import cKDTree

from continuum_statics.calibration.replay import error_statistics, rms, rms_aligned

#: m: two rows whose every motor position agrees within this are "the same command".
SAME_COMMAND = 2.5e-4
#: Neighbour counts and (degree, ridge) settings the cross-validation chooses from.
NEIGHBOURS = (1, 2, 3, 5, 8, 12)
POLYNOMIALS = tuple((d, r) for d in (1, 2, 3) for r in (1e-3, 1e-2, 1e-1, 1.0, 10.0))
#: Cross-validation folds over the motion patterns.
FOLDS = 5


def repeatability(lengths, tips, tolerance=SAME_COMMAND):
    """Repeatability of a run: {pairs, pair_rms, per_row, pair_median} (m).

    :param lengths: (n, n_cables) motor-side lengths, m
    :param tips: (n, 3) measured tips, m
    """
    pairs = cKDTree(lengths).query_pairs(tolerance, p=np.inf, output_type='ndarray')
    if len(pairs) == 0:
        return {'pairs': 0, 'pair_rms': None, 'per_row': None, 'pair_median': None}
    d = np.linalg.norm(tips[pairs[:, 0]] - tips[pairs[:, 1]], axis=1)
    return {'pairs': int(len(pairs)), 'pair_rms': float(np.sqrt(np.mean(d ** 2))),
            'per_row': float(np.sqrt(np.mean(d ** 2) / 2.0)),
            'pair_median': float(np.median(d))}


def pattern_groups(labels):
    """Motion-pattern index of each row: its label without ``repN_`` and a phase suffix.

    ``rep2_seg1_dir90_hold`` and ``rep1_seg1_dir90`` are one pattern; unlabelled runs are cut
    into ten consecutive blocks instead.
    """
    keys = [re.sub(r'_(hold|pull|release)$', '', re.sub(r'^rep\d+_', '', str(label)))
            for label in labels]
    if not any(keys):
        return np.arange(len(keys)) * 10 // max(len(keys), 1)
    index = {key: i for i, key in enumerate(dict.fromkeys(keys))}
    return np.array([index[key] for key in keys])


def folds(groups, count=FOLDS):
    """Fold of each row: whole patterns, dealt round-robin in order of appearance."""
    order = {g: i for i, g in enumerate(dict.fromkeys(groups.tolist()))}
    return np.array([order[g] % count for g in groups.tolist()])


class Neighbours:
    """Mean tip of the k training rows with the nearest motor positions."""

    def __init__(self, k):
        self.k = k

    def fit(self, lengths, tips):
        """Keep the training rows (lengths (n, c) m, tips (n, 3) m)."""
        self.tree, self.tips = cKDTree(lengths), tips
        return self

    def predict(self, lengths):
        """Predicted tips (m, 3) of motor lengths (m, c)."""
        k = min(self.k, len(self.tips))
        _, index = self.tree.query(lengths, k=k)
        return self.tips[np.reshape(index, (len(lengths), k))].mean(axis=1)


class Polynomial:
    """Ridge regression of the tip on the monomials of the scaled lengths up to ``degree``."""

    def __init__(self, degree, ridge):
        self.degree, self.ridge = degree, ridge

    def _features(self, lengths):
        z = (lengths - self.centre) / self.scale
        columns = [np.ones(len(z))]
        for d in range(1, self.degree + 1):
            for combination in combinations_with_replacement(range(z.shape[1]), d):
                columns.append(np.prod(z[:, combination], axis=1))
        return np.column_stack(columns)

    def fit(self, lengths, tips):
        """Solve the ridge normal equations on the training rows (m)."""
        self.centre = lengths.mean(axis=0)
        self.scale = max(float(np.max(np.abs(lengths - self.centre))), 1e-12)
        a = self._features(lengths)
        self.weights = np.linalg.solve(a.T @ a + self.ridge * np.eye(a.shape[1]), a.T @ tips)
        return self

    def predict(self, lengths):
        """Predicted tips (m, 3) of motor lengths (m, c)."""
        return self._features(lengths) @ self.weights


def cross_validated(make, settings, lengths, tips, fold):
    """Return the setting with the lowest cross-validated RMS, and that RMS (m)."""
    best = None
    for setting in settings:
        errors = np.zeros_like(tips)
        for f in np.unique(fold):
            test = fold == f
            errors[test] = make(setting).fit(lengths[~test], tips[~test]).predict(
                lengths[test]) - tips[test]
        score = rms(errors)
        if best is None or score < best[1]:
            best = (setting, score)
    return best


def error_budget(train, held_out=None, model_errors=None, tolerance=SAME_COMMAND):
    """Return the error budget of a run (and a held-out run): floor, smooth baselines, the model.

    :param train: a :class:`recorded_run.RecordedRun` (lengths m, tips m, labels)
    :param held_out: the held-out run, or None (the baselines then report their CV error)
    :param model_errors: {'train': (n, 3), 'held_out': (m, 3)} model minus measured (m)
    :returns: a dict of figures in m (the summary's ``error_budget``)
    """
    runs = {'train': train} if held_out is None else {'train': train, 'held_out': held_out}
    budget = {'same_command_tolerance': tolerance,
              'repeatability': {name: repeatability(run.lengths, run.tips, tolerance)
                                for name, run in runs.items()}}
    fold = folds(pattern_groups(train.labels))
    baselines = {}
    for name, make, settings in (
            ('nearest_neighbours', lambda k: Neighbours(k), NEIGHBOURS),
            ('polynomial_ridge', lambda s: Polynomial(*s), POLYNOMIALS)):
        setting, cv = cross_validated(make, settings, train.lengths, train.tips, fold)
        entry = {'setting': setting if np.isscalar(setting) else list(setting),
                 'train_cv_rms': cv}
        if held_out is not None:
            errors = make(setting).fit(train.lengths, train.tips).predict(
                held_out.lengths) - held_out.tips
            entry.update(held_out_rms=rms(errors), held_out_rms_aligned=rms_aligned(errors))
        baselines[name] = entry
    budget['baselines'] = baselines
    if model_errors:
        model = {}
        for name, errors in model_errors.items():
            floor = budget['repeatability'].get(name, {}).get('per_row')
            stats = error_statistics(errors)  # a row that did not solve counts as failed
            model[name] = {'rms': stats['rms'], 'rms_aligned': stats['rms_aligned'],
                           'beyond_floor': None if floor is None else float(
                               np.sqrt(max(stats['rms_aligned'] ** 2 - floor ** 2, 0.0)))}
        budget['model'] = model
    return budget


def format_budget(budget):
    """Plain-text table of an error budget (mm)."""
    mm = lambda value: '—' if value is None else '%.2f' % (value * 1e3)  # noqa: E731
    lines = ['error budget (tip RMS per row, mm; motor positions within %.2f mm count as the '
             'same command):' % (budget['same_command_tolerance'] * 1e3)]
    for name, entry in budget['repeatability'].items():
        lines.append('  repeatability floor, %-10s %s (%d pairs, pair RMS %s, median %s)' % (
            name + ':', mm(entry['per_row']), entry['pairs'], mm(entry['pair_rms']),
            mm(entry['pair_median'])))
    for name, entry in budget['baselines'].items():
        text = '  %s (%s): train CV %s' % (name.replace('_', ' '), entry['setting'],
                                           mm(entry['train_cv_rms']))
        if 'held_out_rms' in entry:
            text += ', held out %s (%s aligned)' % (mm(entry['held_out_rms']),
                                                    mm(entry['held_out_rms_aligned']))
        lines.append(text)
    for name, entry in budget.get('model', {}).items():
        lines.append('  physical model, %-10s %s (%s aligned); beyond the floor about %s' % (
            name + ':', mm(entry['rms']), mm(entry['rms_aligned']), mm(entry['beyond_floor'])))
    return '\n'.join(lines)
