"""Displacement-driven forward statics: the motors hold cable lengths, the rod and cables settle.

Unknowns z = [u(0) (3, 1/m); t (n_cables, N), each cable's tension at its end disk]. Equations:
- the tip moment balance (:func:`kernel.probe` rows ``balance``, three equations), the shooting
  condition of every solver here (paper sec. III.E);
- per cable, the complementarity of a cable that cannot push
  (:mod:`continuum_statics.core.description.tendons`): t >= 0, g = Lf - sum_i p_i / (1 + T_i / EA)
  >= 0,
  t g = 0, where p_i are the straight hole-to-hole spans of its path (eq. 11 with the errata)
  and T_i their tensions. Written as the
  semismooth equation min(kappa t, g) = 0 (kappa scales N to m), solved by Newton's method with a
  backtracking line search on the squared residual and least-norm steps (tensions an inextensible
  antagonist pair cannot tell apart stay as small as the start allows).

Friction (capstan, Euler-Eytelwein): across a guide hole where the cable's direction turns by the
wrap angle theta, the tension changes by the factor exp(mu theta), rising toward the motor while
the motor pulls (the cable slides toward the motor) and falling while it pays out. A cable's last
direction of motion comes from ``warm_start`` (its free length then and now); segment i then
carries T_i = t exp(sigma mu sum of the wraps between it and the end disk), sigma = +1 pulled,
-1 released, 0 unknown (a cold start), and in between while the guides stick after a reversal
(``tendons.stick_length``: the state turns over that much travel, :func:`motion_since`). Friction
thus changes how much a cable stretches for the same end tension, so pulling and releasing to
the same motor position give different shapes. Limits: the holes' friction forces load the rod
only through that stretch (the point-moment model loads the end disk alone; the distributed
model takes the end tension all along the cable), the run from the motor to the base disk is
straight and folded into EA, and a stick zone is one state per cable (the same fraction of the
capstan band at every hole), not a tension per hole.
"""
from dataclasses import dataclass
import functools
from typing import NamedTuple

import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.description.layout import ProbeRows
from continuum_statics.core.rod.kernel import POINT_MOMENT
from continuum_statics.core.rod.length_tracking import (
    BALANCE_TOLERANCE,
    ChordLimits,
    Pieces,
    TendonArgs,
)
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.statics import bvp
from continuum_statics.core.statics.attempts import first_answer

_NO_VALUES, _NO_STATES = np.zeros(0), np.zeros((0, 0))  # tell chord to integrate at its start
#: Capstan coefficient below which a cable is taken as frictionless (exp(2 pi mu) - 1 < 1e-8).
NEGLIGIBLE_FRICTION = 1e-9
#: Free-length change (m) below which a cable is taken as not moving (its friction sign is kept).
MOTION_THRESHOLD = 1e-7
#: Chord steps on a warm start's Jacobian before a fresh Newton solve.
CHORD_ITERATIONS = 6
#: Step halvings per Newton iteration of a bounded (per-cycle) call.
BOUNDED_BACKTRACKS = 4
#: Jacobian refreshes (4 + n IVPs each, compiled) a warm solve may take before that Newton solve.
CHORD_REFRESHES = 1
#: End tension (relative to E I / (L r)) at or below which a cable counts as slack.
SLACK_TENSION = 1e-9


