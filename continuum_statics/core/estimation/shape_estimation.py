"""Shape estimation: measured cable lengths (and tensions) + tip load -> shape (paper sec. V.A).

Unknowns: the solver state x = [u(0); each section's cable moment in the span its cables can
apply] (:mod:`continuum_statics.core.robot`). Equations: the model's cable lengths (eq. 11) match
the measurements in the least-squares sense, subject to the tip moment balance (three equations).
Cables cannot twist the rod and can only bend it about axes their holes span, so unobservable
bending stays at the passive equilibrium instead of being fixed by an arbitrary regulariser.
With measured tensions the shape is the forward statics of those tensions (the lengths then only
measure how well model and measurement agree), for ideal cables.

Real tendons (:mod:`continuum_statics.core.description.tendons`): a robot file with a tendon model
(stiffness,
pretension, friction or zero offsets) is estimated by the displacement-driven statics
(:func:`length_statics.solve_lengths`), which also gives each cable's tension and which are
slack; measured tensions are then compared with the model's (the motor-held lengths decide the
shape: a tension reading of a stretched, rubbing cable says less than its motor's position).
Ideal cables keep the least-squares fit above; when it misses the lengths by more than
:data:`SLACK_RESIDUAL` (a paid-out cable no taut shape explains) the same statics is tried, and
its shape is taken when it explains the lengths with some cables slack.
"""
import dataclasses
from dataclasses import dataclass
import functools
import math

import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.description.layout import ProbeRows
from continuum_statics.core.description.tendons import full_circle_tension
from continuum_statics.core.rod.least_squares import constrained_gauss_newton
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.rod.tracking import (
    DAMPING,
    SECANT_AGE,
    SECANT_FRACTION,
    TRACK_ITERATIONS,
    TRACK_RUNS,
    TrackLimits,
    TrackStart,
    WarmStart,
)
from continuum_statics.core.statics import bvp, length_statics
from continuum_statics.core.statics.attempts import first_answer
from continuum_statics.core.statics.length_statics import MOTION_THRESHOLD

#: Newton iterations a node's per-cycle tendon-model estimate may take when its warm start has
#: no Jacobian for chord steps (else the chord's refresh is the bound).
TENDON_NEWTON = 1
#: The same for trying ideal cables as slack (a rare event: a paid-out cable, not noise, since
#: the misfit is above the warn threshold), started from a least-squares fit: a few more.
SLACK_NEWTON = 3
#: Fraction of the encoders' noise to which a node's per-cycle tendon-model solve matches the
#: lengths: what is left moves the shape a tenth as far as the noise of that very measurement
#: does (solving it to the 1 nm estimate_tolerance took 3-5 chord steps instead of 1-2).
NOISE_FRACTION = 0.1
#: RMS length residual (m) above which an estimate says in its message that it is a best fit.
BEST_FIT_NOTE = 1e-6
#: RMS length residual (m) of the least-squares fit above which ideal cables are tried as slack
#: (statics' default warn_residual: below it lag and encoder noise, above it a paid-out cable).
SLACK_RESIDUAL = 1e-4
_NO_JACOBIAN = np.zeros((0, 0))  # tells track to use finite-difference Jacobians
_NO_VALUES, _NO_STATES = np.zeros(0), np.zeros((0, 0))  # tells track to integrate at the start
_UNBOUNDED = 2 ** 62  # model runs: no budget (the iteration limits bound the work)


