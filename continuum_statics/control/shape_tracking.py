"""Shape tracking: what statics decides for each measurement (paper sec. V.A, per cycle).

One :meth:`ShapeTracker.update` per ``cable_states``: limits and tension plausibility, the
warm-started estimate (at most ``max_iterations`` and ``max_model_runs`` IVPs per measurement;
one more such estimate when still far off; an unfinished one warm-starts the next
measurement), tensions that disagree with the lengths set aside, and the residual judged against
the thresholds: published as a shape, published as a best fit (warn), or dropped. No ROS.

Every solve is with :attr:`ShapeTracker.obstacles` (None: the robot file's; statics sets the
robot file's merged with its ``obstacles`` topic, base frame): ``estimate.shape.contacts`` says
where the body rests on them (contacts the core cannot resolve come back in the estimate's
message; a contact solve that raises drops the measurement, as any other failed estimate).
"""
from dataclasses import dataclass
import math
import time

import numpy as np

from continuum_statics.control.sensor_readings import SensorInbox
from continuum_statics.core.estimation.shape_estimation import Tracking
from continuum_statics.core.rod.tracking import TRACK_RUNS
from continuum_statics.core.statics.contact import ContactError
from continuum_statics.core.statics.length_statics import MOTION_THRESHOLD


@dataclass(frozen=True)
class Thresholds:
    """The judgement of a fit.

    ``warn``: RMS length residual (m) above which a fit is a best fit; ``drop``: above which no
    shape is near; ``margin``: how far (m) lengths may be outside the robot file's limits;
    ``motion``: how far (m) a cable must move before its friction direction follows (the
    margin becomes 5 σ of the noise); ``noise``: the encoders' σ (m).
    """

    warn: float
    drop: float
    margin: float
    motion: float = MOTION_THRESHOLD
    noise: float = 0.0

    @classmethod
    def with_noise(cls, warn, drop, margin, noise):
        """Thresholds raised to the encoders' noise σ (m): 3 σ warn and motion, 10 σ drop."""
        warn = max(warn, 3.0 * noise)
        return cls(warn, max(drop, warn, 10.0 * noise), max(margin, 5.0 * noise),
                   max(MOTION_THRESHOLD, 3.0 * noise), noise)


@dataclass(frozen=True, eq=False)
class TrackResult:
    """What one measurement gave.

    :ivar estimate: the shape estimate (None when rejected before solving)
    :ivar rejection: why the measurement is dropped ('' when the shape is to be published)
    :ivar message: what limited the estimate, for diagnostics
    :ivar converged: stationary (or refined from one measurement to the next) and a good fit
    :ivar capped: stopped at ``max_iterations`` or ``max_model_runs``, refined with the next
        measurement
    :ivar best_fit: residual above ``warn`` (published with WARN)
    :ivar tensions_used: the shape follows measured tensions
    :ivar distrust: why measured tensions were set aside ('' when not)
    :ivar load_problem: why the tip load was replaced by zero ('' when not)
    :ivar outside_limits: rejected for lengths outside the limits
    """

    estimate: object = None
    rejection: str = ''
    message: str = ''
    converged: bool = False
    capped: bool = False
    best_fit: bool = False
    tensions_used: bool = False
    distrust: str = ''
    load_problem: str = ''
    outside_limits: bool = False

    @property
    def residual(self):
        """RMS length residual (m), NaN without an estimate."""
        return math.nan if self.estimate is None else float(self.estimate.residual)


