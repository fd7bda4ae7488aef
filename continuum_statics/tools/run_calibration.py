"""Calibration from a recorded run: replay the cable lengths through the model, fit its parameters.

Each evaluation replays the run row by row through :meth:`Robot.solve_lengths` (slack cables,
stretch, pretension, friction by direction of motion), each row warm-started by the previous one
as on the robot, and compares the model's tracked point (``tip_marker`` on the tip frame) with
the measured tip. ``scipy.optimize.least_squares`` (trust region, bounds) minimises those errors
over the chosen parameters; its finite-difference Jacobian columns are replays run on every core.

The registration of the tracker frame to the base (rotation + translation) is not a search
variable: for every candidate robot it is the best rigid fit of the model points to the measured
ones (Kabsch), so it cannot start in a wrong basin. Gravity, given in the tracker frame, enters
the model through the registration of the previous evaluation.

Fit names (``--fit``):

- ``registration``: base orientation and position in the tracker frame (closed form)
- ``base_position``: the base position alone (the orientation stays the file's)
- ``section_rotation`` (rad): each section's hole pattern about the backbone; with
  ``registration`` the first section's is the registration's roll and stays fixed
- ``cable_angle`` (rad): each cable's hole angle, on top of its section's rotation (their mean
  per section is held at zero, the section rotation's job)
- ``cable_zero`` (m): per-cable ``zero_offset`` (a cable homed too long: > 0)
- ``stiffness`` (N): EA per section; ``pretension`` (N) per section (with ``cable_zero`` only
  the offsets' mean per section tells them apart: it is held at zero)
- ``cable_stiffness`` (N): EA per cable instead of per section
- ``friction``: one capstan coefficient for every cable
- ``youngs_modulus`` (Pa), ``density`` (kg/m^3)
- ``tip_marker`` (m, tip frame): where the tracked point sits on the tip
- ``gravity`` (m/s^2, tracker frame): which way gravity pointed, for a run that did not record
  it; with the density it fits the rod's weight per length, so the written file keeps
  |g| = 9.81 and scales the density
"""
from concurrent.futures import ProcessPoolExecutor
import contextlib
import dataclasses
import gc
import math
import multiprocessing
import os
import time

import numpy as np
from scipy.optimize import least_squares

from continuum_statics.core.robot import Robot
from continuum_statics.core.tendons import Tendons

RUN_PARAMETERS = ('registration', 'base_position', 'section_rotation', 'cable_angle',
                  'cable_zero', 'stiffness', 'pretension', 'friction', 'youngs_modulus',
                  'density', 'gravity', 'tip_marker', 'cable_stiffness')
DEFAULT_FIT = ('registration', 'section_rotation', 'cable_angle', 'cable_zero', 'stiffness',
               'friction')
#: Stiffness start (times E I / (L r), the tension that bends the robot by about 1 rad) for a
#: robot file whose tendons are inextensible: a stretch of 0.1 % at that tension.
STIFFNESS_START = 1000.0
#: Angles per section and rows of the pattern-rotation scan that starts a fit.
SCAN_STEPS = 24
SCAN_ROWS = 250
#: m/s^2: a fitted gravity is written with this magnitude (its excess goes into the density).
STANDARD_GRAVITY = 9.80665
#: Error (m, per axis) of a row whose model point is not finite.
FAILED_ROW_ERROR = 1.0
#: Weight (per m or rad) of the rows that hold a degenerate combination at zero.
GAUGE_WEIGHT = 1.0


@dataclasses.dataclass(frozen=True)
class Block:
    """A slice of the search vector: one fit name's variables."""

    name: str
    start: np.ndarray
    low: np.ndarray
    high: np.ndarray
    index: slice