@dataclass(frozen=True, eq=False)
class LengthSolution:
    """Equilibrium of rod and cables for motor-held lengths (:func:`solve_lengths`).

    :ivar shape: the backbone (``shape.state`` warm-starts other solvers)
    :ivar tensions: (n,) N at the motor, what a motor's current or a load cell measures
    :ivar end_tensions: (n,) N at each cable's end disk, what bends the rod
    :ivar slack: (n,) bool, cables that carry no tension (path no longer than the cable)
    :ivar converged: balance and complementarity reached their tolerances
    :ivar message: what limited the solve, empty when nothing did
    :ivar free_lengths: (n,) m, unstretched lengths Lf (the next solve's motion reference)
    :ivar motion: (n,) friction state: +1 last pulled, -1 last paid out, 0 unknown, between
        while a cable's guides stick after a reversal (:func:`motion_since`)
    :ivar iterations: Newton iterations
    :ivar residual: largest complementarity residual (m)
    """

    shape: Shape
    tensions: np.ndarray
    end_tensions: np.ndarray
    slack: np.ndarray
    converged: bool
    message: str
    free_lengths: np.ndarray
    motion: np.ndarray
    iterations: int = 0
    residual: float = 0.0
    jacobian_parts: tuple = None  # the last Jacobian pieces: the next warm call starts on them
    slack_lengths: np.ndarray = None  # (n,) m by which each cable is longer than its path
    model_at: object = None  # the model at the solution (:class:`ModelAt`), for the next call
    motion_reference: np.ndarray = None  # (n,) m, free lengths where each cable last moved

    @property
    def state(self):
        """Solver state x of the shape (see :mod:`continuum_statics.core.robot`)."""
        return self.shape.state


class _Problem:
    """One solve's fixed data and the evaluation of the residual F(z) and its Jacobian."""

    def __init__(self, robot, free_lengths, motion, tip_force, tip_moment,
                 motion_reference=None):
        self.robot = robot
        self.motion_reference = motion_reference  # where each cable last moved (m)
        self.balance_tolerance = BALANCE_TOLERANCE  # of a converged solve, relative
        self.tolerance = robot.solver.estimate_tolerance  # cable rows, m
        self.n = len(robot.cable_names)
        self.free = free_lengths
        self.motion = motion
        self.tip_force, self.tip_moment = tip_force, tip_moment
        constants = problem_constants(robot)
        self.rows, self.compliance, self.base_axis = (constants.rows, constants.compliance,
                                                      constants.base_axis)
        self.radius, self.t_ref, self.kappa = constants.radius, constants.t_ref, constants.kappa
        self.scale, self.moment_map = constants.scale, constants.moment_map
        self.kernel_moment_map = constants.kernel_map
        # no -0.0: ModelAt compares the bytes
        self.friction = constants.friction * motion + 0.0
        self.with_friction = bool(self.friction.any())

    def tendon_args(self):
        """Return the problem's :class:`length_tracking.TendonArgs` (what compiled steps read)."""
        return TendonArgs(self.kernel_moment_map, self.free, self.friction, self.compliance,
                          self.base_axis, self.kappa, self.radius)

    def state_of(self, z):
        """Solver state x and fixed tensions of z (the robot's solver-state convention)."""
        x = self.robot.passive_state(z[:3])
        if self.moment_map is not None:
            x[3:] = self.moment_map @ z[3:]
            return x, None
        return x, z[3:].copy()

    def evaluate(self, z, parts=None):
        """Residual F (3 + n, scaled), its Jacobian in scaled z, states and cable quantities.

        With ``parts`` (the Jacobian's pieces of an earlier evaluation, a chord step) only the
        nominal IVP is run and those pieces make the Jacobian; returns (F, J, info, parts).
        """
        robot, n, rows = self.robot, self.n, self.rows
        x, fixed = self.state_of(z)
        point_columns = parts is None and fixed is None  # the point model's, with the nominal
        probed = robot.probe(x, robot.state_size if point_columns else 0, self.tip_force,
                             self.tip_moment, fixed)
        values, jac_x, states = probed.values, probed.jacobian, probed.states
        t = z[3:]
        paths = values[rows.lengths]
        consumed, motor, mean = self.consumed(states, paths, t)
        gap = self.free - consumed
        chord = parts is not None
        if point_columns:
            jac = np.empty((jac_x.shape[0], 3 + n))
            jac[:, :3] = jac_x[:, :3]
            jac[:, 3:] = jac_x[:, 3:] @ self.moment_map
            # d consumed / dz with the friction profile held (exact without friction)
            stretch = 1.0 + mean * self.compliance
            d_consumed = jac[rows.lengths] / stretch[:, None]
            d_consumed[:, 3:] -= np.diag(paths * self.compliance / stretch ** 2)
            parts = (jac[rows.balance], d_consumed)
        elif not chord:  # tension columns too: one compiled batch of 4 + n IVPs
            parts = robot.model.jacobian_pieces(self.tip_force, self.tip_moment,
                                                np.asarray(z, dtype=float),
                                                self.kernel_moment_map, self.compliance, mean,
                                                1e-7 * self.t_ref)
        taut = self.kappa * t >= gap
        residual = np.concatenate([values[rows.balance],
                                   np.where(taut, gap, self.kappa * t) / self.radius])
        # a chord step (parts given) assembles its Jacobian itself, when the branches change
        jacobian = None if chord else self.jacobian(parts, taut)
        return residual, jacobian, (x, fixed, states, motor, gap, taut), parts

    def jacobian(self, parts, taut):
        """Jacobian in scaled z of the residual, for the cables' branches ``taut``."""
        n = self.n
        balance, d_consumed = parts
        jacobian = np.zeros((3 + n, 3 + n))
        jacobian[:3] = balance
        jacobian[3:] = np.where(taut[:, None], -d_consumed,
                                np.hstack([np.zeros((n, 3)), self.kappa * np.eye(n)]))
        jacobian[3:] /= self.radius
        return jacobian * self.scale

    def consumed(self, states, paths, t):
        """Free length each cable's path takes (m), motor-side tension (N), mean tension (N)."""
        if not self.with_friction:
            return paths / (1.0 + t * self.compliance), t.copy(), t.copy()
        return self.robot.model.path_stretch(states, self.base_axis, np.ascontiguousarray(t),
                                             self.friction, self.compliance)


