"""A recorded run's residuals: candidate robots replayed, registered onto the tracker, compared.

The registration of the tracker frame to the base (rotation + translation) is not a search
variable: for every candidate robot it is the best rigid fit of the model points to the measured
ones (Kabsch), so it cannot start in a wrong basin. Gravity, given in the tracker frame, enters
the model through the registration of the previous evaluation (:attr:`RunModel.gravity_frame`:
the Jacobian at an evaluation is of the robot its replay solved).
"""
import dataclasses

import numpy as np

from continuum_statics.calibration.parameters import SearchVector, quaternion
from continuum_statics.calibration.replay import FAILED_ROW_ERROR, kabsch, replay_solutions
from continuum_statics.core.robot import Robot

#: m/s^2: a fitted gravity is written with this magnitude (its excess goes into the density).
STANDARD_GRAVITY = 9.80665
#: Weight (per m or rad) of the rows that hold a degenerate combination at zero.
GAUGE_WEIGHT = 1.0
#: m of cable: a replay's rows converge to this (a node's 1e-9 m would leave a bias of that
#: size in every Jacobian column started from the base rows: 2 % at a 1e-4 step).
REPLAY_TOLERANCE = 1e-12
#: m: the largest point move of a registration column (:meth:`RunModel.jacobian`).
REGISTRATION_STEP = 1e-6
#: Variable step of a gauge row's derivative (the rows are linear in the angles and offsets).
GAUGE_STEP = 1e-6