@dataclass(frozen=True)
class Tracking:
    """How a node that tracks the robot estimates each measurement (bounded work per call).

    :ivar max_model_runs: IVPs a least-squares estimate may integrate per call (a Jacobian
        refresh begun inside may overrun it); an estimate that needs more is ``capped``; 0:
        until it converges (and the tendon model's solve too)
    :ivar slack_residual: RMS misfit (m) above which ideal cables are tried as slack (statics'
        warn threshold: at least 3 sigma of its encoders)
    :ivar motion_threshold: free-length change (m) that counts as a cable's motion, which sets
        its friction direction (3 sigma of its encoders: noise is not motion)
    :ivar length_noise: the encoders' sigma (m): the tendon model and the least squares solve
        each measurement's cable lengths to :data:`NOISE_FRACTION` of it (or
        ``solver.estimate_tolerance``)
    """

    max_model_runs: int = TRACK_RUNS
    slack_residual: float = SLACK_RESIDUAL
    motion_threshold: float = MOTION_THRESHOLD
    length_noise: float = 0.0

    def length_tolerance(self):
        """Cable-length tolerance (m) of one measurement's solve (tendon model, least squares).

        ``solve_lengths`` raises it to the robot's ``solver.estimate_tolerance``.
        """
        return NOISE_FRACTION * self.length_noise


#: What a warm-started ``Robot.estimate_shape`` does without a ``tracking`` of its own: the
#: statics node's defaults (its per-call budget, thresholds of noise-free encoders).
DEFAULT_TRACKING = Tracking()


@dataclass(frozen=True, eq=False)
class ShapeEstimate:
    """Result of :func:`estimate_shape`.

    :ivar shape: estimated backbone (its ``state`` warm-starts the next estimate)
    :ivar u0: estimated base bending (1/m)
    :ivar converged: the solver reached a stationary point with the tip balance satisfied
    :ivar residual: RMS difference between model and measured cable lengths (m)
    :ivar iterations: Gauss-Newton (or shooting) iterations used
    :ivar observable_bending: bending directions the cables observe (2 per section at most)
    :ivar message: what limited the estimate, empty when nothing did
    :ivar jacobians: a :class:`tracking.WarmStart`: the solver's Jacobians at the estimate (and
        the model there, the damping reached), reused by the next warm start
    :ivar model_runs: IVPs integrated (the cost of the estimate)
    :ivar tendons: the :class:`length_statics.LengthSolution` when the tendon model gave the shape
    :ivar slack_attempt: an unfinished try of ideal cables as slack (a
        :class:`length_statics.LengthSolution`), which the next measurement's try goes on from
    :ivar capped: an estimate left unfinished by its per-call bound (:class:`Tracking`): it
        spent its budget, or it made the model's own Jacobians after a failed secant step; the
        best state reached, and the next call, warm-started from it, goes on
    :ivar position_covariance: (N, 3, 3) m^2 of each backbone point at ``shape.s``, or None
        (the robot file has no ``model_uncertainty``): :mod:`state_estimation`
    :ivar tip_covariance: (6, 6) of the tip's position (m) and rotation (rad), base frame, or None
    :ivar unmodelled: the unmodelled loads explained so far, and the tip load of the file's
        ``load_model`` (:class:`state_estimation.Unmodelled`; :attr:`tip_wrench`)
    :ivar sensors: {name: :class:`sensors.SensorVerdict`} of the readings given
    :ivar tensions_verdict: the :class:`sensors.SensorVerdict` of the measured tensions when
        they were a measurement of the fused state (the robot file's ``tension_noise``), or None
    :ivar sensitivity: the load columns (:class:`state_estimation.Sensitivity`), kept for the
        next call
    :ivar history: the model's recent estimates ((stamp s, model shape, sensitivity), oldest
        first, :data:`state_estimation.HISTORY_SECONDS`): a late reading is compared with the
        model of its own stamp, or set aside when none is kept
    """

    shape: Shape
    u0: np.ndarray
    converged: bool
    residual: float
    iterations: int
    observable_bending: int
    message: str
    jacobians: tuple = None
    model_runs: int = 0
    tendons: object = None
    capped: bool = False
    slack_attempt: object = None
    unmodelled: object = None
    sensors: dict = None
    tensions_verdict: object = None
    sensitivity: object = None
    history: tuple = ()

    @functools.cached_property
    def position_covariance(self):
        """(N, 3, 3) m^2 of each backbone point at ``shape.s``; None without model_uncertainty."""
        if self.sensitivity is None:
            return None
        g = self.sensitivity.positions
        floor = self.unmodelled.point_variance(self.shape, self.shape.s)
        covariance = ((g @ self.unmodelled.covariance) @ g.transpose(0, 2, 1)
                      + floor[:, None, None] * np.eye(3))
        if self.unmodelled.tip_white is not None:  # a reading at the tip saw its white error
            covariance[-1] += self.unmodelled.tip_white[1][:3, :3] - floor[-1] * np.eye(3)
        return covariance

    @functools.cached_property
    def tip_covariance(self):
        """(6, 6) of the tip's position (m) and rotation (rad), base frame; or None."""
        if self.sensitivity is None:
            return None
        tip = np.concatenate([self.sensitivity.positions[-1], self.sensitivity.angles[-1]])
        covariance = tip @ self.unmodelled.covariance @ tip.T
        white = self.unmodelled.tip_white
        if white is None:
            covariance[:3, :3] += self.unmodelled.tip_variance * np.eye(3)
        else:
            covariance += white[1]
        return covariance

    @property
    def tip_wrench(self):
        """(6,) the file's ``load_model`` tip load [force N; moment N m], base frame; or None."""
        return None if self.unmodelled is None else self.unmodelled.tip_wrench

    @property
    def tip_wrench_covariance(self):
        """(6, 6) of :attr:`tip_wrench`; None without a load model."""
        return None if self.unmodelled is None else self.unmodelled.tip_wrench_covariance

    @property
    def tensions(self):
        """(n,) model tensions at the motors (N), or None when the fit did not use tendons."""
        return None if self.tendons is None else self.tendons.tensions

    @property
    def slack(self):
        """(n,) bool, cables carrying no tension, or None when the fit did not use tendons."""
        return None if self.tendons is None else self.tendons.slack

    @property
    def state(self):
        """Solver state x of the estimate."""
        return self.shape.state


