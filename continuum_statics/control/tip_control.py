"""Everything the tip_controller decides, without ROS: goal intake, teleoperation, the loop.

:class:`TipControl` is the declared API every goal interface talks to (the ``tip_goal`` service,
the ``tip_goal_pose`` / ``tip_goal_point`` topics, the ``move_tip`` action server and
``tip_twist``); the node only parses messages into numbers, calls it and publishes what it
returns. It owns

- the state records (newest cable lengths, tip poses, tracker poses, tip load, the driver's
  refusal, contact) and the rule of when they are missing or too old,
- goal intake: the checks, the wait for fresh state (``state_wait``), the same-goal rule (a goal
  equal to the running one attaches to it: streams repeat their goal), the hand-over by arrival
  (:class:`~continuum_statics.control.handover.Handover`) and the solve
  (:meth:`GoalRun.plan <continuum_statics.control.goal_run.GoalRun.plan>`),
- teleoperation take-over, which starts through the goal run's own recovery rule
  (:meth:`GoalRun.start_point <continuum_statics.control.goal_run.GoalRun.start_point>`:
  motor-side lengths, as a goal),
- the control tick and the counting of outcomes (:class:`~.goal_run.Outcome`).

Waiting is the caller's: ``wait_until(condition, deadline)`` returns an awaitable (the node's
:mod:`~continuum_statics.nodes.waits`, an asyncio loop in the tests). ``timer`` is anything with
``reset()`` and ``cancel()``: the control timer, run only while a goal or teleoperation does.
Thread-safe: inputs, goals and the tick may come from different threads.
"""
from collections import deque
import dataclasses
import math
import threading
import time

import numpy as np

from continuum_statics.control.goal_run import (
    Goal,
    GoalRun,
    Outcome,
    RunSettings,
    stale_state,
)
from continuum_statics.control.handover import Handover
from continuum_statics.control.health import Problems
from continuum_statics.control.records import (
    Measurement,
    TipLoadInput,
    TipSample,
    tracked_tip,
)
from continuum_statics.control.teleop import TeleopRun, TeleopSettings, Twist, twist_hold
from continuum_statics.control.tip_source import TipSource, disagreement_bound

#: Smallest goal tolerance, m: below a micrometre the model's own accuracy decides.
MIN_TOLERANCE = 1e-6
#: A goal starts from the mean of the cable lengths measured in this window, s (at rest it
#: averages the encoder noise; a moving cable lags by at most speed x window).
MEAN_WINDOW_S = 0.05
#: A tip_twist stamped further than this from now is refused, s (or twist_timeout if longer).
MAX_TWIST_STAMP_OFFSET = 1.0
#: The cable_driver's /diagnostics status counts this long, s (it publishes at >= 1 Hz).
DRIVER_STATUS_AGE = 5.0
#: A goal's waiters end it this long after its own deadline, s (the last judgement's margin).
END_MARGIN = 5.0


class _NoTimer:
    def reset(self):
        pass

    def cancel(self):
        pass


