"""Calibration from a recorded run: replay the cable lengths through the model, fit it.

Each evaluation replays the run row by row through :meth:`Robot.solve_lengths` (slack cables,
stretch, pretension, friction by direction of motion), each row warm-started by the previous one
as on the robot, and compares the model's tracked point (``tip_marker`` on the tip frame) with
the measured tip (:mod:`.run_model`, :mod:`.fit`). Fit names: :mod:`.parameters`.
"""
import time

import numpy as np

from continuum_statics.calibration import summary as summaries
from continuum_statics.calibration.error_budget import error_budget
from continuum_statics.calibration.fit import fit as fit_model
from continuum_statics.calibration.model_uncertainty import fold_robots
from continuum_statics.calibration.model_uncertainty import measure as measure_uncertainty
from continuum_statics.calibration.parameters import DEFAULT_FIT, check_names, quaternion
from continuum_statics.calibration.phases import Phases
from continuum_statics.calibration.pool import Background, default_workers
from continuum_statics.calibration.recorded_run import check_tip_units, read_recorded_run
from continuum_statics.calibration.replay import error_statistics, replay
from continuum_statics.calibration.robot_writer import write_robot_file
from continuum_statics.calibration.run_model import RunModel
from continuum_statics.calibration.selection import select


def read_run(path, robot, column_map, tip_topic='tip_pose_measured'):
    """Read a recorded run (CSV or bag) in the robot's cable order, SI units, tips checked."""
    run = read_recorded_run(path, robot.cable_names, robot.straight_cable_lengths, column_map,
                            tip_topic, [sensor.name for sensor in robot.sensors
                                        if not sensor.at_tip])
    check_tip_units(run.tips, robot.length, path)
    return run


def calibrate_run(robot_file, data_file, fit_names, column_map, output=None, validate=None,
                  tip_topic='tip_pose_measured', log=print, max_evaluations=40, report=False,
                  workers=None, candidates=(), jacobian='implicit', uncertainty=False):
    """Fit a robot file to a recorded run; write ``output``; return the summary (SI units).

    :param validate: a held-out run: its errors are reported, never fitted
    :param report: add the error budget (:mod:`.error_budget`) as ``error_budget``
    :param candidates: fit names to try on top of ``fit_names``: each is kept when it lowers the
        error cross-validated inside the run (:mod:`.selection`, summary ``selection``)
    :param jacobian: how the fit's Jacobian is made (:data:`fit.JACOBIANS`)
    :param uncertainty: also measure the fitted model's own error on the run, cross-validated
        inside it (:mod:`.model_uncertainty`), summary ``model_uncertainty``, written to the file

    A fit of more names than the default ones starts where a fit of its default names ends.
    The summary's ``phases`` says where the time went (:mod:`.phases`: wall and CPU seconds of
    ``read``, ``select``, ``scan``, ``fit``, ``before``, ``validate``, ``report``, ``folds``,
    ``uncertainty``, ``write``).
    :raises ValueError: unreadable files, unknown parameters, missing columns
    """
    check_names(list(fit_names) + list(candidates), 'run')
    phases = Phases()
    summary = _calibrate_run(robot_file, data_file, fit_names, column_map, output, validate,
                             tip_topic, log, max_evaluations, report, workers, candidates,
                             jacobian, uncertainty, phases)
    summary['phases'] = phases.rounded()
    return summary