class RunModel:
    """Candidate robots of a search vector and their replayed model points."""

    def __init__(self, robot, fit, run):
        self.robot = robot
        self.run = run
        self.fit = [name for name in RUN_PARAMETERS if name in fit]
        self.registered = 'registration' in self.fit
        self.rotation = robot.base_rotation.copy()  # tracker <- base, updated by the fit
        self.position = np.array(robot.base_position, dtype=float)
        self.blocks = self._blocks()
        self.size = sum(b.start.size for b in self.blocks)

    # -- the search vector -------------------------------------------------------------------
    def _blocks(self):
        robot, tendons = self.robot, self.robot.tendons
        n_sections, n_cables = len(robot.sections), len(robot.cable_names)
        radius = np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1])
        t_ref = robot.c[0] / (robot.length * float(np.mean(radius)))
        stiffness = np.array([tendons.stiffness[list(s.cable_indices)].mean()
                              for s in robot.sections])
        stiffness[~np.isfinite(stiffness)] = STIFFNESS_START * t_ref
        per_cable = np.where(np.isfinite(tendons.stiffness), tendons.stiffness,
                             STIFFNESS_START * t_ref)
        first = 1 if self.registered else 0
        starts = {
            'section_rotation': (np.zeros(n_sections - first), -math.pi, math.pi),
            'cable_angle': (np.zeros(n_cables), -0.5, 0.5),
            'cable_zero': (np.array(tendons.zero_offset), -0.02, 0.02),
            'stiffness': (np.log(stiffness), np.log(stiffness) - 9.0, np.log(stiffness) + 9.0),
            'cable_stiffness': (np.log(per_cable), np.log(per_cable) - 9.0,
                                np.log(per_cable) + 9.0),
            'pretension': (np.array([tendons.pretension[list(s.cable_indices)].mean()
                                     for s in robot.sections]), 0.0, 100.0 * t_ref),
            'friction': (np.array([float(np.mean(tendons.friction))]), 0.0, 1.0),
            'youngs_modulus': (np.zeros(1), -3.0, 3.0),
            'density': (np.zeros(1), -3.0, 3.0),
            'gravity': (np.array(robot.gravity, dtype=float), -100.0, 100.0),
            'tip_marker': (np.array(robot.tip_marker, dtype=float),
                           robot.tip_marker - 0.1 * robot.length,
                           robot.tip_marker + 0.1 * robot.length),
        }
        blocks, at = [], 0
        for name in self.fit:
            if name not in starts:
                continue
            start, low, high = starts[name]
            size = start.size
            blocks.append(Block(name, start, np.broadcast_to(low, size).astype(float),
                                np.broadcast_to(high, size).astype(float),
                                slice(at, at + size)))
            at += size
        return blocks

    def start(self):
        """Search vector of the robot file's values."""
        return np.concatenate([b.start for b in self.blocks]) if self.blocks else np.zeros(0)

    def bounds(self):
        """(low, high) of the search vector."""
        if not self.blocks:
            return np.zeros(0), np.zeros(0)
        low = np.concatenate([b.low for b in self.blocks])
        high = np.concatenate([b.high for b in self.blocks])
        return low, high

    def values(self, x):
        """Fit name -> its variables (in their units: log stiffness becomes N, ...)."""
        out = {}
        for block in self.blocks:
            v = np.array(x[block.index], dtype=float)
            if block.name in ('stiffness', 'cable_stiffness'):
                v = np.exp(v)
            elif block.name in ('youngs_modulus', 'density'):
                v = np.exp(v)  # factor on the file's value
            out[block.name] = v
        return out

    # -- candidate robots --------------------------------------------------------------------
    def robot_for(self, x, frame='base'):
        """Return the robot of search vector ``x``.

        Its base is at the origin (``frame='base'``, gravity turned into the base frame) or at
        the registration in the tracker frame (``frame='tracker'``).
        """
        robot, description = self.robot, self.robot.description
        values = self.values(x)
        changes = {}
        angles = np.zeros(len(robot.cable_names))
        if 'section_rotation' in values:
            turn = values['section_rotation']
            if self.registered:
                turn = np.concatenate([[0.0], turn])
            for k, section in enumerate(robot.sections):
                angles[list(section.cable_indices)] += turn[k]
        if 'cable_angle' in values:
            angles += values['cable_angle']
        if np.any(angles != 0.0):
            changes['cable_offsets'] = _turned(description.cable_offsets, angles)
        tendons = robot.tendons
        arrays = {f.name: np.array(getattr(tendons, f.name))
                  for f in dataclasses.fields(Tendons)}
        for k, section in enumerate(robot.sections):
            cables = list(section.cable_indices)
            if 'stiffness' in values:
                arrays['stiffness'][cables] = values['stiffness'][k]
            if 'pretension' in values:
                arrays['pretension'][cables] = values['pretension'][k]
        if 'cable_stiffness' in values:
            arrays['stiffness'][:] = values['cable_stiffness']
        if 'cable_zero' in values:
            arrays['zero_offset'][:] = values['cable_zero']
        if 'friction' in values:
            arrays['friction'][:] = values['friction'][0]
        changes['tendons'] = Tendons(**arrays)
        rod = description.rod
        if 'youngs_modulus' in values or 'density' in values:
            factor = values.get('youngs_modulus', [1.0])[0]
            changes['rod'] = dataclasses.replace(
                rod, youngs_modulus=rod.youngs_modulus * factor,
                shear_modulus=rod.shear_modulus * factor,
                density=rod.density * values.get('density', [1.0])[0])
        if 'tip_marker' in values:
            changes['tip_marker'] = values['tip_marker']
        gravity = np.asarray(values.get('gravity', description.gravity), dtype=float)
        if frame == 'base':
            changes['base_position'] = np.zeros(3)
            changes['base_orientation'] = np.array([0.0, 0.0, 0.0, 1.0])
            changes['gravity'] = self.rotation.T @ gravity
        else:
            changes['base_position'] = self.position.copy()
            changes['base_orientation'] = _quaternion(self.rotation)
            magnitude = float(np.linalg.norm(gravity))
            if 'gravity' in values and magnitude > 0.0:  # |g| = 9.81, the weight in the density
                rod = changes.get('rod', description.rod)
                changes['rod'] = dataclasses.replace(
                    rod, density=rod.density * magnitude / STANDARD_GRAVITY)
                changes['gravity'] = gravity * STANDARD_GRAVITY / magnitude
            else:
                changes['gravity'] = gravity
        return Robot(dataclasses.replace(description, **changes))

    # -- residuals ---------------------------------------------------------------------------
    def points(self, x, run=None):
        """Model marker points (n, 3), base frame, and the rows whose solve did not converge."""
        return replay(self.robot_for(x), self.run if run is None else run)

    def register(self, points, tips):
        """Registration (rotation, position) of the model points onto the tips, per the fit."""
        ok = np.all(np.isfinite(points), axis=1)
        if self.registered and np.count_nonzero(ok) >= 3:
            return kabsch(points[ok], tips[ok])
        rotation = self.rotation
        if 'base_position' in self.fit and np.any(ok):
            return rotation, np.mean(tips[ok] - points[ok] @ rotation.T, axis=0)
        return rotation, self.position

    def residuals(self, x, update=False):
        """Return registered model minus measured tips (flattened, m) and the gauge rows."""
        points, _ = self.points(x)
        rotation, position = self.register(points, self.run.tips)
        if update:
            self.rotation, self.position = rotation, position
        errors = points @ rotation.T + position - self.run.tips
        errors = np.nan_to_num(errors, nan=FAILED_ROW_ERROR, posinf=FAILED_ROW_ERROR,
                               neginf=-FAILED_ROW_ERROR)
        return np.concatenate([errors.ravel(), self.gauge(x)])

    def gauge(self, x):
        """Return rows holding at zero the combinations the data cannot see.

        A section's mean cable angle (its rotation's, or the registration's roll for the first
        section) and, with ``pretension``, a section's mean zero offset (a pretension shifts
        every free length).
        """
        values, rows = self.values(x), []
        for k, section in enumerate(self.robot.sections):
            cables = list(section.cable_indices)
            if 'cable_angle' in values and ('section_rotation' in values
                                            or (k == 0 and self.registered)):
                rows.append(GAUGE_WEIGHT * np.mean(values['cable_angle'][cables]))
            if 'cable_zero' in values and 'pretension' in values:
                rows.append(GAUGE_WEIGHT * np.mean(values['cable_zero'][cables])
                            / self.robot.length)
        return np.array(rows)