class TipControl:
    """Goals, teleoperation and the control loop of one tip_controller.

    :param robot: the :class:`~continuum_statics.core.robot.Robot`
    :param params: mapping of the node's parameters (``params['goal_timeout']``, ...)
    :param log: logger with ``info``, ``warning`` and ``error``
    :param wait_until: ``wait_until(condition, deadline)`` -> awaitable, see the module
    :param clock: monotonic seconds
    """

    def __init__(self, robot, params, log, wait_until=None, clock=time.monotonic):
        self.robot = robot
        self.params = params
        self.log = log
        self.cable_names = tuple(robot.cable_names)
        self.clock = clock
        self._wait_until = wait_until
        self.timer = _NoTimer()
        #: called with each goal that starts (e.g. to publish ``tip_goal_active``)
        self.on_goal_started = None
        self.lock = threading.Lock()  # guards the run: the control loop and goal starts
        self.closing = False
        self.handover = Handover()  # goals and teleoperation: the later arrival wins
        self.tracker = TipSource(self._tracker_bound())
        self.run = GoalRun(robot, self._run_settings())
        self.teleop = TeleopRun(robot, self._teleop_settings())
        self.problems = Problems(log.warning)
        self.counts = {outcome: 0 for outcome in Outcome}
        self.last_outcome = 'no goal yet'
        self.tip_source = 'tip_pose'
        self._twist = None  # the newest Twist
        self._last_tick = None
        # The intake thread appends to these deques while the control loop judges a goal: the
        # loop takes a snapshot under this lock (never iterates a deque being appended to).
        self._samples_lock = threading.Lock()
        self._tips = deque(maxlen=4000)  # recent TipSamples, for the judgement of a goal
        self._recent_lengths = deque(maxlen=64)  # recent Measurements, for a low-noise mean
        self.measurement = None  # newest Measurement (one assignment: always consistent)
        self.tip = None  # newest TipSample
        self._tip_rotation = None  # the model tip's rotation (3, 3) of the newest tip_pose
        self._measured_tips = deque(maxlen=4000)  # recent tracker TipSamples (tip, not marker)
        self.measured_tip = None
        self.backbone = None  # (stamp ns, serialized Path) of the newest backbone
        estimate = params['tip_wrench_source'] == 'estimate'  # kept past its timeout
        self._load = TipLoadInput('tip_wrench_estimate' if estimate else 'tip_wrench', estimate,
                                  log.warning, log.info, clock)
        self._driver_status = None  # (refusal or '', monotonic s) of cable_driver's status
        self._contact_since = None  # monotonic s tip_contact turned true, None without contact

    # -- settings --------------------------------------------------------------------------
    def _run_settings(self):
        params = self.params
        return RunSettings(**{name: params[name] for name in RunSettings.__dataclass_fields__
                              if name != 'max_correction'},
                           max_correction=self._tracker_bound())

    def _tracker_bound(self, value=None):
        """tracker_max_disagreement in m (0: a tenth of the rod length)."""
        value = self.params['tracker_max_disagreement'] if value is None else value
        return disagreement_bound(self.robot.length, value)

    def _teleop_settings(self):
        params = self.params
        return TeleopSettings(max_tip_speed=params['max_tip_speed'],
                              max_tip_rate=params['max_tip_rate'],
                              twist_timeout=params['twist_timeout'],
                              max_cable_speed=params['max_cable_speed'])

    def on_parameter_change(self, name, value) -> None:
        """Apply a parameter change (called before the table stores the new value)."""
        with self.lock:
            if name in RunSettings.__dataclass_fields__:
                self.run.settings = dataclasses.replace(self.run.settings, **{name: value})
            if name == 'tracker_max_disagreement':
                self.tracker.bound = self._tracker_bound(value)
                self.run.settings = dataclasses.replace(self.run.settings,
                                                        max_correction=self.tracker.bound)
            if name in TeleopSettings.__dataclass_fields__:
                self.teleop.settings = dataclasses.replace(self.teleop.settings,
                                                           **{name: value})

    def set_timer(self, timer) -> object:
        """Use ``timer`` (``reset()``/``cancel()``) for the loop from now on; return the old one.

        Swapped under the lock goal starts reset it under, so no start resets a destroyed timer.
        """
        with self.lock:
            old, self.timer = self.timer, timer
        return old

    # -- state inputs (already parsed and checked by the node) ------------------------------
    def on_tip_pose(self, position, rotation, stamp_ns) -> None:
        """Take the model tip: position (3,) m and rotation (3, 3) in the base frame."""
        tip = TipSample(position, stamp_ns, self.clock())
        with self._samples_lock:
            self._tips.append(tip)
        self.tip, self._tip_rotation = tip, rotation

    def on_tip_pose_measured(self, marker_position, stamp_ns, age=0.0) -> None:
        """Take a tracker's marker position (3,) m, base frame (ignored before a tip_pose).

        ``age``: s since the measurement (its judged stamp): freshness counts from then.
        """
        if self._tip_rotation is None:
            return  # the marker's offset needs the model's tip frame: wait for tip_pose
        tip = tracked_tip(marker_position, self._tip_rotation, self.robot.tip_marker)
        sample = TipSample(tip, stamp_ns, self.clock() - age)
        with self._samples_lock:
            self._measured_tips.append(sample)
        self.measured_tip = sample

    def on_cable_states(self, lengths, stamp_ns) -> None:
        """Measured cable lengths (n,) m in robot order."""
        measurement = Measurement(lengths, stamp_ns, self.clock())
        with self._samples_lock:
            self._recent_lengths.append(measurement)
        self.measurement = measurement

    def on_backbone(self, stamp_ns, data) -> None:
        """Keep the newest backbone serialized (only the one that answers a goal is read)."""
        self.backbone = (stamp_ns, data)

    def on_tip_wrench(self, wrench) -> None:
        """Take a checked tip wrench (6,): force N, moment N m, base frame."""
        self._load.take(wrench)

    def on_driver_status(self, refusal) -> None:
        """cable_driver's status: why it refuses commands, or '' when it accepts them."""
        self._driver_status = (refusal, self.clock())

    def on_contact(self, contact) -> None:
        """tip_contact: True while the tip load estimator sees a contact."""
        if not contact:
            self._contact_since = None
        elif self._contact_since is None:
            self._contact_since = self.clock()

    def driver_refusal(self) -> str:
        """Why cable_driver refuses cable_commands now (its fresh status), or ''."""
        status = self._driver_status
        if status is None or self.clock() - status[1] > DRIVER_STATUS_AGE:
            return ''
        return status[0]

    def current_tip_load(self) -> np.ndarray:
        """Return the tip wrench (6,) in force: zero without one, or after its timeout.

        An estimated load (``tip_wrench_source: estimate``) is kept after it, as statics does.
        """
        return self._load.current(self.params['tip_wrench_timeout'])

    def missing_state(self) -> str:
        """Return which state has never arrived, or '' when both have."""
        missing = [what for what, state in (('cable_states from cable_driver', self.measurement),
                                            ('tip_pose from statics', self.tip))
                   if state is None]
        return ('no %s yet' % ' and no '.join(missing)) if missing else ''

    def stale_state(self, now, need_tip=True) -> str:
        """Why the state is too old to control with (``max_state_age``), or ''."""
        return stale_state(now, self.measurement, self.tip, self.params['max_state_age'],
                           need_tip)

    def _no_lengths(self, now):
        return ('no cable_states from cable_driver yet' if self.measurement is None
                else self.stale_state(now, need_tip=False))

    def _mean_lengths(self, newest):
        """Mean of the measurements of the last MEAN_WINDOW_S s: encoder noise averaged out."""
        with self._samples_lock:
            recent = tuple(self._recent_lengths)
        recent = [m.lengths for m in recent if newest.received - m.received <= MEAN_WINDOW_S]
        return np.mean(recent, axis=0) if recent else newest.lengths.copy()

    # -- what goal interfaces ask -----------------------------------------------------------
    @property
    def wants_direction(self) -> bool:
        """True when goals carry a tip direction (``goal_orientation: direction``)."""
        return self.params['goal_orientation'] == 'direction'

    def checked_tolerance(self, tolerance) -> float:
        """Return a goal tolerance (m) if usable; ValueError says why not."""
        if not (math.isfinite(tolerance) and MIN_TOLERANCE <= tolerance <= self.robot.length):
            raise ValueError('tolerance must be between %g m and the rod length %g m, got %r'
                             % (MIN_TOLERANCE, self.robot.length, tolerance))
        return tolerance

    def latest_tip(self) -> 'TipSample | None':
        """Return the newest TipSample (or None)."""
        return self.tip

    def phase(self) -> str:
        """Return what the controller does now: a goal run's phase or 'teleoperation'."""
        return 'teleoperation' if self.teleop.active else self.run.phase.value

    def wait_until(self, condition, deadline) -> object:
        """Awaitable of ``condition()`` once it holds, ``deadline`` passes or at shutdown."""
        return self._wait_until(lambda: self.closing or condition(), deadline)

    async def goal_end(self, goal, deadline=None) -> bool:
        """Wait for ``goal`` to end (True) or ``deadline`` (False), holding no thread.

        Past the goal's own deadline (plus a margin for the last judgement) or at shutdown the
        goal is ended here.
        """
        limit = goal.deadline + END_MARGIN
        await self.wait_until(goal.done.is_set, limit if deadline is None
                              else min(deadline, limit))
        if not goal.done.is_set() and (self.closing or self.clock() >= limit):
            self.finish_goal(goal, False, 'shutting down' if self.closing else 'timed out')
        return goal.done.is_set()

    async def backbone_after(self, tip_stamp, wait=0.5) -> 'bytes | None':
        """Return the newest serialized backbone, waiting briefly for the one of ``tip_stamp``."""
        def arrived():
            return self.backbone is not None and (tip_stamp is None
                                                  or self.backbone[0] >= tip_stamp)

        await self.wait_until(arrived, self.clock() + wait)
        return None if self.backbone is None else self.backbone[1]

    def reject(self, kind, reason) -> None:
        """Drop an input of ``kind``: counted, on diagnostics, logged (throttled)."""
        self.problems.reject(kind, reason)

    # -- goals -------------------------------------------------------------------------------
    def goal_arrived(self) -> int:
        """Take a goal's place in the hand-over as its request arrives; return its ticket.

        For a request whose :meth:`start_goal` runs later (an action's execute, scheduled
        after its acceptance is sent): twists that arrived in between overtake it. Only for a
        goal :meth:`check_goal` passed: a rejected one must not overtake anything.
        """
        return self.handover.take('a newer goal')

    def check_goal(self, position) -> None:
        """Raise ValueError when no robot state could make ``position`` (m) a goal."""
        robot = self.robot
        if not self.cable_names:
            raise ValueError('robot has no cables: %r is a passive rod, nothing to move'
                             % robot.name)
        # the infinity norm: no overflow for a goal at 1e308 m
        reach = float(np.max(np.abs(position - robot.base_position)))
        if reach > robot.length:
            raise ValueError('the tip goal (%.4g, %.4g, %.4g) m is unreachable: %.3g m from '
                             'the base along an axis, the rod is %.3g m long'
                             % (*position, reach, robot.length))

    async def start_goal(self, position, tolerance, source, direction=None,
                         ticket=None) -> Goal:
        """Solve the goal and make it the active one; ValueError says why it is rejected.

        Returns the running :class:`Goal` (the same goal again attaches to it); a goal that
        teleoperation or a newer goal overtook while it was being solved comes back finished
        (``Outcome.PREEMPTED``, 'pre-empted ... before it started'): the later arrival wins.
        ``ticket``: the request's :meth:`goal_arrived` (default: it arrives now).
        """
        params = self.params
        self.check_goal(position)
        if ticket is None:
            ticket = self.goal_arrived()
        # Right after start-up, or while a driver or statics restarts, the state may be missing
        # or old for a moment: wait up to state_wait for fresh state before answering.
        await self.wait_until(
            lambda: not (self.missing_state() or self.stale_state(self.clock())
                         or self.driver_refusal()),
            self.clock() + params['state_wait'])
        no_lengths = self._no_lengths(self.clock())
        if no_lengths:
            raise ValueError('%s (waited %.3g s)' % (no_lengths, params['state_wait']))
        refusal = self.driver_refusal()
        if refusal:
            raise ValueError('cable_driver refuses cable_commands: %s' % refusal)
        # Fresh lengths but no fresh tip pose: statics drops the lengths (they fit no shape,
        # e.g. after a hand-made command or a removed tip load). Start from the measured
        # lengths' nearest shape and move the cables onto it: statics then follows again.
        tip_lost = self.missing_state() or self.stale_state(self.clock())
        if tip_lost:
            self.log.warning('goal without a fresh tip pose (%s): moving the cables onto the '
                             'model from the measured lengths first' % tip_lost)
        with self.lock:
            running = self.run.goal
            if running is not None and running.tolerance == tolerance and np.array_equal(
                    running.position, position) and np.array_equal(running.direction, direction):
                return running  # the same goal again (a stream repeats it): it goes on
            if not self.handover.holds(ticket):
                return self._overtaken(position, tolerance, source, direction)
            self._end_teleop('pre-empted by a tip goal')
            snapshot = self.run.snapshot()
        plan = self.run.plan(position, tolerance, direction,
                             self._mean_lengths(self.measurement), self.current_tip_load(),
                             not tip_lost, snapshot)
        now = self.clock()
        goal = Goal(position=position, tolerance=tolerance, source=source, started=now,
                    deadline=now + params['goal_timeout'], direction=direction)
        with self.lock:
            # teleoperation or a newer goal came while this one was solved: they win
            if not self.handover.holds(ticket):
                return self._overtaken(position, tolerance, source, direction)
            previous = self.run.begin(goal, plan, now)
            if previous is not None:
                self._report(previous)
            self.tracker.reset()
            self._last_tick = now
            self.timer.reset()
        if self.on_goal_started is not None:
            self.on_goal_started(goal)
        self.log.info('tip goal (%.4f, %.4f, %.4f) m, tolerance %.2g m from %s%s' % (
            *position, tolerance, source, '' if plan.recover is None
            else ' (cables off the last command: onto the model first)'))
        return goal

    def _overtaken(self, position, tolerance, source, direction):
        """Return a goal that lost the hand-over before it started, finished (under the lock)."""
        now = self.clock()
        goal = Goal(position=position, tolerance=tolerance, source=source, started=now,
                    deadline=now, direction=direction)
        self.run.finish(goal, False, 'pre-empted by %s before it started'
                        % self.handover.holder, Outcome.PREEMPTED)
        self._report(goal)
        return goal

    def finish_goal(self, goal, reached, reason, outcome=None) -> None:
        """End ``goal`` (cancel, shutdown, a caller's timeout) and report it."""
        with self.lock:
            if self.run.finish(goal, reached, reason, outcome):
                self._report(goal)

    def goal_rejected(self, error) -> None:
        """Count and report a goal rejected before it started."""
        self.counts[Outcome.REJECTED] += 1
        self.last_outcome = 'rejected: %s' % error
        self.problems.add('tip_goal', error)
        self.log.warning('tip goal rejected: %s' % error)

    def _report(self, goal):
        """Count, log and put on diagnostics a goal that ended (under the lock)."""
        outcome = goal.outcome
        self.counts[outcome] += 1
        self.last_outcome = '%s (%.4f, %.4f, %.4f): %s' % (outcome.value, *goal.position,
                                                           goal.reason)
        if outcome is Outcome.REACHED:
            self.log.info('tip goal reached: %s' % goal.reason)
        elif outcome is Outcome.PREEMPTED:  # streams pre-empt each other all the time
            self.log.info('tip goal (%.4f, %.4f, %.4f) m %s' % (*goal.position, goal.reason))
        else:
            self.problems.add('tip_goal', goal.reason)
            self.log.warning('tip goal (%.4f, %.4f, %.4f) m not reached: %s'
                             % (*goal.position, goal.reason))

    # -- teleoperation -----------------------------------------------------------------------
    def twist(self, linear, angular, stamp_ns=0, clock_ns=0) -> None:
        """Follow a tip twist (m/s, rad/s, base frame), taking over from any goal.

        :param stamp_ns: the twist's stamp (0: unstamped, taken on arrival)
        :param clock_ns: the node's clock now (0: simulated time before the first /clock)
        :raises ValueError: a stamp far from now, non-finite numbers, no fresh cable lengths
        """
        linear, angular = np.asarray(linear, dtype=float), np.asarray(angular, dtype=float)
        if not (np.all(np.isfinite(linear)) and np.all(np.isfinite(angular))):
            raise ValueError('non-finite velocity')
        if angular.any() and not self.wants_direction:
            angular = np.zeros(3)  # the tip direction is not controlled
        timeout = self.params['twist_timeout']
        if stamp_ns != 0 and clock_ns != 0:
            offset = (clock_ns - stamp_ns) * 1e-9
            limit = max(MAX_TWIST_STAMP_OFFSET, timeout)
            if abs(offset) > limit:
                raise ValueError('stamped %.3g s %s now (more than %.3g s): a replayed command '
                                 'or a sender with another clock; unstamped twists (stamp 0) '
                                 'are taken on arrival' % (abs(offset), 'before' if offset > 0
                                                           else 'after', limit))
        now, previous = self.clock(), self._twist
        self._twist = Twist(linear, angular, now, twist_hold(
            None if previous is None else previous.received, now, timeout))
        if self.teleop.active:
            # the operator still drives: a goal that arrived before this twist and is still
            # waiting for state or being solved must not start once the twists stop (on a
            # loaded machine one waited out the stream and ran after the dead-man stop)
            self.handover.take('teleoperation (tip_twist)')
            return
        if not (linear.any() or angular.any()):
            return
        self._start_teleop()

    def _start_teleop(self):
        """Take over from any goal and follow the twists from the current equilibrium."""
        now = self.clock()
        no_lengths = self._no_lengths(now)
        if no_lengths:
            raise ValueError(no_lengths)
        ticket = self.handover.take('teleoperation (tip_twist)')
        with self.lock:
            goal = self.run.goal
            if goal is not None and self.run.finish(goal, False, 'pre-empted by teleoperation',
                                                    Outcome.PREEMPTED):
                self._report(goal)
            snapshot = self.run.snapshot()
        # the goal run's recovery rule: the last commanded equilibrium while the cables are
        # at its command, else the measurement's estimate and its motor-side lengths
        start = self.run.start_point(self._mean_lengths(self.measurement),
                                     self.current_tip_load(), snapshot)
        commanded = start.commanded if start.recover is None else start.recover
        with self.lock:
            if not self.handover.holds(ticket):  # a goal arrived meanwhile: it wins
                self.log.info('tip_twist not followed: %s arrived after it'
                              % self.handover.holder)
                return
            self.teleop.start(start.state, commanded)
            self._last_tick = now
            self.timer.reset()
        self.log.info('teleoperation: following tip_twist (dead-man %.3g s)'
                      % self.params['twist_timeout'])

    def _end_teleop(self, reason):
        """Stop teleoperation (under the lock); the goal run starts from where it left off."""
        teleop = self.teleop
        if teleop.active:
            teleop.stop(reason)
        if teleop.state is not None:
            self.run.adopt(teleop.state, teleop.commanded)
            teleop.state = None
            self.log.info('teleoperation ended: %s' % teleop.reason)

    # -- the control loop --------------------------------------------------------------------
    def tick(self) -> 'np.ndarray | None':
        """One control period: return the cable lengths (m) to command, or None.

        With nothing to control the timer stops itself, only ever here, in its own callback and
        under the lock goal starts reset it under: a timer another thread cancels between the
        executor's wait and its call raises in the executor (Jazzy's rclpy: "timer is canceled")
        and stops the node.
        """
        params = self.params
        with self.lock:
            now = self.clock()
            elapsed, self._last_tick = max(now - (self._last_tick or now), 0.0), now
            if self.teleop.active or self.teleop.state is not None:
                # a late tick catches up (the cable speed limit still bounds the step)
                commanded = self.teleop.tick(now, min(elapsed, params['twist_timeout']),
                                             self._twist, self.current_tip_load())
                if self.teleop.stopped:
                    self.problems.add('tip_twist', self.teleop.stopped)
                if not self.teleop.active:
                    self._end_teleop(self.teleop.reason)
            else:
                commanded = self._tick_goal(now, min(elapsed, 3.0 / params['control_rate']))
            if self.run.goal is None and not self.teleop.active:
                self.timer.cancel()
        if commanded is None:
            return None
        limits = self.run.limits
        return np.clip(commanded, limits[:, 0], limits[:, 1])

    def _tick_goal(self, now, dt):
        """One tick of the goal run (under the lock); the command to publish or None."""
        goal = self.run.goal
        if goal is None:
            return None
        refusal = self.driver_refusal()
        if refusal:
            self.run.finish(goal, False, 'cable_driver refuses cable_commands: %s' % refusal)
            self._report(goal)
            return None
        contact = self._contact_since
        if self.params['stop_on_contact'] and contact is not None and contact >= goal.started:
            self.run.finish(goal, False, 'stopped on contact: tip_contact turned true %.2f s '
                            'into the goal (stop_on_contact)' % (contact - goal.started))
            self._report(goal)
            measurement = self.measurement  # hold where the cables are
            return None if measurement is None else measurement.lengths.copy()
        with self._samples_lock:
            tips, measured_tips = tuple(self._tips), tuple(self._measured_tips)
        tip, tips, self.tip_source, warning = self.tracker.judged(
            now, self.measured_tip, measured_tips, self.tip, tips,
            self.params['max_state_age'], self.params['use_measured_tip'])
        if warning:
            self.problems.add('tip_pose_measured', warning)
            self.log.warning(warning)
        self.run.tip_source = self.tip_source  # the abort message names the real cause
        commanded = self.run.tick(now, dt, self.measurement, tip, tips, self.current_tip_load())
        for note in self.run.notes:
            self.problems.add('ramp', note)
            self.log.warning(note)
        self.run.notes.clear()
        if goal.done.is_set():
            self._report(goal)
        return commanded

    def release(self) -> None:
        """End the goal in progress (shutdown): every waiter returns."""
        self.closing = True
        with self.lock:
            goal = self.run.goal
            if goal is not None and self.run.finish(goal, False, 'shutting down'):
                self._report(goal)
