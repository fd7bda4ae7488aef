"""Which fit names to keep, chosen by cross-validation inside the training run.

The training run is split by motion pattern (:func:`error_budget.pattern_groups`, whole patterns
per fold): each fold is fitted on the other folds' rows and scored on its own, with the
registration of that fit. A candidate name is kept when adding it to the base fit lowers the
cross-validated tip RMS by at least :data:`MIN_GAIN`; the held-out run never takes part.
"""
import dataclasses

import numpy as np

from continuum_statics.calibration.error_budget import folds, pattern_groups
from continuum_statics.calibration.fit import fit
from continuum_statics.calibration.replay import error_statistics
from continuum_statics.calibration.run_model import RunModel

#: Folds of the cross-validation (whole motion patterns each).
SELECTION_FOLDS = 3
#: Relative drop of the cross-validated RMS a candidate must bring to be kept.
MIN_GAIN = 0.01
#: A candidate whose every variable, moved by its finite-difference step, moves no model tip by
#: more than this (m) changes nothing on the run (disk masses without gravity): not scored,
#: because its score would differ from the base's only by the fit's path.
INERT_MOTION = 1e-12
#: Rows of the run that test a candidate's effect (evenly spread).
INERT_ROWS = 100
#: Capstan coefficient with which a stick length is tested on a frictionless file.
STICK_FRICTION = 0.1


def cross_validated_rms(robot, run, fit_names, count=SELECTION_FOLDS, log=print, workers=None,
                        max_evaluations=40, shear_fixed=False):
    """Tip RMS (m) of every row predicted by a fit that did not see its motion pattern."""
    groups = pattern_groups(run.labels)
    if len(np.unique(groups)) < 2:
        raise ValueError('cross-validation needs at least 2 motion patterns in the run (labels '
                         'or, unlabelled, 10 blocks of rows); %d found' % len(np.unique(groups)))
    fold = folds(groups, count)
    errors = np.zeros_like(run.tips)
    for f in range(count):
        test = fold == f
        if not np.any(test):
            continue
        model = RunModel(robot, fit_names, run.subset(~test), shear_fixed)
        result = fit(model, log=lambda line: None, workers=workers,
                     max_evaluations=max_evaluations)
        errors[test] = model.errors(result.x, run.subset(test))[0]
    score = error_statistics(errors)['rms']  # a row that did not solve counts as failed
    log('  cross-validated (%d folds by motion pattern) %s: %.2f mm'
        % (count, ' '.join(fit_names), score * 1e3))
    return score


def moves_the_tips(robot, run, name, shear_fixed=False):
    """Whether fit name ``name`` changes any model tip of ``run`` (m, :data:`INERT_MOTION`).

    ``stick_length`` acts through friction, which its fit scans with it: it is tried with a
    friction of :data:`STICK_FRICTION` where the file has none, on every row (a subset would
    change the travel between rows, which the friction state follows).
    """
    if name == 'stick_length':
        sample = run
        if not robot.tendons.has_friction:
            tendons = dataclasses.replace(robot.tendons, friction=np.full(
                len(robot.cable_names), STICK_FRICTION))
            robot = robot.__class__(dataclasses.replace(robot.description, tendons=tendons))
    else:
        sample = run.subset(np.unique(np.linspace(0, len(run) - 1, INERT_ROWS).astype(int)))
    model = RunModel(robot, [name], sample, shear_fixed)
    x0, steps = model.start(), model.vector.steps()
    base, _ = model.points(x0, sample)
    for i in range(model.size):
        trial = x0.copy()
        trial[i] += steps[i]
        moved, _ = model.points(trial, sample)
        if np.nanmax(np.abs(moved - base)) > INERT_MOTION:
            return True
    return False


def select(robot, run, base, candidates, log=print, workers=None, max_evaluations=40,
           shear_fixed=False):
    """Keep the candidate names that lower the cross-validated RMS of ``base``.

    :returns: {'base': rms, 'candidates': {name: rms}, 'kept': [names], 'selected': rms of
        base + kept, 'fit': the chosen fit names}
    """
    kwargs = dict(log=log, workers=workers, max_evaluations=max_evaluations,
                  shear_fixed=shear_fixed)
    base = list(base)
    base_rms = cross_validated_rms(robot, run, base, **kwargs)
    scores = {}
    for name in candidates:
        if name in base:
            continue
        if not moves_the_tips(robot, run, name, shear_fixed):
            log('  %s changes no tip of this run (disk_mass needs gravity): not a candidate'
                % name)
            continue
        scores[name] = cross_validated_rms(robot, run, base + [name], **kwargs)
    kept = sorted((name for name, score in scores.items()
                   if score < (1.0 - MIN_GAIN) * base_rms), key=scores.get)
    selected = scores[kept[0]] if kept else base_rms
    if len(kept) > 1:  # together, or the best alone when together they do worse
        together = cross_validated_rms(robot, run, base + kept, **kwargs)
        if together < selected:
            selected = together
        else:
            kept = kept[:1]
    return {'base': base_rms, 'candidates': scores, 'kept': kept, 'selected': selected,
            'fit': base + kept}
