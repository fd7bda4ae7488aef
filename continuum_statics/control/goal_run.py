"""The tip-goal run: from a goal to cable-length commands, closed loop on the measured tip.

A state machine (:class:`Phase`) the tip_controller node ticks at its control rate:

1. ``RECOVER``: when the measured lengths are not where the last command put them (a restarted
   driver, a hand-made command, lengths statics could not fit), move straight onto the lengths
   of the measurement's nearest shape, back onto the model;
2. ``RAMP``: step from that equilibrium to the goal's through the model's own unknowns
   (``Robot.equilibrium_between``: section moments interpolated, base state solved), so every
   command is the cable-length set of an equilibrium, with no cable faster than
   ``max_cable_speed`` (straight in cable space only where no equilibrium is found);
3. ``SETTLE``: wait until every cable is measured at its command, or its gap to it has
   stopped closing over ``settle_time`` (further than :data:`OFF_COMMAND` from it: up to
   :data:`ANSWER_TIME`);
4. ``JUDGE``: average the tip poses that *arrived* since then (enough that the noise of the mean
   is inside the tolerance, at most ``tip_average_time``): reached, or correct the goal by the
   remaining error (``target += goal - mean_tip``) and ramp again, up to ``max_corrections``
   and never further than ``max_correction`` from the goal in all (a tip source that disagrees
   with the model by more is wrong, not the model: the goal fails and says so).

Every command of a model state is its motor-side lengths with real tendons
(:func:`tendon_commands.command_for`: the stretch of the tensions the shape needs, antagonists
at ``min_tension``); a goal that needs more tension than ``tension_limits`` allow is rejected.

Not thread-safe: the node calls it under its own lock. No ROS: tested without DDS.
"""
from dataclasses import dataclass, field
import enum
import math
import threading

import numpy as np

from continuum_statics.core.statics import clearance as clear
from continuum_statics.core.statics.tendon_commands import command_for

#: Measured lengths further than this from the last command (m) are not where the controller put
#: them: a goal then starts from the estimate of the measurement and moves onto it first.
OFF_COMMAND = 2e-3
#: Tip samples needed before the mean is judged (three identical ones: no noise).
MIN_TIP_SAMPLES = 3
#: Cables still closing on their command by more than a tenth of the gap per ``settle_time``
#: are still moving: the tip is not judged yet.
STILL_CLOSING = 0.9
#: s from the settle's start that cables further than :data:`OFF_COMMAND` from their command
#: are waited for, though no longer closing on it (a driver behind its commands, or stalled),
#: before the tip is judged anyway (a failure then names the driver).
ANSWER_TIME = 1.0


class Outcome(str, enum.Enum):
    """How a goal ended (compares equal to its value: ``Outcome.REACHED == 'reached'``)."""

    REACHED = 'reached'
    FAILED = 'failed'
    #: refused before it started (bad numbers, unreachable, no state)
    REJECTED = 'rejected'
    #: a newer goal or teleoperation took over
    PREEMPTED = 'preempted'


class Phase(enum.Enum):
    """Where a run is; ``IDLE`` without a goal."""

    IDLE = 'idle'
    RECOVER = 'recover'
    RAMP = 'ramp'
    SETTLE = 'settle'
    JUDGE = 'judge'


@dataclass(frozen=True)
class RunSettings:
    """The node parameters the run reads (units as the parameters: m, m/s, s)."""

    max_cable_speed: float = 0.02
    settle_time: float = 0.2
    settled_cable_error: float = 1e-6
    max_corrections: int = 10
    tip_average_time: float = 1.0
    max_state_age: float = 0.5
    min_tension: float = 0.0
    max_correction: float = math.inf  # m: the corrections of a goal add up to at most this
    clearance: float = None  # m the body keeps from obstacles; None or < 0: the robot file's