class ProblemConstants(NamedTuple):
    """A robot's fixed data of the tendon problem (:func:`problem_constants`)."""

    rows: ProbeRows
    compliance: np.ndarray  #: (n,) 1 / EA of each cable (1/N)
    base_axis: np.ndarray  #: (3,) the rod's axis at the base, global
    radius: float  #: mean hole radius (m): the scale of the cable rows
    t_ref: float  #: tension scale E I / (L radius) (N)
    kappa: float  #: m per N in the semismooth min(kappa t, g)
    scale: np.ndarray  #: (3 + n,) scales of z
    moment_map: np.ndarray  #: ``tension_moment_map`` (point-moment model) or None
    kernel_map: np.ndarray  #: the same, or zeros of its shape: what the compiled code reads
    friction: np.ndarray  #: (n,) capstan coefficients, negligible ones as 0


@functools.lru_cache(maxsize=16)
def problem_constants(robot) -> ProblemConstants:
    """Return a robot's fixed problem data (per call it cost more than the compiled solve)."""
    n = len(robot.cable_names)
    base_axis = np.ascontiguousarray(robot.base_rotation[:, 2])
    radius = np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1])
    # scales: u(0) L, t / t_ref and lengths / r are O(angle) for bends of O(1 rad)
    radius = float(np.mean(radius)) if n else 1.0
    t_ref = robot.c[0] / (robot.length * radius)
    kappa = radius / t_ref  # m per N in min(kappa t, g)
    scale = np.concatenate([np.full(3, 1.0 / robot.length), np.full(n, t_ref)])
    moment_map = robot.tension_moment_map if robot.model_code == POINT_MOMENT else None
    # the compiled chord reads an array of that shape whatever the model
    kernel_map = (moment_map if moment_map is not None
                  else np.zeros((robot.state_size - 3, n)))
    # a capstan factor within 1e-8 of 1 over a full turn is none (a fit that found no friction
    # writes ~1e-13): the frictionless path is much cheaper than the wrap of every hole
    friction = np.where(robot.tendons.friction > NEGLIGIBLE_FRICTION, robot.tendons.friction, 0.0)
    return ProblemConstants(ProbeRows(n), robot.tendons.compliance, base_axis, radius, t_ref,
                            kappa, scale, moment_map, kernel_map, friction)