def estimate_shape(robot, cable_lengths, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
                   tensions=None, start=None, jacobians=None, previous=None,
                   tracking=None):
    """Estimate the shape from measured cable lengths (m, ``robot.cable_names`` order).

    ``tip_force`` (N) and ``tip_moment`` (N m) are the external tip load in the base frame.
    ``tensions`` (N, >= 0) when measured; ``start`` a solver state (the previous estimate when
    tracking; default the small-deflection passive solution) and ``jacobians`` the previous
    estimate's, to be reused (one model run per iteration instead of 1 + len(state));
    ``previous`` the previous result itself (the tendon model's warm start and friction history);
    ``tracking`` a :class:`Tracking` when a node calls it once per measurement (bounded work,
    thresholds of its encoders' noise); None: solved to the end.
    The estimate is the first of :data:`ATTEMPTS` that gives one.
    """
    job = _Job.of(robot, cable_lengths, tip_force, tip_moment, tensions, start, jacobians,
                  previous, tracking)
    return first_answer(ATTEMPTS, job)


@dataclass(eq=False)
class _Job:
    """One estimate's inputs and what its attempts hand on (the start, the model runs)."""

    robot: object
    measured: np.ndarray  #: (n,) lengths, m
    tip_force: np.ndarray
    tip_moment: np.ndarray
    tensions: np.ndarray  #: (n,) measured tensions (N) or None
    start: np.ndarray  #: solver state the least squares go on from (None: not yet chosen)
    jacobians: tuple  #: the previous estimate's :class:`WarmStart` (None: none to reuse)
    previous: object  #: the previous result
    tracking: Tracking  #: a node's per-cycle bounds, or None: solved to the end
    notes: list  #: what limited the estimate so far
    runs: int = 0  #: IVPs integrated
    cold: bool = False  #: started on the passive rod's Jacobians

    @classmethod
    def of(cls, robot, cable_lengths, tip_force, tip_moment, tensions, start, jacobians,
           previous, tracking):
        """Validate the inputs (``ValueError`` saying what is wrong) into a job."""
        n_cables = len(robot.cable_names)
        measured = as_vector(cable_lengths, n_cables, 'cable_lengths')
        if tensions is not None:
            tensions = as_vector(tensions, n_cables, 'tensions')
            if np.any(tensions < 0.0):
                raise ValueError('tensions must be >= 0 N, got %s'
                                 % np.round(tensions, 6).tolist())
        notes = []
        observable = robot.observable_bending
        if observable < 2 * max(len(robot.sections), 1) and n_cables:
            notes.append('%d cable(s) observe %d of %d bending directions; the rest is held at '
                         'the passive equilibrium' % (n_cables, observable,
                                                      2 * len(robot.sections)))
        return cls(robot, measured, as_vector(tip_force, 3, 'tip_force'),
                   as_vector(tip_moment, 3, 'tip_moment'), tensions, start, jacobians, previous,
                   tracking, notes)

    @property
    def bounded(self):
        """A node's per-cycle call: bounded work unless its budget is 0 (until it converges)."""
        return self.tracking is not None and bool(self.tracking.max_model_runs)

    @property
    def slack_residual(self):
        """RMS misfit (m) above which ideal cables are tried as slack."""
        return SLACK_RESIDUAL if self.tracking is None else self.tracking.slack_residual

    @property
    def load(self):
        """(6,) the tip force and moment."""
        return np.concatenate([self.tip_force, self.tip_moment])

    def tendon_estimate(self, notes, tracking):
        """Return the displacement-driven statics of these lengths (:func:`_tendon_estimate`)."""
        return _tendon_estimate(self.robot, self.measured, self.tip_force, self.tip_moment,
                                self.previous, self.robot.observable_bending, notes, tracking)

    def slack_estimate(self, residual, tracking):
        """Return (estimate or None, unfinished try) of ideal cables as slack."""
        return _slack_estimate(self.robot, self.measured, self.tip_force, self.tip_moment,
                               self.previous, self.robot.observable_bending, self.notes,
                               residual, tracking, self.slack_residual)

    def finish(self, tracked, carry, capped=False, slack_attempt=None):
        """Return the estimate at a compiled solve's state (``_finish``)."""
        return _finish(self.robot, tracked.x, self.tip_force, tracked.states, tracked.residual,
                       tracked.ok, tracked.iterations, self.robot.observable_bending,
                       self.notes, carry, self.runs, capped=capped, slack_attempt=slack_attempt)