class RunModel:
    """Candidate robots of a search vector and their replayed model points on a run.

    :param robot: the robot file's robot (its base pose is the registration's start)
    :param fit: fit names (:data:`parameters.RUN_PARAMETERS`)
    :param run: a :class:`recorded_run.RecordedRun`
    """

    def __init__(self, robot, fit, run, shear_fixed=False):
        self.robot = robot
        self.run = run
        self.vector = SearchVector(robot, fit, shear_fixed)
        self.fit = self.vector.fit
        self.registered = self.vector.registered
        self.blocks = self.vector.blocks
        self.size = self.vector.size
        self.solutions = self.replayed = None  # of the last replay: solutions, points
        self.starts = None  # per-row warm starts of a Jacobian's columns (set by the fit)
        self._last_replay = None  # ((x, run, gravity), solutions, points, failed) of a whole one
        self.rotation = robot.base_rotation.copy()  # tracker <- base, updated by the fit
        # the registration that turns gravity into the base frame: the one before the replay
        # being fitted (its solutions and their Jacobian are of that robot)
        self.gravity_frame = self.rotation.copy()
        self.position = np.array(robot.base_position, dtype=float)

    def start(self):
        """Search vector of the robot file's values."""
        return self.vector.start()

    def bounds(self):
        """(low, high) of the search vector."""
        return self.vector.bounds()

    def start_from(self, other, x):
        """Return a start at ``other``'s fit ``x`` for the names both have, the file's elsewhere.

        The registration is taken over too.
        """
        start = self.start()
        for block in self.blocks:
            match = next((b for b in other.blocks if b.name == block.name), None)
            if match is not None:
                start[block.index] = x[match.index]
        self.rotation, self.position = other.rotation.copy(), other.position.copy()
        self.gravity_frame = self.rotation.copy()
        return start

    def values(self, x):
        """Fit name -> its values in file units."""
        return self.vector.values(x)

    def robot_for(self, x, frame='base'):
        """Return the robot of search vector ``x``.

        Its base is at the origin (``frame='base'``, gravity turned into the base frame) or at
        the registration in the tracker frame (``frame='tracker'``).
        """
        candidate = self.vector.robot_for(x)
        description = candidate.description
        gravity = np.array(description.gravity, dtype=float)
        changes = {'solver': dataclasses.replace(description.solver,
                                                 estimate_tolerance=REPLAY_TOLERANCE)}
        if frame == 'base':
            changes.update(base_position=np.zeros(3),
                           base_orientation=np.array([0.0, 0.0, 0.0, 1.0]),
                           gravity=self.gravity_frame.T @ gravity)
        else:
            changes.update(base_position=self.position.copy(),
                           base_orientation=quaternion(self.rotation))
            magnitude = float(np.linalg.norm(gravity))
            if 'gravity' in self.fit and magnitude > 0.0:  # |g| = 9.81, the weight in the density
                changes['rod'] = dataclasses.replace(
                    description.rod, density=description.rod.density * magnitude
                    / STANDARD_GRAVITY)
                changes['gravity'] = gravity * STANDARD_GRAVITY / magnitude
        return Robot(dataclasses.replace(description, **changes))

    def points(self, x, run=None, starts=None):
        """Model marker points (n, 3), base frame, and the rows whose solve did not converge.

        ``starts``: per-row warm starts (:func:`replay.replay_solutions`); the solutions are
        kept in :attr:`solutions` for the next call's.
        """
        run = self.run if run is None else run
        robot = self.robot_for(x)
        # a whole replay of the robot and run the last whole replay solved gives its result
        # again (the fit's last evaluation is its end; the end's train errors): not re-solved
        key = (np.array(x, dtype=float), run, robot.gravity)
        last = self._last_replay
        if (starts is None and last is not None and last[0][1] is run
                and np.array_equal(last[0][0], key[0]) and np.array_equal(last[0][2], key[2])):
            self.solutions, self.replayed = last[1], last[2]
            return last[2], last[3]
        points, failed, self.solutions = replay_solutions(robot, run, starts)
        self.replayed = points
        self._last_replay = (key, self.solutions, points, failed) if starts is None else None
        return points, failed

    def register(self, points, tips):
        """Registration (rotation, position) of the model points onto the tips, per the fit."""
        ok = np.all(np.isfinite(points), axis=1)
        if self.registered and np.count_nonzero(ok) >= 3:
            return kabsch(points[ok], tips[ok])
        rotation = self.rotation
        if 'base_position' in self.fit and np.any(ok):
            return rotation, np.mean(tips[ok] - points[ok] @ rotation.T, axis=0)
        return rotation, self.position

    def residuals(self, x, update=False, run=None, starts=None):
        """Return registered model minus measured tips (flattened, m) and the gauge rows."""
        run = self.run if run is None else run
        if update:  # this replay's robot turns gravity by the registration of now
            self.gravity_frame = self.rotation.copy()
        points, _ = self.points(x, run, starts)
        return self.residuals_of(points, x, update, run)

    def residuals_of(self, points, x, update=False, run=None):
        """:meth:`residuals` of model points (n, 3; base frame) already replayed at ``x``."""
        run = self.run if run is None else run
        rotation, position = self.register(points, run.tips)
        if update:
            self.rotation, self.position = rotation, position
        errors = points @ rotation.T + position - run.tips
        errors = np.nan_to_num(errors, nan=FAILED_ROW_ERROR, posinf=FAILED_ROW_ERROR,
                               neginf=-FAILED_ROW_ERROR)
        return np.concatenate([errors.ravel(), self.gauge(x)])

    def jacobian(self, x, points, sensitivities):
        """Jacobian of :meth:`residuals` from the points' sensitivities (rows, 3, variables).

        The registration (closed form) follows the points: each column is a central difference
        of the registered errors along the sensitivity, moving no point by more than
        :data:`REGISTRATION_STEP`; the gauge rows are linear in the variables they hold.
        """
        points = np.array(points, dtype=float)
        n = 3 * len(points)
        columns = []
        for j in range(self.size):
            direction = np.nan_to_num(sensitivities[:, :, j])
            largest = float(np.max(np.abs(direction), initial=0.0))
            step = REGISTRATION_STEP / largest if largest > 0.0 else 1.0
            column = (self.residuals_of(points + step * direction, x)
                      - self.residuals_of(points - step * direction, x))[:n] / (2.0 * step)
            unit = np.zeros(self.size)
            unit[j] = GAUGE_STEP
            gauge = (self.gauge(x + unit) - self.gauge(x - unit)) / (2.0 * GAUGE_STEP)
            columns.append(np.concatenate([column, gauge]))
        return np.stack(columns, axis=1) if columns else np.zeros((n, 0))

    def errors(self, x, run):
        """Return registered model minus measured tips (n, 3) of ``run`` and its failed rows.

        The registration is held at the fit's, and turns gravity as in the written robot.
        """
        self.gravity_frame = self.rotation.copy()
        points, failed = self.points(x, run)
        return points @ self.rotation.T + self.position - run.tips, failed

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