def motion_since(robot, free_lengths, warm_start, threshold=MOTION_THRESHOLD):
    """Each cable's friction state and motion reference (m) after ``warm_start``.

    The state sigma in [-1, 1] scales the capstan exponent (+1: sliding toward the motor, the
    cable pulled; -1: paid out; 0: unknown, a cold start). A cable whose free length moved more
    than ``threshold`` (m) from its reference (where it was when it last moved) moves its state
    and its reference along; else both stay, so encoder noise under the threshold never
    changes friction and slow motion still counts once it adds up. The state turns at once
    (sigma = the sign of the motion) or, for a cable with ``tendons.stick_length`` s > 0,
    linearly from one end to the other over s of travel: after a reversal its guides stick
    first, the tension on either side of a hole differing by less than the capstan limit, and
    the cable slides through the holes once the difference reaches it (a stick zone; Dahl's
    friction model).
    """
    previous = getattr(warm_start, 'motion_reference', None)
    if previous is None:
        previous = getattr(warm_start, 'free_lengths', None)
    last = getattr(warm_start, 'motion', None)
    n = len(robot.cable_names)
    motion = np.zeros(n) if last is None or len(last) != n else np.array(last, dtype=float)
    if previous is None or len(previous) != n:
        return motion, free_lengths.copy()
    change = free_lengths - previous
    moved = np.abs(change) > threshold
    if not moved.any():  # the common case at rest: nothing turns (half the cost)
        return motion, np.array(previous, dtype=float)
    turned = turned_state(robot, motion, change)
    motion[moved] = turned[moved] + 0.0  # no -0.0: ModelAt compares the bytes
    return motion, np.where(moved, free_lengths, previous)


def turned_state(robot, motion, change):
    """Return each cable's friction state (n,) after its free length changed by ``change`` (m).

    At once to the sign of the motion, or for ``tendons.stick_length`` s > 0 a full turn, +1 to
    -1, over s of travel (:func:`motion_since`).
    """
    stick = robot.tendons.stick_length
    return np.where(stick > 0.0, np.clip(
        motion - 2.0 * change / np.where(stick > 0.0, stick, 1.0), -1.0, 1.0), -np.sign(change))


def solve_lengths(robot, lengths, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
                  warm_start=None, continuation=True, max_newton=None,
                  motion_threshold=MOTION_THRESHOLD, tolerance=None):
    """Equilibrium when the motors hold cable ``lengths`` (m, motor side, cable_names order).

    ``tip_force`` (N) and ``tip_moment`` (N m) in the base frame; ``warm_start`` the previous
    :class:`LengthSolution` of the same sequence (its state starts the solve and its free lengths
    give each cable's direction of motion for friction). Never raises for a failed solve: then
    ``converged`` is False and ``message`` says why; bad arguments raise ``ValueError``.
    ``continuation`` False skips the slow last resort (a try whose failure has a fallback).
    ``max_newton`` bounds the work of a warm-started call (a node's per-cycle budget): the chord
    steps (with one Jacobian refresh) when the warm start has a Jacobian, else at most that many
    Newton iterations from it, and nothing else; the
    next call goes on from the result, and the balance is solved to the lengths' tolerance
    (``tolerance`` over the holes' radius). ``motion_threshold``: free-length
    change (m) that counts as a cable's motion for its friction direction (:func:`motion_since`).
    ``tolerance``: on the cable rows (m; default ``solver.estimate_tolerance``), e.g. a fraction
    of the encoders' noise for a node's per-cycle call.
    """
    n = len(robot.cable_names)
    lengths = as_vector(lengths, n, 'lengths')
    tip_force = as_vector(tip_force, 3, 'tip_force')
    tip_moment = as_vector(tip_moment, 3, 'tip_moment')
    free = robot.tendons.free_lengths(lengths, robot.straight_cable_lengths)
    if n and free.min() <= 0.0:
        raise ValueError('lengths give non-positive free lengths for cables %s'
                         % [name for name, f in zip(robot.cable_names, free) if f <= 0.0])
    motion, reference = motion_since(robot, free, warm_start, motion_threshold)
    problem = _Problem(robot, free, motion, tip_force, tip_moment, reference)
    if tolerance is not None:
        problem.tolerance = max(float(tolerance), robot.solver.estimate_tolerance)
    if max_newton is not None:
        # a per-cycle call solves the balance to the lengths' tolerance: a balance error b
        # (an angle over the rod) moves a cable at radius r by about r b
        problem.balance_tolerance = max(BALANCE_TOLERANCE, problem.tolerance / problem.radius)
    job = _LengthJob(robot, problem, warm_unknowns(robot, warm_start), warm_start, max_newton,
                     continuation)
    return first_answer(LENGTH_ATTEMPTS, job)