@dataclass(eq=False)
class Goal:
    """One tip goal in progress; ``done`` is set when it ends, ``reason`` says how."""

    position: np.ndarray
    tolerance: float
    source: str
    started: float
    deadline: float
    done: threading.Event = field(default_factory=threading.Event)
    reached: bool = False
    reason: str = ''
    tip_stamp: int = None  # ns
    error: float = math.nan
    direction: np.ndarray = None  # unit tip z axis goal (base frame), or None
    outcome: Outcome = None  # set when it ends (:meth:`GoalRun.finish`)


@dataclass(frozen=True, eq=False)
class Start:
    """Where a goal or teleoperation starts: the recovery rule's answer."""

    state: object  # equilibrium of the start (an estimate or the last commanded state)
    recover: np.ndarray  # motor-side lengths (m) of ``state`` to move onto first, or None
    commanded: np.ndarray  # the command in force (m): the last one, or the measured lengths


@dataclass(frozen=True, eq=False)
class Plan:
    """A solved goal, ready to run: where it starts and what it commands first."""

    start: object  # equilibrium of the start (estimate or the last commanded state)
    solution: object  # the goal's tip-goal solution
    load: np.ndarray  # tip wrench (6,) it was solved under
    commanded: np.ndarray  # first command (m): the measured lengths when recovering
    recover: np.ndarray  # lengths to recover onto first (m), or None
    target: np.ndarray  # the goal's commanded lengths (m)


def towards(commanded, target, step):
    """Move towards ``target`` along a straight line; the largest change moves ``step``."""
    delta = target - commanded
    largest = float(np.max(np.abs(delta)))
    if largest <= step:
        return target.copy()
    return commanded + delta * (step / largest)


def stale_state(now, measurement, tip, max_age, need_tip=True):
    """Why the measured state is too old to control with, or '' when it is fresh.

    Moving the cables needs only fresh ``cable_states``; judging the tip needs ``tip_pose``.
    """
    if measurement is not None and measurement.age(now) > max_age:
        return ('no cable_states for %.2f s (max_state_age %.3g s): is cable_driver running?'
                % (measurement.age(now), max_age))
    if need_tip and tip is not None and tip.age(now) > max_age:
        return ('no tip_pose for %.2f s (max_state_age %.3g s): statics is not running or drops '
                'every cable_states (its /diagnostics status says why)' % (tip.age(now), max_age))
    return ''


def direction_error(solution, direction):
    """Angle (rad) between a solution's tip z axis and a goal direction."""
    return float(np.arccos(np.clip(solution.shape.tip_rotation[:, 2] @ direction, -1.0, 1.0)))