def _tendon_model(job):
    """Estimate tendon robots: the motor-held lengths decide the shape (stretch, slack, friction).

    Measured tensions are compared with the model's. A cable that turns round the rod (the
    distributed model) has no section moment coordinates (the least-squares unknowns): its
    tension is one, so such a robot takes this path too.
    """
    robot = job.robot
    if robot.tendons.is_ideal and (robot.routing.straight or robot.cable_model != 'distributed'):
        return None
    estimate = job.tendon_estimate(job.notes, job.tracking)
    if job.tensions is not None:
        off = _rms(estimate.tendons.tensions - job.tensions)
        estimate = dataclasses.replace(estimate, message='; '.join(filter(None, [
            estimate.message, "measured tensions %.3g N RMS from the tendon model's" % off])))
    return estimate


def _measured_tensions(job):
    """Estimate ideal cables with measured tensions: the forward statics of those tensions."""
    if job.tensions is None:
        return None
    robot, notes = job.robot, job.notes
    try:
        state = bvp.solve_loaded(robot, robot.passive_state(), job.tensions, job.tip_force,
                                 job.tip_moment, job.start)
        converged = True
    except bvp.ConvergenceError as error:
        state, converged = robot.passive_state(), False
        notes.insert(0, str(error))
    states = robot.integrate_state(state, job.tip_force, job.tensions)
    shape = robot.make_shape(state, job.tip_force, states, job.tensions)
    residual = _rms(robot.cable_lengths(shape) - job.measured)
    notes.insert(0, 'shape from the measured tensions')
    return _result(shape, converged, residual, 0, robot.observable_bending, notes)