class ShapeTracker:
    """The estimate of one robot, warm-started from the last published one."""

    def __init__(self, robot, cable_names, max_iterations=0, max_model_runs=TRACK_RUNS,
                 sensor_timeout=0.5, clock=time.monotonic):
        self.robot = robot
        #: the robot file's sensors' readings, fused by :meth:`update` (None without sensors)
        self.inbox = SensorInbox([sensor.name for sensor in robot.sensors], sensor_timeout) \
            if robot.sensors else None
        self._clock = clock
        self.cable_names = cable_names
        limits = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)
        self.low, self.high = limits[:, 0].copy(), limits[:, 1].copy()
        self.warm = None  # the last published (or unfinished) estimate: warm start of the next
        #: the obstacles every estimate is solved with, base frame (None: the robot file's)
        self.obstacles = None
        self.set_max_iterations(max_iterations)
        self.max_model_runs = max_model_runs

    def set_max_iterations(self, max_iterations):
        """Cap the Gauss-Newton iterations per measurement (0: the robot file's)."""
        if not max_iterations or max_iterations >= self.robot.solver.max_iterations:
            self._tracking = self.robot
        else:
            self._tracking = self.robot.with_solver(max_iterations=int(max_iterations))

    def accept(self, result):
        """Warm-start the next update from a result whose shape was published."""
        self.warm = result.estimate

    def update(self, lengths, tensions, load, thresholds, tension_limit, sensors=None,
               stamp=None):
        """Judge and solve one measurement.

        :param lengths: (n_cables,) measured lengths, m, robot order
        :param tensions: (n_cables,) measured tensions, N, or None
        :param load: (6,) tip wrench (N, N m), base frame
        :param thresholds: :class:`Thresholds`; ``tension_limit``: largest plausible tension, N
        :param sensors: {name: SensorReading} to fuse, or None: the fresh readings of
            :attr:`inbox`, whose verdicts it then counts
        :param stamp: the measurement's stamp, s (the unmodelled loads' decay)
        """
        inbox = self.inbox if sensors is None else None
        if inbox is not None:
            sensors = inbox.take(self._clock(), stamp)
        result = self._update(lengths, tensions, load, thresholds, tension_limit, sensors, stamp)
        if inbox is not None and result.estimate is not None:
            inbox.judged(result.estimate.sensors)
        return result

    def _update(self, lengths, tensions, load, thresholds, tension_limit, sensors, stamp):
        names = self.cable_names
        outside = np.flatnonzero((lengths < self.low - thresholds.margin)
                                 | (lengths > self.high + thresholds.margin))
        if outside.size:
            return TrackResult(outside_limits=True, rejection=(
                "lengths outside the robot file's length limits (margin %.3g m): %s" % (
                    thresholds.margin, ', '.join('%s %.4f m not in [%.4f, %.4f]' % (
                        names[i], lengths[i], self.low[i], self.high[i]) for i in outside[:4]))))
        if tensions is not None:
            high = np.flatnonzero(tensions > tension_limit)
            if high.size:  # one absurd reading costs a slow solve and a nonsense shape
                return TrackResult(rejection='implausible tensions (max_tension %.4g N): %s' % (
                    tension_limit, ', '.join('%s %.4g N' % (names[i], tensions[i])
                                             for i in high[:4])))
        notes = {'load_problem': '', 'distrust': ''}
        obstacles = self.obstacles  # one read per measurement (statics swaps in new sets)
        try:
            # the first measurement (nothing to track from yet) is solved to the end, once
            tracking = None if self.warm is None else Tracking(
                self.max_model_runs, thresholds.warn, thresholds.motion, thresholds.noise)
            estimate = self._estimate(self._tracking, lengths, load, tensions, self.warm, notes,
                                      tracking, sensors, stamp, obstacles)
            if tensions is not None and not estimate.residual <= thresholds.warn:
                # tensions and lengths disagree: the lengths (encoders) are trusted, the
                # tensions (a sensor, a current estimate) are not used for this shape
                notes['distrust'] = ('measured tensions disagree with the lengths (shape from '
                                     'the tensions %.3g m RMS off them): shape from the lengths'
                                     % estimate.residual)
                tensions = None
                estimate = self._estimate(self._tracking, lengths, load, None, self.warm, notes,
                                          tracking, sensors, stamp, obstacles)
            capped = estimate.capped or (not estimate.converged
                                         and self._tracking is not self.robot)
            if capped and not estimate.residual <= thresholds.drop:
                # far from the last shape (a jump, a restart): one more bounded estimate now,
                # from this one (its readings are fused already)
                estimate = self._estimate(self.robot, lengths, load, tensions, estimate, notes,
                                          tracking, None, stamp, obstacles)
                capped = estimate.capped
            if capped:  # the best state reached: the next measurement goes on from it
                self.warm = estimate
            if not estimate.residual <= thresholds.drop and np.any(load):
                estimate, capped = self._under_no_load(lengths, load, tensions, estimate, capped,
                                                       thresholds, notes, stamp, obstacles)
        except (ValueError, ContactError) as error:
            return TrackResult(rejection=str(error), load_problem=notes['load_problem'])
        residual = float(estimate.residual)
        good_fit = residual <= thresholds.warn
        message = estimate.message
        if capped:
            message = 'refined with the next measurement (max_iterations %d)' % (
                self._tracking.solver.max_iterations)
        if not good_fit:
            message = ('best fit: cable lengths %.3g m RMS from the nearest shape (warn above '
                       '%.3g m)%s' % (residual, thresholds.warn, '; ' + message if message
                                      else ''))
        if notes['distrust']:
            message = notes['distrust'] + ('; ' + message if message else '')
        rejection = ''
        if not residual <= thresholds.drop:
            # lengths no shape of this robot explains (broken cable, wrong robot file, unhomed
            # encoder): keep the last good shape rather than publish a best fit of nonsense
            rejection = ('cable lengths fit no shape: RMS residual %.3g m > max_residual %.3g m%s'
                         % (residual, thresholds.drop,
                            '' if estimate.converged else ' (%s)' % estimate.message))
        # converged: stationary, or (iteration cap) being refined from one measurement to the
        # next, and in both cases the lengths are a shape within warn_residual
        return TrackResult(estimate=estimate, rejection=rejection, message=message,
                           converged=(bool(estimate.converged) or capped) and good_fit,
                           capped=capped, best_fit=not good_fit,
                           tensions_used=tensions is not None, **notes)

    def _under_no_load(self, lengths, load, tensions, estimate, capped, thresholds, notes,
                       stamp, obstacles=None):
        """Return (estimate, capped): the shape under zero tip load when that one fits.

        A tip load (an estimator's, a topic's) the lengths fit no shape under must not silence
        statics: with tip_wrench_source estimate it dropped every cable_states for 13 s
        (issue 43). The shape under the load's prior (zero), solved to the end, is published
        instead, and the load named on diagnostics.
        """
        plain = self._estimate(self.robot, lengths, np.zeros(6), tensions, None, notes, None,
                               None, stamp, obstacles)
        if not plain.residual <= thresholds.drop:
            return estimate, capped  # not the load: the lengths fit no shape at all
        notes['load_problem'] = ('cable lengths fit no shape under tip load %s (RMS residual '
                                 '%.3g m): the shape under zero load instead'
                                 % (np.array2string(np.asarray(load), precision=3),
                                    estimate.residual))
        return plain, False

    @staticmethod
    def _estimate(robot, lengths, load, tensions, warm, notes, tracking=None, sensors=None,
                  stamp=None, obstacles=None):
        """Estimate; a tip load the model cannot take is replaced by zero (and noted).

        ``obstacles``: base frame; None: the robot file's (the call as without obstacles).
        """
        more = {} if obstacles is None else {'obstacles': obstacles}
        try:
            return robot.estimate_shape(lengths, tip_force=load[:3], tip_moment=load[3:],
                                        tensions=tensions, warm_start=warm, tracking=tracking,
                                        sensors=sensors, stamp=stamp, **more)
        except ValueError as error:
            if not np.any(load):
                raise
            notes['load_problem'] = ('the model has no finite shape under tip load %s (%s): '
                                     'using zero' % (np.array2string(load, precision=3), error))
            return robot.estimate_shape(lengths, tensions=tensions, warm_start=None,
                                        sensors=sensors, stamp=stamp, **more)


def passive_shape(robot, load, obstacles=None):
    """Return (shape, '') of a passive rod under gravity and ``load`` (6,), or (None, reason).

    ``obstacles`` as :attr:`ShapeTracker.obstacles` (None: the robot file's): the rod rests on
    them (``shape.contacts``). None when the rod has no equilibrium under that load (the last
    shape stays published).
    """
    try:
        if robot.obstacles_or_file(obstacles):  # no cables: the rod's own weight and the load
            return robot.solve_tensions(np.zeros(0), load[:3], load[3:],
                                        obstacles=obstacles), ''
        return robot.solve_bvp(tip_force=load[:3], tip_moment=load[3:]), ''
    except Exception as error:  # ConvergenceError, ValueError, a solver failure: never fatal
        return None, 'no equilibrium of the passive rod under %s: %s' % (
            np.array2string(np.asarray(load), precision=3), error)