class GoalRun:
    """The goal in progress of one controller and the commands that move the robot to it."""

    def __init__(self, robot, settings=RunSettings()):
        self.robot = robot
        self.settings = settings
        self.limits = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)
        self.goal = None
        self.phase = Phase.IDLE
        self.commanded = None  # last command (m), inside the limits
        self.command_state = None  # the equilibrium whose lengths were commanded last
        self.warm = None  # the last estimate or solution: warm start of the next solve
        self.corrections = 0
        self.moved_onto_model = 0
        self.judged_error = None  # mean tip error of the judgement in progress (m)
        self.notes = []  # degraded behaviour to report (the node drains it)
        # which tip is judged: 'tip_pose_measured' (a tracker) or 'tip_pose' (the model's own)
        self.tip_source = 'tip_pose_measured'
        self._target = None
        self._corrected_goal = None
        self._path = None  # (start, goal solution, tip load) of the ramp in progress
        self._legs = []  # solutions still to ramp to after the current one (waypoints)
        self._obstacles = None
        self._recheck = False  # new obstacles: the running goal's way is checked again
        self._fraction = 0.0
        self._fraction_step = 0.05
        self._straight = False  # no equilibrium path found: straight in cable space
        self._recover_target = None
        self._settle_start = None
        # (largest cable gap to its command m, arrival s) at the last look
        self._settle_gap = None
        self._judge_start = None

    @property
    def fraction(self) -> float:
        """How far the ramp in progress is (0..1)."""
        return self._fraction

    @property
    def obstacles(self):
        """Obstacles the body keeps clear of (base frame; None: the robot file's)."""
        return self._obstacles

    @obstacles.setter
    def obstacles(self, obstacles):
        # a goal on its way checks the rest of it against them at the next tick
        self._obstacles, self._recheck = obstacles, self.goal is not None

    @property
    def clearance(self):
        """Clearance (m) of the goals' solves: the setting, None for the robot file's."""
        value = self.settings.clearance
        return None if value is None or value < 0.0 else float(value)

    def model_tolerance(self, tolerance) -> float:
        """Solve the model well inside the goal's tolerance, so the tip lands near its centre."""
        return min(0.01 * tolerance, self.robot.solver.goal_tolerance)

    # -- a new goal --------------------------------------------------------------------------
    def snapshot(self) -> tuple:
        """Return what :meth:`plan` starts from: (last commanded state, command, warm start)."""
        return self.command_state, self.commanded, self.warm

    def start_point(self, measured, load, snapshot, tip_fresh=True) -> Start:
        """Apply the recovery rule: where a goal or teleoperation starts from lengths (m).

        When the cables are within :data:`OFF_COMMAND` of the last command (and statics
        publishes a tip for them), the last commanded equilibrium; otherwise the estimate of the
        measurement, with its motor-side lengths (:meth:`command`) to move onto first.
        """
        low, high = self.limits[:, 0], self.limits[:, 1]
        command_state, commanded, warm = snapshot
        if tip_fresh and command_state is not None and commanded is not None and float(
                np.max(np.abs(measured - commanded))) <= OFF_COMMAND:
            # the cables are where the last command put them
            return Start(command_state, None, commanded)
        # a goal starts from the measured shape itself, solved to the end (not a node's
        # bounded per-cycle step)
        start = self.robot.estimate_shape(measured, tip_force=load[:3], tip_moment=load[3:],
                                          warm_start=warm, exact=True)
        # onto the commands of that shape: slack cables taken up, antagonists at min_tension
        try:
            recover = self.command(start)
        except ValueError:  # the shape needs more than the tension limits: stay
            recover = np.clip(measured, low, high)
        # a ramp starts where the cables are, but never commands outside the limits
        return Start(start, recover, np.clip(measured, low, high))

    def plan(self, position, tolerance, direction, measured, load, tip_fresh,
             snapshot) -> Plan:
        """Solve a goal from the measured lengths (m); ValueError says why it is rejected.

        The expensive part (estimate and tip-goal solve), done without the node's lock, from
        a :meth:`snapshot` taken under it.
        :param tip_fresh: False when statics publishes no tip pose for these lengths: the run
            then starts from their nearest shape and moves the cables onto it
        """
        robot = self.robot
        begin = self.start_point(measured, load, snapshot, tip_fresh)
        start, recover, commanded = begin.state, begin.recover, begin.commanded
        solution = None
        obstacles = self.obstacles  # one read: the node swaps in new sets under its lock
        # warm from the start, then cold: a warm start far from the goal can end in a local
        # minimum of the tip error and call a reachable goal unreachable (seen 1.5-3 mm away)
        for warm_start in (start, None):
            trial = robot.solve_tip_goal(position, tip_force=load[:3], tip_moment=load[3:],
                                         tolerance=self.model_tolerance(tolerance),
                                         goal_direction=direction, warm_start=warm_start,
                                         clearance=self.clearance, obstacles=obstacles)
            if solution is None or trial.error < solution.error:
                solution = trial
            if solution.error <= tolerance:
                break
        if direction is not None:
            # judged against the goal's tolerance (the model solved to 1 % of it, which a
            # direction goal may not reach): position within it, direction within it over L
            angle = direction_error(solution, direction)
            if not (solution.error <= tolerance and angle <= tolerance / robot.length):
                raise ValueError('unreachable goal (%.4f, %.4f, %.4f) m with direction %s: tip '
                                 '%.2f mm and %.3g rad from it (tolerance %.2f mm, %.3g rad); '
                                 '%s' % (*position, np.round(direction, 3).tolist(),
                                         solution.error * 1e3, angle, tolerance * 1e3,
                                         tolerance / robot.length, solution.message))
        if math.isfinite(solution.clearance) and not solution.converged and (
                solution.error <= tolerance):
            raise ValueError('goal (%.4f, %.4f, %.4f) m refused: %s'
                             % (*position, solution.message))
        if not solution.error <= tolerance:
            limited = ', '.join(solution.limited_cables)
            raise ValueError('unreachable goal (%.4f, %.4f, %.4f) m: the nearest reachable tip '
                             'is %.1f mm away (tolerance %.2f mm)%s' % (
                                 *position, solution.error * 1e3, tolerance * 1e3,
                                 '; cables at a length limit: ' + limited if limited else ''))
        if not np.all(np.isfinite(solution.cable_lengths)):
            raise ValueError('the solver returned non-finite cable lengths')
        try:
            target = self.command(solution)
            for leg in solution.waypoints:  # the way round an obstacle must be commandable too
                self.command(leg)
        except ValueError as error:
            raise ValueError('goal (%.4f, %.4f, %.4f) m %s' % (*position, error)) from None
        return Plan(start, solution, np.array(load, dtype=float), commanded, recover, target)

    def command(self, result) -> np.ndarray:
        """Motor-side lengths (m) holding a model result's shape, inside the length limits.

        :raises ValueError: the shape needs more tension than ``tension_limits`` allow
        """
        lengths = command_for(self.robot, result.shape, self.settings.min_tension).lengths
        return np.clip(lengths, self.limits[:, 0], self.limits[:, 1])

    def begin(self, goal, plan, now) -> 'Goal | None':
        """Make ``goal`` the running one; return the goal it pre-empts (finished) or None."""
        previous = self.goal
        if previous is not None:
            self.finish(previous, False, 'pre-empted by a new goal', Outcome.PREEMPTED)
        self.goal = goal
        if plan.recover is not None or self.commanded is None:
            self.commanded = plan.commanded
        # else a running goal may have moved the command on meanwhile: the ramp closes that gap
        # at max_cable_speed (see _advance) instead of jumping back
        self.command_state = plan.start if plan.recover is None else None
        self._recover_target = plan.recover
        self._start_path(plan.start, plan.solution, plan.load, plan.target)
        self._corrected_goal = goal.position.copy()
        self.warm = plan.solution
        self.corrections = 0
        self.phase = Phase.RAMP if plan.recover is None else Phase.RECOVER
        self.moved_onto_model += plan.recover is not None
        return previous

    def adopt(self, state, commanded) -> None:
        """Continue from an equilibrium commanded elsewhere (teleoperation) with no goal."""
        self.command_state, self.commanded, self.warm = state, np.array(commanded), state

    def finish(self, goal, reached, reason, outcome=None) -> bool:
        """End ``goal`` (idempotent); return True if this call ended it.

        :param outcome: an :class:`Outcome`; by default ``REACHED`` or ``FAILED`` after
            ``reached``
        """
        if goal.done.is_set():
            return False
        goal.reached, goal.reason = reached, reason
        goal.outcome = Outcome(outcome) if outcome is not None else (
            Outcome.REACHED if reached else Outcome.FAILED)
        self.judged_error = None
        if self.goal is goal:
            self.goal, self.phase = None, Phase.IDLE
        goal.done.set()
        return True

    def _start_path(self, start, solution, load, target):
        legs = list(getattr(solution, 'waypoints', ()))
        if legs:  # around an obstacle: ramp through each waypoint, the goal last
            self._legs = legs[1:] + [(solution, target)]
            solution, target = legs[0], self.command(legs[0])
        else:
            self._legs = []
        self._path = (start, solution, load)
        self._target = target
        self._fraction = 0.0
        self._fraction_step = min(self._fraction_step * 4.0, 0.25)
        self._straight = False

    # -- the control loop --------------------------------------------------------------------
    def stale(self, now, measurement, tip) -> str:
        """Why the state is too old for the current phase, or '' (see :func:`stale_state`)."""
        return stale_state(now, measurement, tip, self.settings.max_state_age,
                           need_tip=self.phase in (Phase.SETTLE, Phase.JUDGE))

    def tick(self, now, dt, measurement, tip, tips, load) -> 'np.ndarray | None':
        """Advance one control period of ``dt`` s; return the command (m) to publish, or None.

        :param measurement: the newest :class:`~continuum_statics.control.records.Measurement`
        :param tip: the newest :class:`~continuum_statics.control.records.TipSample` (or None)
        :param tips: recent tip samples, oldest first (for the judgement)
        :param load: the current tip wrench (6,), for a correction's solve
        A goal that ends is finished here (``goal.done``); the caller reports it.
        """
        goal = self.goal
        if goal is None:
            return None
        error = math.inf if tip is None else float(np.linalg.norm(goal.position - tip.position))
        goal.error = error if self.judged_error is None else self.judged_error
        if now > goal.deadline:
            self.finish(goal, False, 'not reached within %.3g s (tip error %.2f mm)'
                        % (goal.deadline - goal.started, goal.error * 1e3))
            return None
        stale = self.stale(now, measurement, tip)
        if stale:
            self.finish(goal, False, stale)
            return None
        blocked = self._recheck and self._way_blocked()
        self._recheck = False
        if blocked:
            self.finish(goal, False, blocked)
            return None
        budget = self.settings.max_cable_speed * dt
        if self.phase is Phase.RECOVER:
            # Off the model (e.g. a restarted driver): straight onto the estimate's lengths,
            # the nearest shape, then along the model.
            self.commanded = towards(self.commanded, self._recover_target, budget)
            if np.array_equal(self.commanded, self._recover_target):
                self.phase = Phase.RAMP
        elif self.phase is Phase.RAMP:
            try:
                self._advance(budget)
                if self._fraction >= 1.0 and self._legs:  # on to the next waypoint
                    leg = self._legs.pop(0)
                    solution, target = leg if isinstance(leg, tuple) else (leg,
                                                                           self.command(leg))
                    self._path = (self._path[1], solution, self._path[2])
                    self._target, self._fraction = target, 0.0
            except ValueError as error:
                self.finish(goal, False, 'ramp failed: %s' % error)
                return None
            if self._fraction >= 1.0:
                self.phase, self._settle_start = Phase.SETTLE, now
        elif self.phase is Phase.SETTLE:
            # Settled: every cable measured at its command, or (noise keeps it from there) its
            # gap to the command stopped closing over a settle_time (a driver behind or stalled:
            # up to ANSWER_TIME; :meth:`_settled`). The tip is judged only on
            # poses that arrived from then on (arrival time, never a stamp the sender controls:
            # unstamped input and clock jumps happen), so a tip pose of the moving cables never
            # triggers a wrong correction. Before, settle_time alone ended the wait: motors
            # still following (a simulated rod slower than real time: 51 mm of model tip motion
            # inside the judged samples) were judged, corrected and the goal failed.
            if measurement is not None and measurement.received > self._settle_start:
                if self._settled(measurement):
                    self.phase, self._judge_start = Phase.JUDGE, now
        else:
            self._judge(goal, now, tips, load, measurement)
        if goal.done.is_set():
            # Nothing after the end: the answer may already be with a client whose next
            # cable command this one would overwrite (the cables are at it anyway).
            return None
        return self.commanded

    def _advance(self, budget):
        """Step along the equilibrium path so that no cable moves more than ``budget`` m."""
        start, solution, load = self._path
        if self._straight:
            self._straight_towards(solution, budget)
            return
        step = self._fraction_step
        for _ in range(12):
            fraction = min(1.0, self._fraction + step)
            if fraction >= 1.0:
                state, lengths = solution, self._target
            else:
                state = self.robot.equilibrium_between(
                    start, solution, fraction, tip_force=load[:3], tip_moment=load[3:],
                    warm_start=self.command_state)
                try:
                    lengths = self.command(state)
                except ValueError:  # over a tension limit part of the way: not usable
                    lengths = np.full(len(self.limits), math.nan)
            finite = np.all(np.isfinite(lengths))
            change = float(np.max(np.abs(lengths - self.commanded))) if finite else math.inf
            usable = (state is solution or state.converged) and finite
            if usable and change <= budget * 1.05:
                self._fraction, self.commanded, self.command_state = fraction, lengths, state
                # lengths are smooth in the fraction: aim the next step at the budget
                self._fraction_step = min(0.5, max(1e-6, step * (
                    2.0 if change <= 0.0 else min(2.0, budget / change))))
                return
            step *= 0.5 if not usable else max(0.1, min(0.9, 0.95 * budget / change))
        if not usable:
            # No equilibrium part of the way (e.g. a heavy tip load near what the model can
            # hold): go straight to the goal's lengths, themselves a shape, at max_cable_speed.
            self._straight = True
            self.notes.append('the model found no equilibrium %.0f %% of the way to the goal '
                              'under tip load %s N: straight to the goal lengths'
                              % (100.0 * self._fraction, np.round(load[:3], 3).tolist()))
            self._straight_towards(solution, budget)
            return
        # Even the smallest step moves a cable faster than allowed (the start was not exactly
        # the model's equilibrium): close that gap at max_cable_speed, then go on.
        self.commanded = towards(self.commanded, lengths, budget)
        self._fraction_step = max(step, 1e-3)

    def _way_blocked(self):
        """Return why the rest of the way now passes too close to an obstacle, or ''."""
        obstacles = self.robot.obstacles_or_file(self._obstacles)
        if not obstacles or self._path is None or self.phase is Phase.RECOVER:
            return ''
        clearance = self.robot.clearance if self.clearance is None else self.clearance
        start, solution, load = self._path
        begin = getattr(self.command_state or start, 'shape', self.command_state or start)
        # the way may not come closer than the body already is
        floor = min(clearance, clear.closest(self.robot, begin, obstacles).gap) - clear.SLACK
        for leg in [solution] + [leg[0] if isinstance(leg, tuple) else leg
                                 for leg in self._legs]:
            worst = clear.along_path(self.robot, begin, leg.shape, obstacles, load[:3],
                                     load[3:], floor, clearance)
            if worst.gap < floor:
                return 'stopped: obstacles changed and %s on the rest of the way' % (
                    worst.says(clearance))
            begin = leg.shape
        return ''

    def _straight_towards(self, solution, budget):
        self.commanded = towards(self.commanded, self._target, budget)
        if np.array_equal(self.commanded, self._target):
            self._fraction, self.command_state = 1.0, solution

    def _settled(self, measurement):
        """Return True once the cables are at their command or have stopped closing on it.

        Looked at by the readings' arrival (a driver that sends nothing does not count as
        still). A largest gap over :data:`OFF_COMMAND` that stopped closing (a driver behind
        its commands, or stalled) is waited for up to :data:`ANSWER_TIME`: on a loaded 2-core
        machine the simulated driver acted 0.1-0.3 s late or stalled 2.6 mm short, and the
        old lengths' tip was judged.
        """
        gap = float(np.max(np.abs(measurement.lengths - self.commanded)))
        if gap <= self.settings.settled_cable_error:
            return True
        at = measurement.received
        last = self._settle_gap
        if last is None or last[1] < self._settle_start:  # the first look of this settle
            self._settle_gap = (gap, at)
            return False
        if at - last[1] < self.settings.settle_time:
            return False
        self._settle_gap = (gap, at)
        return gap > STILL_CLOSING * last[0] and (
            gap <= OFF_COMMAND or at - self._settle_start >= ANSWER_TIME)

    def _judge(self, goal, now, tips, load, measurement):
        """Judge the mean tip since the cables settled: reached, correct, or wait for more."""
        samples = [tip.position for tip in tips if tip.received >= self._judge_start]
        if len(samples) < MIN_TIP_SAMPLES:
            return
        points = np.asarray(samples)
        mean = points.mean(axis=0)
        error = float(np.linalg.norm(mean - goal.position))
        # standard error of the mean tip (noise): 0 for identical samples
        spread = float(np.linalg.norm(points.std(axis=0))) / math.sqrt(len(points))
        self.judged_error = error
        goal.error = error
        timed_out = now - self._judge_start >= self.settings.tip_average_time
        if error + 2.0 * spread <= goal.tolerance or (timed_out and error <= goal.tolerance):
            goal.tip_stamp = tips[-1].stamp_ns
            self.finish(goal, True, 'tip %.2f mm from the goal (mean of %d tip poses) after '
                        '%.2f s, %d correction(s)' % (error * 1e3, len(points),
                                                      now - goal.started, self.corrections))
        elif error - 2.0 * spread > goal.tolerance or timed_out:
            self.judged_error = None
            self._correct(goal, mean, load, measurement)

    def _correct(self, goal, measured_tip, load, measurement=None):
        off = (float(np.max(np.abs(measurement.lengths - self.commanded)))
               if measurement is not None else 0.0)
        # cables that did not reach their command: the driver, not the model, is the cause
        not_following = ('; the cables are %.1f mm from their command: is cable_driver active '
                         'and following cable_commands? (its /diagnostics status says)'
                         % (off * 1e3)) if off > OFF_COMMAND else ''
        if self.corrections >= self.settings.max_corrections:
            self.finish(goal, False, 'still %.2f mm from the goal after %d corrections%s'
                        % (goal.error * 1e3, self.corrections, not_following))
            return
        corrected = self._corrected_goal + (goal.position - measured_tip)
        total = float(np.linalg.norm(corrected - goal.position))
        if total > self.settings.max_correction:
            self.finish(goal, False, 'the corrections would move the target %.1f mm from the '
                        'goal, more than tracker_max_disagreement %.1f mm: %s%s'
                        % (total * 1e3, self.settings.max_correction * 1e3,
                           _correction_cause(self.tip_source), not_following))
            return
        self._corrected_goal = corrected
        start = self.command_state
        try:
            solution = self.robot.solve_tip_goal(
                self._corrected_goal, tip_force=load[:3], tip_moment=load[3:],
                tolerance=self.model_tolerance(goal.tolerance), goal_direction=goal.direction,
                warm_start=start, clearance=self.clearance, obstacles=self.obstacles)
        except ValueError as error:
            self.finish(goal, False, 'correction failed: %s' % error)
            return
        if not np.all(np.isfinite(solution.cable_lengths)):
            self.finish(goal, False, 'correction gave non-finite cable lengths')
            return
        try:
            target = self.command(solution)
        except ValueError as error:
            self.finish(goal, False, 'correction %s' % error)
            return
        self.corrections += 1
        self.warm = solution
        self._start_path(start, solution, load, target)
        self.phase = Phase.RAMP


def _correction_cause(tip_source):
    """Why the corrections grew, by the tip that was judged (the real cause, never a guess)."""
    if tip_source == 'tip_pose_measured':
        return ('the measured tip and the model disagree that much (check the tracker and its '
                'registration, or calibrate the robot)')
    return ("no tracker is used: the model's own tip (tip_pose) moved that far from the shape "
            'it commanded, so its inputs changed under the goal (the tip load on tip_wrench or '
            'the tip-load estimate, or lengths the cables did not reach)')