def _still_slack(job):
    """Try the tendon model first when a cable was paid out at the last measurement.

    It is most likely still slack.

    Kept only when it explains the lengths (ideal cables that all end up shorter than any shape
    allows have no equilibrium: then the least squares, as without slack).
    """
    paid_out = getattr(getattr(job.previous, 'tendons', None), 'slack_lengths', None)
    if paid_out is None or not np.any(paid_out > job.slack_residual):
        return None
    slack = job.tendon_estimate(list(job.notes), job.tracking)
    return slack if _plausible(job.robot, slack) else None


def _tracked(job):
    """Solve the compiled least squares on the previous estimate's Jacobians, Broyden-updated.

    A cold estimate starts on the passive rod's Jacobians (known per robot and load: most cold
    starts are near it; a bent one refreshes them on the way). A node's bounded call returns
    its best state, ``capped``; an estimate solved to the end goes on from there.
    """
    robot, tracking = job.robot, job.tracking
    if job.start is None and job.jacobians is None:
        misses = _passive_start.cache_info().misses
        job.start, job.jacobians = _passive_start(robot, tuple(job.tip_force),
                                                  tuple(job.tip_moment))
        job.cold = True
        if _passive_start.cache_info().misses > misses:
            job.runs += robot.probe_runs  # integrated now for this robot and load
    elif job.start is None:
        job.start = robot.passive_state(bvp.linear_guess(robot, job.tip_force, job.tip_moment))
    if job.jacobians is None:
        return None
    load = job.load
    carry = WarmStart(*job.jacobians)
    same_load = np.array_equal(carry.load, load)
    known = carry.values.shape[0] and same_load
    tracked = robot.model.track(
        job.tip_force, job.tip_moment, np.zeros(len(job.measured)), job.measured,
        # under another tip load they are not the model's own here (age 0 says they are)
        TrackStart(job.start, carry.jac, carry.con_jac, carry.damping,
                   carry.values if known else _NO_VALUES, carry.states,
                   carry.age if same_load else max(carry.age, 1)),
        # a node's call to NOISE_FRACTION of its encoders' noise, as the tendon model's: most
        # second Gauss-Newton steps predicted less, and cost one IVP plus up to three failed
        # chord corrections (tendon_robot at 1 kHz: 2.8 IVPs a call on average)
        TrackLimits(max(robot.solver.estimate_tolerance,
                        tracking.length_tolerance() if job.bounded else 0.0),
                    robot.length, TRACK_ITERATIONS,
                    robot.probe_runs, tracking.max_model_runs if job.bounded else _UNBOUNDED,
                    SECANT_FRACTION if job.bounded else 0.0))
    job.runs += tracked.runs
    age = tracked.age
    if job.cold and age:
        # secant updates of the straight rod's Jacobians: the next (warm) call makes the
        # model's own first (probe_runs IVPs, 40 of 170 us on a single section, which a one-off
        # estimate never needs)
        age = SECANT_AGE + 1
    if tracked.ok:
        slack, attempt = job.slack_estimate(_rms(tracked.residual), tracking)
        return slack or job.finish(tracked, _carry(tracked, job, DAMPING, age),
                                   slack_attempt=attempt)
    if job.bounded:
        # bounded work per measurement: the best state reached; the next call goes on
        job.notes.insert(0, 'unfinished after %d model runs%s: refined with the next '
                            'measurement' % (job.runs, ' (max_model_runs %d)'
                                             % tracking.max_model_runs
                                             if job.runs >= tracking.max_model_runs else ''))
        return job.finish(tracked, _carry(tracked, job, tracked.damping, age), capped=True)
    job.start = tracked.x  # keep the progress; go on as from a cold start
    return None