def replay(robot, run):
    """Replay a run row by row: model marker points (n, 3; m, base frame) and failed rows.

    The second array (n,) is True where the solve did not converge (its best state is kept).
    """
    points = np.full((len(run.lengths), 3), np.nan)
    failed = np.zeros(len(run.lengths), dtype=bool)
    previous = None
    for i, lengths in enumerate(run.lengths):
        try:
            solution = robot.solve_lengths(lengths, warm_start=previous)
        except ValueError:
            failed[i] = True
            continue
        failed[i] = not solution.converged
        shape = solution.shape
        points[i] = shape.tip_position + shape.tip_rotation @ robot.tip_marker
        previous = solution
    return points, failed


def kabsch(points, targets):
    """Rotation R and translation p minimising |R points + p - targets| (Kabsch, no reflection)."""
    mean_p, mean_t = points.mean(axis=0), targets.mean(axis=0)
    u, _, vt = np.linalg.svd((points - mean_p).T @ (targets - mean_t))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rotation = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return rotation, mean_t - rotation @ mean_p


def _turned(offsets, angles):
    """Hole offsets (n, 3) turned about the backbone (local z) by ``angles`` (rad)."""
    c, s = np.cos(angles), np.sin(angles)
    out = np.array(offsets, dtype=float)
    out[:, 0] = c * offsets[:, 0] - s * offsets[:, 1]
    out[:, 1] = s * offsets[:, 0] + c * offsets[:, 1]
    return out