@dataclass(eq=False)
class _LengthJob:
    """One solve's problem and what its attempts hand on (the warm start, the iterations)."""

    robot: object
    problem: '_Problem'
    warm: np.ndarray  #: unknowns z of the warm start (progress replaces it), or None
    warm_start: object  #: the previous result
    max_newton: int  #: a node's per-cycle bound, or None
    continuation: bool  #: the slow last resort is allowed
    iterations: int = 0
    linear: np.ndarray = None  #: the small-deflection start (continuation starts there)

    @property
    def bounded(self):
        """A node's per-cycle call from a warm start: bounded work."""
        return self.max_newton is not None and self.warm is not None

    def answer(self, z, info, converged, message='', parts=None, model=None):
        """Return the :class:`LengthSolution` at z."""
        return _solution(self.robot, self.problem, z, info, converged, self.iterations, message,
                         parts, model)


def _chord_steps(job):
    """Take compiled quasi-Newton steps on the last solve's Jacobian pieces (one IVP each).

    A node's bounded call whose chord refreshed its Jacobian and still gave up answers from
    there (the next call goes on); otherwise its progress starts Newton.
    """
    n = len(job.robot.cable_names)
    parts = getattr(job.warm_start, 'jacobian_parts', None)
    if job.warm is None or parts is None or parts[0].shape != (3, 3 + n):
        return None
    z, ok, iterations, info, parts, model = _chord(job.problem, job.warm, parts, job.warm_start)
    job.iterations += iterations
    if ok:
        return job.answer(z, info, True, parts=parts, model=model)
    job.warm = z  # keep the progress
    if job.bounded:
        return job.answer(z, info, False, 'unfinished (chord steps on a refreshed Jacobian): '
                          'refined with the next measurement', parts)
    return None


def _bounded_newton(job):
    """Take a few Newton iterations from the warm start: a node's call with no Jacobian."""
    if not job.bounded:
        return None
    z, ok, iterations, info, parts = _newton(job.problem, job.warm, job.max_newton,
                                             BOUNDED_BACKTRACKS)
    job.iterations += iterations
    return job.answer(z, info, ok, '' if ok else 'unfinished after %d Newton iterations (the '
                      'per-call bound): refined with the next measurement' % job.max_newton,
                      parts)


def _full_newton(job):
    """Solve by Newton from the warm start, then from the small-deflection (linear) guess."""
    robot, problem = job.robot, job.problem
    starts = [] if job.warm is None else [job.warm]
    starts.append(np.concatenate([bvp.linear_guess(robot, problem.tip_force, problem.tip_moment),
                                  np.zeros(len(robot.cable_names))]))
    for z0 in starts:
        z, ok, iterations, info, parts = _newton(problem, z0)
        job.iterations += iterations
        if ok:
            return job.answer(z, info, True, parts=parts)
    job.linear = starts[-1]
    if not job.continuation:
        return job.answer(z, info, False, 'no equilibrium found from the warm or the '
                          'small-deflection start', parts)
    return None