def _finite_differences(job):
    """Solve by the same compiled loop with finite-difference Jacobians at every evaluation."""
    robot = job.robot
    tracked = robot.model.track(
        job.tip_force, job.tip_moment, np.zeros(len(job.measured)), job.measured,
        TrackStart(job.start, _NO_JACOBIAN, _NO_JACOBIAN, DAMPING, _NO_VALUES, _NO_STATES, 0),
        TrackLimits(robot.solver.estimate_tolerance, robot.length, robot.solver.max_iterations,
                    robot.probe_runs, _UNBOUNDED, 0.0))
    job.runs += tracked.runs
    if tracked.ok:
        slack, _ = job.slack_estimate(_rms(tracked.residual), None)
        return slack or job.finish(tracked, _carry(tracked, job, DAMPING, 0))
    job.start = tracked.x  # keep the progress; go on in Python (longer line search)
    return None


def _python_newton(job):
    """Solve by the last resort: the constrained Gauss-Newton in Python (longer line search)."""
    robot, measured = job.robot, job.measured
    rows = ProbeRows(len(measured))

    def evaluate(x):
        job.runs += robot.probe_runs
        probed = robot.probe(x, robot.state_size, job.tip_force, job.tip_moment)
        values, jac = probed.values, probed.jacobian
        return (values[rows.lengths] - measured, jac[rows.lengths], values[rows.balance],
                jac[rows.balance], probed.states)

    result = constrained_gauss_newton(
        evaluate, job.start, robot.solver.max_iterations, robot.solver.estimate_tolerance,
        constraint_weight=robot.length)
    slack, _ = job.slack_estimate(_rms(result.residual), None)
    if slack is not None:
        return slack
    return _finish(robot, result.x, job.tip_force, result.evaluation, result.residual,
                   result.stationary, result.iterations, robot.observable_bending, job.notes,
                   WarmStart(*result.jacobians), job.runs)


#: The strategies of :func:`estimate_shape`, in the order they are tried: each answers, or
#: passes (None) to the next, handing on its progress (``_Job.start``).
ATTEMPTS = (_tendon_model, _measured_tensions, _still_slack, _tracked, _finite_differences,
            _python_newton)


def _finish(robot, x, tip_force, states, length_residual, stationary, iterations, observable,
            notes, jacobians, runs, capped=False, slack_attempt=None):
    """Build the estimate record, with notes on convergence and on the fit."""
    residual = _rms(length_residual)
    if not stationary and not capped:  # a capped estimate's note says why already
        notes.insert(0, 'not converged in %d iterations' % iterations)
    if residual > BEST_FIT_NOTE:
        notes.insert(0, 'best fit: the lengths fit no shape to RMS %.3g m' % residual)
    shape = robot.make_shape(x, tip_force, states)
    return _result(shape, stationary, residual, iterations, observable, notes, jacobians, runs,
                   capped=capped, slack_attempt=slack_attempt)


def _slack_estimate(robot, measured, tip_force, tip_moment, previous, observable, notes,
                    residual, tracking, slack_residual):
    """Return the tendon model's estimate when it explains lengths least squares missed.

    Returns (estimate or None, unfinished attempt or None). The estimate is None when the
    least-squares fit was within ``slack_residual`` or the tendon model did no better (lengths
    no taut-or-slack shape has either: noise, a wrong file), or only with tensions no cable
    takes (inextensible cables pulled in against the rod's axial stiffness: above the
    full-circle tension or a tension limit). A node's bounded try that did not finish cannot be
    judged yet: it is handed back, and the next measurement's try goes on from it.
    """
    if residual <= slack_residual or not len(measured):
        return None, None
    slack = _tendon_estimate(robot, measured, tip_force, tip_moment, previous, observable,
                             list(notes), tracking)
    if _plausible(robot, slack) and slack.residual < residual:
        return slack, None
    return None, slack.tendons if slack.capped else None