def _quaternion(rotation):
    from scipy.spatial.transform import Rotation
    q = Rotation.from_matrix(rotation).as_quat()
    return q / np.linalg.norm(q)


# -- the fit, with the Jacobian's replays on every core ------------------------------------------
_WORKER_MODEL = None


def rms(errors):
    """RMS of Euclidean point errors (n, 3) (m)."""
    return float(np.sqrt(np.mean(np.sum(errors ** 2, axis=1))))


def rms_aligned(errors):
    """RMS of point errors (n, 3) after removing their mean (m).

    From rms^2 = rms_aligned^2 + |mean|^2, so it never exceeds :func:`rms` by round-off.
    """
    return float(np.sqrt(max(rms(errors) ** 2 - np.sum(errors.mean(axis=0) ** 2), 0.0)))


def scan_rotations(model, x0, log=print, steps=SCAN_STEPS, rows=SCAN_ROWS):
    """Start each section's pattern rotation at the best of ``steps`` angles around the circle.

    A lab knows its holes' radius and spacing but not how each pattern sits: a local fit from a
    wrong quarter turn ends in a wrong basin. Sections are scanned base to tip on every
    ``len(run) // rows``-th row (the registration, solved in closed form, follows each guess).
    """
    block = next((b for b in model.blocks if b.name == 'section_rotation'), None)
    if block is None:
        return x0
    stride = max(1, len(model.run.tips) // rows)
    coarse = RunModel(model.robot, model.fit,
                      model.run.subset(np.arange(0, len(model.run.tips), stride)))
    x = np.array(x0, dtype=float)
    for index in range(block.index.start, block.index.stop):
        costs = []
        for angle in x[index] + np.linspace(-math.pi, math.pi, steps, endpoint=False):
            trial = x.copy()
            trial[index] = math.remainder(angle, 2.0 * math.pi)
            costs.append((float(np.sum(coarse.residuals(trial) ** 2)), trial[index]))
        x[index] = min(costs)[1]
    log('  pattern rotations scanned (%d angles each, %d rows): start %s rad'
        % (steps, len(coarse.run.tips), np.round(x[block.index], 3).tolist()))
    return x


@contextlib.contextmanager
def fork_pool(workers):
    """Yield a pool of ``workers`` forked processes that never collect the parent's garbage.

    Forked, the workers share the model without pickling it. A reference cycle the parent left
    behind (an rclpy node of an earlier test or tool in the same process) collected in a fork
    runs its DDS finalizers there and segfaults the worker; so the parent collects first and
    freezes what is left out of every later collection until the pool is closed.
    """
    gc.collect()
    gc.freeze()
    try:
        with ProcessPoolExecutor(max_workers=workers,
                                 mp_context=multiprocessing.get_context('fork')) as pool:
            yield pool
    finally:
        gc.unfreeze()


def fit(model, log=print, workers=None, max_evaluations=40):
    """Fit the model's search vector; returns (x, scipy result)."""
    global _WORKER_MODEL
    workers = workers or min(os.cpu_count() or 1, 8)
    low, high = model.bounds()
    x0 = np.clip(model.start(), low, high)
    x0 = scan_rotations(model, x0, log)
    model.residuals(x0, update=True)
    _WORKER_MODEL = model
    began = time.monotonic()
    count = [0]
    with fork_pool(workers) as pool:
        cache = {}

        def fun(x):
            res = model.residuals(x, update=True)
            cache['x'], cache['res'] = np.array(x), res
            count[0] += 1
            n = len(model.run.tips)
            log('  evaluation %d: RMS %.3f mm (%.0f s)' % (
                count[0], rms(res[:3 * n].reshape(-1, 3)) * 1e3, time.monotonic() - began))
            return res

        def jac(x):
            base = cache['res'] if np.array_equal(cache.get('x'), x) else model.residuals(x)
            steps = 1e-4 * np.maximum(np.abs(x), 1e-2)
            steps = np.where(x + steps > high, -steps, steps)
            trials = [x + steps[i] * np.eye(len(x))[i] for i in range(len(x))]
            # the workers see the registration of the fork; refresh them by passing it along
            columns = list(pool.map(_worker_residuals_with, [
                (trial, model.rotation, model.position) for trial in trials]))
            return np.stack([(c - base) / h for c, h in zip(columns, steps)], axis=1)

        # ftol 1e-3: a step that gains less than 0.1 % of the cost ends the fit (its last
        # evaluations gained micrometres at a minute each)
        result = least_squares(fun, x0, jac=jac, bounds=(low, high), x_scale='jac',
                               xtol=1e-8, ftol=1e-3, gtol=1e-8, max_nfev=max_evaluations)
    model.residuals(result.x, update=True)
    return result.x, result


def _worker_residuals_with(args):
    x, rotation, position = args
    _WORKER_MODEL.rotation, _WORKER_MODEL.position = rotation, position
    return _WORKER_MODEL.residuals(x)


def errors_of(model, x, run):
    """Return registered model minus measured tips (n, 3) of ``run`` (registration held)."""
    points, failed = model.points(x, run)
    return points @ model.rotation.T + model.position - run.tips, failed


# -- the command ---------------------------------------------------------------------------------
def calibrate_run(robot_file, data_file, fit_names, column_map, output=None, validate=None,
                  tip_topic='tip_pose_measured', log=print, max_evaluations=40):
    """Fit a robot file to a recorded run; write ``output``; return the summary dict (SI units).

    :raises ValueError: unreadable files, unknown parameters, missing columns
    """
    from continuum_statics import load_robot
    from continuum_statics.tools.recorded_run import check_tip_units, read_recorded_run

    unknown = [name for name in fit_names if name not in RUN_PARAMETERS]
    if unknown:
        raise ValueError('unknown parameter(s) %s for a recorded run; fittable: %s'
                         % (', '.join(unknown), ', '.join(RUN_PARAMETERS)))
    robot = load_robot(robot_file)

    def read(path):
        run = read_recorded_run(path, robot.cable_names, robot.straight_cable_lengths,
                                column_map, tip_topic)
        check_tip_units(run.tips, robot.length, path)
        return run

    run = read(data_file)
    held_out = read(validate) if validate else None
    model = RunModel(robot, fit_names, run)
    if 3 * len(run.tips) < model.size:
        raise ValueError('%d rows cannot determine %d parameters' % (len(run.tips), model.size))
    began = time.monotonic()
    before = _summary_errors(replay(robot, run)[0] - run.tips)
    log('calibrate: %d rows of %s, %d parameters (%s); the robot file as given: RMS %.2f mm'
        % (len(run.tips), data_file, model.size, ', '.join(model.fit), before[0] * 1e3))
    x, result = fit(model, log, max_evaluations=max_evaluations)
    errors, failed = errors_of(model, x, run)
    summary = {
        'robot': str(robot_file), 'data': str(data_file), 'rows': int(len(run.tips)),
        'model': 'solve_lengths (recorded run replayed row by row)',
        'fit': list(model.fit), 'fitted': _fitted(model, x),
        'rms_before': before[0], 'rms_after': rms(errors),
        'rms_aligned_after': rms_aligned(errors),
        'max_after': float(np.max(np.linalg.norm(errors, axis=1))),
        'unconverged_rows': int(np.count_nonzero(failed)),
        'registration': {'position': model.position.tolist(),
                         'orientation': _quaternion(model.rotation).tolist()},
        'optimizer': {'success': bool(result.success), 'evaluations': int(result.nfev),
                      'message': str(result.message)},
        'seconds': round(time.monotonic() - began, 1),
        'notes': _notes(_fitted(model, x)),
        'output': None if output is None else str(output),
    }
    if held_out is not None:
        errors, failed = errors_of(model, x, held_out)
        summary.update(validate=str(validate), validate_rows=int(len(held_out.tips)),
                       validate_rms=rms(errors),
                       validate_rms_aligned=rms_aligned(errors),
                       validate_max=float(np.max(np.linalg.norm(errors, axis=1))),
                       validate_unconverged_rows=int(np.count_nonzero(failed)))
    if output is not None:
        write_run_robot_file(output, robot_file, model.robot_for(x, frame='tracker'), summary)
    return summary


def _summary_errors(errors):
    errors = np.nan_to_num(errors, nan=FAILED_ROW_ERROR)
    return rms(errors), rms_aligned(errors)


def _fitted(model, x):
    return {name: np.atleast_1d(value).tolist() for name, value in model.values(x).items()}


#: A capstan coefficient below this changes a tension by < 0.3 % over a half turn: none.
NEGLIGIBLE_FRICTION = 1e-3


def _notes(fitted):
    """Return notes on fitted values that are not what they look like (e.g. friction ~ 0)."""
    notes = []
    friction = fitted.get('friction')
    if friction is not None and max(friction) < NEGLIGIBLE_FRICTION:
        notes.append('friction: the data show none (fitted %.2g; below %g the capstan effect '
                     'is under 0.3 %% per half turn of wrap)' % (max(friction),
                                                                NEGLIGIBLE_FRICTION))
    return notes


def write_run_robot_file(output, robot_file, robot, summary):
    """Write the input robot file with the calibrated robot's values and a provenance header."""
    import datetime

    import yaml

    with open(robot_file, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    description, tendons = robot.description, robot.tendons
    document['base'] = dict(document['base'], position=_rounded(description.base_position),
                            orientation=_rounded(description.base_orientation, 9))
    document['gravity'] = _rounded(description.gravity, 6)
    document['tip_marker'] = _rounded(robot.tip_marker, 6)
    rod = robot.rod
    document['rod'] = dict(document['rod'], youngs_modulus=float('%.6g' % rod.youngs_modulus),
                           density=float('%.6g' % rod.density))
    holders = document.get('sections') or [document]
    top = dict(document.get('tendons') or {})
    if np.all(tendons.friction == tendons.friction[0]):
        top['friction'] = float('%.6g' % tendons.friction[0])
    document['tendons'] = top
    j = 0
    for holder, section in zip(holders, robot.sections):
        block = dict(holder.get('tendons') or {}) if holder is not document else top
        cables = list(section.cable_indices)
        per_cable = []  # keys whose values differ within the section: on each cable entry
        for key in ('stiffness', 'pretension'):
            values = getattr(tendons, key)[cables]
            if not np.all(np.isfinite(values)) or (key == 'pretension' and not np.any(values)):
                continue
            if np.all(values == values[0]):
                block[key] = float('%.6g' % values[0])
            else:
                per_cable.append(key)
        if holder is not document:
            holder['tendons'] = block
        for cable in holder.get('cables') or []:
            cable['offset'] = _rounded(robot.cable_offsets[j], 7)
            for key in per_cable:
                cable[key] = float('%.6g' % getattr(tendons, key)[j])
            if tendons.zero_offset[j] != 0.0:
                cable['zero_offset'] = float('%.6g' % tendons.zero_offset[j])
            j += 1
    lines = [
        'Calibrated by `python -m continuum_statics calibrate` on %s UTC'
        % datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M'),
        'from %s, replaying the recorded run %s (%d rows) through solve_lengths;'
        % (summary['robot'], summary['data'], summary['rows']),
        'fitted: %s. Tip RMS %.2f mm (file as given) -> %.2f mm (%.2f mm mean-offset aligned).'
        % (', '.join(summary['fit']), summary['rms_before'] * 1e3, summary['rms_after'] * 1e3,
           summary['rms_aligned_after'] * 1e3),
    ]
    if 'validate_rms' in summary:
        lines.append('Held out %s (%d rows): RMS %.2f mm (%.2f mm aligned).' % (
            summary['validate'], summary['validate_rows'], summary['validate_rms'] * 1e3,
            summary['validate_rms_aligned'] * 1e3))
    text = ''.join('# %s\n' % line for line in lines)
    text += yaml.safe_dump(document, sort_keys=False, default_flow_style=None, width=99)
    with open(output, 'w', encoding='utf-8') as stream:
        stream.write(text)


def _rounded(values, digits=9):
    return [float('%.*g' % (digits, v)) for v in np.asarray(values, dtype=float)]