def _load_continuation(job):
    """Move the free lengths from the passive rod's paths in increments (the last resort)."""
    z, ok, iterations, info, parts = _continuation(job.robot, job.problem, job.linear)
    job.iterations += iterations
    message = '' if ok else ('no equilibrium found for these lengths (cable residual %.3g m '
                             'after load continuation)' % _cable_residual(info))
    return job.answer(z, info, ok, message, parts)


#: The strategies of :func:`solve_lengths`, in the order they are tried.
LENGTH_ATTEMPTS = (_chord_steps, _bounded_newton, _full_newton, _load_continuation)


def warm_unknowns(robot, warm_start):
    """Unknowns z of a previous result (u(0) and end tensions), or None."""
    shape = getattr(warm_start, 'shape', warm_start)
    state = getattr(shape, 'state', None)
    if state is None or len(state) != robot.state_size or not np.all(np.isfinite(state)):
        return None
    tensions = getattr(warm_start, 'end_tensions', None)
    if tensions is None or len(tensions) != len(robot.cable_names):
        tensions = np.zeros(len(robot.cable_names))
    return np.concatenate([state[:3], tensions])


def _chord(problem, z0, parts, warm_start):
    """Quasi-Newton steps from the previous solve's Jacobian (one IVP each, compiled).

    A tracking sequence moves little between calls, so the last Jacobian (with each cable's
    branch of now), corrected by a Broyden update after every step, still contracts the error;
    it gives up as soon as a step gains less than half (:func:`length_tracking.chord`).
    Returns (z, ok, iterations, info, parts, model): the updated Jacobian pieces start the next
    call, and so does the model at z (:class:`ModelAt`) when its load and friction are the same.
    """
    robot = problem.robot
    known = getattr(warm_start, 'model_at', None)
    if known is not None and not known.holds_for(problem):
        known = None
    if known is not None:
        z0 = known.z  # the z the model was integrated at (a slack tension reads 0 elsewhere)
    done = robot.model.chord(
        problem.tip_force, problem.tip_moment, np.asarray(z0, dtype=float),
        problem.tendon_args(), problem.scale, Pieces(*parts),
        ChordLimits(problem.tolerance, problem.balance_tolerance, CHORD_ITERATIONS,
                    CHORD_REFRESHES),
        _NO_VALUES if known is None else known.values,
        _NO_STATES if known is None else known.states)
    z, x, fixed, states = done.z, done.x, done.fixed, done.states
    info = (x, None if problem.moment_map is not None else fixed, states, done.motor, done.gap,
            done.taut)
    model = ModelAt(z.copy(), done.model_values, np.array(states), problem.friction.copy(),
                    np.concatenate([problem.tip_force, problem.tip_moment]), robot)
    return z, done.ok, done.iterations, info, done.pieces, model


class ModelAt(NamedTuple):
    """The model at a solution's z, which the next warm solve starts from without an IVP."""

    z: np.ndarray  #: (3 + n,) the unknowns it holds for
    values: np.ndarray  #: (3 + 3 n,) :data:`length_tracking.MODEL_VALUES`
    states: np.ndarray  #: (N, 21) node states (writable: a numba argument)
    friction: np.ndarray  #: (n,) mu times the sign of motion it was integrated with
    load: np.ndarray  #: (6,) tip force and moment
    robot: object = None  #: the robot it was integrated for (another robot's is not reused)

    def holds_for(self, problem):
        """Whether a problem has this model's robot, load and friction directions."""
        # bytes compared: exact equality, a tenth of np.array_equal's cost per cycle
        return (problem.robot is self.robot
                and self.friction.tobytes() == problem.friction.tobytes()
                and self.load[:3].tobytes() == problem.tip_force.tobytes()
                and self.load[3:].tobytes() == problem.tip_moment.tobytes())