def _plausible(robot, estimate):
    """Whether a tendon-model estimate of ideal cables converged with tensions a cable takes.

    Inextensible cables pulled in against the rod's axial stiffness "converge" with thousands of
    N: above the full-circle tension or a tension limit the lengths fit no shape.
    """
    limit = min(full_circle_tension(robot), float(np.min(robot.tendons.tension_limits[:, 1])))
    return estimate.converged and np.max(estimate.tensions, initial=0.0) <= limit


def _tendon_estimate(robot, measured, tip_force, tip_moment, previous, observable, notes,
                     tracking=None):
    """Return the estimate of the displacement-driven statics (slack, stretch, friction).

    ``tracking``: a node's per-cycle call (chord steps with one Jacobian refresh, or
    :data:`TENDON_NEWTON` / :data:`SLACK_NEWTON` Newton iterations when the warm start has no
    Jacobian; an unfinished result is ``capped``; its motion threshold).
    """
    warm = (getattr(previous, 'tendons', None) or getattr(previous, 'slack_attempt', None)
            or previous)
    # ideal cables only try it (the least squares are the fallback): no slow last resort
    solution = length_statics.solve_lengths(
        robot, measured, tip_force, tip_moment, warm, continuation=not robot.tendons.is_ideal,
        max_newton=((TENDON_NEWTON if not robot.tendons.is_ideal else SLACK_NEWTON)
                    if tracking and tracking.max_model_runs else None),
        motion_threshold=tracking.motion_threshold if tracking else MOTION_THRESHOLD,
        tolerance=tracking.length_tolerance() if tracking else None)
    if solution.message:
        notes.insert(0, solution.message)
    if np.any(solution.slack):
        notes.append('slack: %s' % ', '.join(
            name for name, slack in zip(robot.cable_names, solution.slack) if slack))
    estimate = _result(solution.shape, solution.converged, solution.residual,
                       solution.iterations, observable, notes, tendons=solution)
    if tracking and tracking.max_model_runs and not solution.converged and warm is not None:
        return dataclasses.replace(estimate, capped=True)
    return estimate


@functools.lru_cache(maxsize=32)
def _passive_start(robot, tip_force, tip_moment):
    """Return the passive rod's state under a tip load and its :class:`WarmStart`."""
    force, moment = np.array(tip_force), np.array(tip_moment)
    state = robot.passive_state(bvp.linear_guess(robot, force, moment))
    rows = ProbeRows(len(robot.cable_names))
    probed = robot.probe(state, robot.state_size, force, moment)
    values, jac = probed.values, probed.jacobian
    model = np.concatenate([values[rows.lengths], values[rows.balance]])
    return state, WarmStart(np.ascontiguousarray(jac[rows.lengths]),
                            np.ascontiguousarray(jac[rows.balance]), DAMPING, model,
                            probed.states.copy(), np.concatenate([force, moment]))


def _carry(tracked, job, damping, age):
    """Return the :class:`WarmStart` of an estimate (its model values save the next an IVP)."""
    return WarmStart(tracked.jac, tracked.con_jac, damping,
                     np.concatenate([tracked.residual + job.measured, tracked.balance]),
                     tracked.states.copy(), job.load, age)


def _rms(values):
    return math.sqrt(float(values @ values) / len(values)) if len(values) else 0.0


def _result(shape, converged, residual, iterations, observable, notes, jacobians=None, runs=0,
            tendons=None, capped=False, slack_attempt=None):
    return ShapeEstimate(shape=shape, u0=shape.u0, converged=bool(converged), residual=residual,
                         iterations=iterations, observable_bending=observable,
                         message='; '.join(notes), jacobians=jacobians, model_runs=runs,
                         tendons=tendons, capped=capped, slack_attempt=slack_attempt)