def _calibrate_run(robot_file, data_file, fit_names, column_map, output, validate, tip_topic,
                   log, max_evaluations, report, workers, candidates, jacobian, uncertainty,
                   phases):
    """:func:`calibrate_run`, its phases timed into ``phases``."""
    from continuum_statics import load_robot

    with phases('read'):
        robot = load_robot(robot_file)
        run = read_run(data_file, robot, column_map, tip_topic)
        held_out = read_run(validate, robot, column_map, tip_topic) if validate else None
        shear_fixed = summaries.shear_fixed(robot_file)
    for note in run.notes:
        log('calibrate: %s: %s' % (data_file, note))
    began = time.monotonic()
    # the file as given replayed (a serial replay, far from the fit: the slowest rows) in a
    # process of its own while the scans and the fit's serial steps leave a core free
    before_points = Background(_replayed_points, robot, run,
                               workers=workers or default_workers())
    try:
        fitted_model = _fitted(robot, run, fit_names, candidates, log, workers, max_evaluations,
                               shear_fixed, jacobian, data_file, before_points, phases)
    finally:
        before_points.close()
    model, result, selection, before, errors, failed = fitted_model
    x = result.x
    fitted = summaries.fitted_values(model.vector, x, result.jacobian, result.residuals,
                                     model.bounds())
    summary = {
        'kind': 'run', 'robot': str(robot_file), 'data': str(data_file),
        'rows': int(len(run.tips)),
        'model': 'solve_lengths (recorded run replayed row by row)',
        'fit': list(model.fit), 'fitted': fitted,
        **summaries.before_after(before, errors),
        'unconverged_rows': int(np.count_nonzero(failed)),
        'registration': {'position': model.position.tolist(),
                         'orientation': quaternion(model.rotation).tolist()},
        'optimizer': {'success': result.success, 'evaluations': result.evaluations,
                      'message': result.message},
        'seconds': round(time.monotonic() - began, 1),
        'notes': summaries.notes(fitted),
        'output': None if output is None else str(output),
    }
    model_errors = {'train': errors}
    if held_out is not None:
        with phases('validate'):
            held_errors, held_failed = model.errors(x, held_out)
        model_errors['held_out'] = held_errors
        stats = error_statistics(held_errors)
        summary.update(validate=str(validate), validate_rows=int(len(held_out.tips)),
                       validate_rms=stats['rms'], validate_rms_aligned=stats['rms_aligned'],
                       validate_max=stats['max'],
                       validate_unconverged_rows=int(np.count_nonzero(held_failed)))
    if selection is not None:
        summary['selection'] = selection
    if report:
        with phases('report'):
            summary['error_budget'] = error_budget(run, held_out, model_errors)
    fitted_robot = model.robot_for(x, frame='tracker')
    measured = None
    if uncertainty:
        log("calibrate: measuring the model's own error on the run (model_uncertainty), "
            'cross-validated: each motion pattern by a fit without it')
        with phases('folds'):
            folds = fold_robots(robot, run, model.fit, model, x, workers, shear_fixed)
        with phases('uncertainty'):
            measured, summary['model_uncertainty'] = measure_uncertainty(fitted_robot, run,
                                                                         folds=folds)
    if output is not None:
        with phases('write'):
            write_robot_file(output, robot_file, fitted_robot, model.fit,
                             summaries.header(summary), measured)
    return summary


def _fitted(robot, run, fit_names, candidates, log, workers, max_evaluations, shear_fixed,
            jacobian, data_file, before_points, phases):
    """Return the selection and fit of :func:`calibrate_run`: model, result, errors (m)."""
    selection = start = None
    if candidates:
        log('calibrate: choosing among %s by cross-validation inside %s'
            % (', '.join(candidates), data_file))
        with phases('select'):
            selection = select(robot, run, fit_names, candidates, log, workers,
                               max_evaluations, shear_fixed)
        fit_names = selection['fit']
    staged = [name for name in fit_names if name in DEFAULT_FIT]
    if staged and len(staged) < len(fit_names):
        # a fit with more than the default names starts where the default part of it ends: from
        # the nominal file, the extra freedom stops the optimiser in a worse basin (v6, every
        # name at once: 9.75 mm on the training rows; staged: never worse than the default)
        log('calibrate: first %s, then all %d names from there' % (' '.join(staged),
                                                                   len(fit_names)))
        base = RunModel(robot, staged, run, shear_fixed)
        start = (base, fit_model(base, log, workers=workers, max_evaluations=max_evaluations,
                                 jacobian=jacobian, phases=phases).x)
    model = RunModel(robot, fit_names, run, shear_fixed)
    if 3 * len(run.tips) < model.size:
        raise ValueError('%d rows cannot determine %d parameters' % (len(run.tips), model.size))
    log('calibrate: %d rows of %s, %d parameters (%s)'
        % (len(run.tips), data_file, model.size, ', '.join(model.fit)))
    result = fit_model(model, log, workers=workers, max_evaluations=max_evaluations,
                       x0=None if start is None else model.start_from(*start),
                       jacobian=jacobian, phases=phases)
    with phases('before'):
        before = before_points.result() - run.tips
    log('calibrate: the robot file as given: RMS %.2f mm' % (
        error_statistics(before)['rms'] * 1e3))
    with phases('validate'):
        errors, failed = model.errors(result.x, run)
    return model, result, selection, before, errors, failed


def _replayed_points(robot, run):
    """Model points (n, 3) of a whole replay of ``run`` by ``robot``."""
    return replay(robot, run)[0]