def _newton(problem, z0, max_iterations=None, backtracks=16):
    """Semismooth Newton with backtracking; (z, converged, iterations, info, parts)."""
    robot = problem.robot
    max_iterations = max_iterations or robot.solver.max_iterations
    z = np.array(z0, dtype=float)
    res, jac, info, parts = problem.evaluate(z)
    for iteration in range(max_iterations):
        if _done(problem, res):
            return z, True, iteration, info, parts
        error = float(res @ res)
        if not np.isfinite(error):
            break
        step = -np.linalg.lstsq(jac, res, rcond=1e-12)[0] * problem.scale
        alpha = 1.0
        for attempt in range(backtracks):
            trial = z + alpha * step
            # the full step comes with its Jacobian (the usual accepted one), shorter ones
            # without (one IVP each): it is made where one is accepted
            trial_res, trial_jac, trial_info, trial_parts = problem.evaluate(
                trial, None if attempt == 0 else parts)
            trial_error = float(trial_res @ trial_res)
            if trial_error <= (1.0 - 1e-4 * alpha) * error or _done(problem, trial_res):
                break
            alpha *= 0.5
        else:
            return z, False, iteration + 1, info, parts
        if trial_jac is None:
            trial_res, trial_jac, trial_info, trial_parts = problem.evaluate(trial)
        z, res, jac, info, parts = trial, trial_res, trial_jac, trial_info, trial_parts
    return z, _done(problem, res), max_iterations, info, parts


def _continuation(robot, problem, z0):
    """Move the free lengths from the passive rod's paths to the asked ones in increments."""
    target = problem.free
    passive = np.array(z0, dtype=float)
    passive[3:] = 0.0
    _, _, info, _ = problem.evaluate(passive)
    start_free = target - info[4] + 1e-6 * robot.length  # paths of the passive rod, just slack
    z, ok, total = passive, False, 0
    for increments in (4, 16, 64):
        z = passive
        for k in range(1, increments + 1):
            fraction = k / increments
            problem.free = (1.0 - fraction) * start_free + fraction * target
            z, ok, iterations, info, _ = _newton(problem, z)
            total += iterations
            if not ok:
                break
        if ok:
            break
    problem.free = target
    _, _, info, parts = problem.evaluate(z)
    return z, ok, total, info, parts


def _done(problem, res):
    return (np.max(np.abs(res[:3]), initial=0.0) <= problem.balance_tolerance
            and np.max(np.abs(res[3:]), initial=0.0) * problem.radius
            <= problem.tolerance)


def _cable_residual(info):
    gap, taut = info[4], info[5]
    return float(np.max(np.abs(np.where(taut, gap, 0.0)), initial=0.0))


def _solution(robot, problem, z, info, converged, iterations, message, parts=None, model=None):
    x, fixed, states, motor, gap, taut = info
    slack = z[3:] <= SLACK_TENSION * problem.t_ref
    tensions = np.where(slack, 0.0, z[3:])  # a slack cable carries exactly nothing
    shape = robot.make_shape(x, problem.tip_force, states, fixed)
    notes = [message] if message else []
    over = np.flatnonzero(motor > robot.tendons.tension_limits[:, 1])
    if over.size:
        notes.append('tension above tension_limits for cables %s' % ', '.join(
            robot.cable_names[i] for i in over))
    return LengthSolution(shape=shape, tensions=np.where(slack, 0.0, motor),
                          end_tensions=tensions, slack=slack,
                          converged=bool(converged), message='; '.join(notes),
                          free_lengths=problem.free.copy(), motion=problem.motion.copy(),
                          motion_reference=problem.motion_reference,
                          iterations=iterations, residual=_cable_residual(info),
                          jacobian_parts=parts, slack_lengths=np.where(slack, gap, 0.0),
                          model_at=model)


def length_problem(robot, free_lengths, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0)):
    """Return the equations :func:`solve_lengths` solves, for an outside (SciPy) solver.

    :returns: an object with ``evaluate(z)`` -> (F (3 + n, scaled), ...) and ``scale`` (z's
        scaling: ``evaluate(z * scale)``); no friction history (every cable at rest)
    """
    n = len(robot.cable_names)
    return _Problem(robot, np.asarray(free_lengths, dtype=float), np.zeros(n),
                    np.asarray(tip_force, dtype=float), np.asarray(tip_moment, dtype=float))
