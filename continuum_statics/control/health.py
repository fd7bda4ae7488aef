"""What each node reports on ``/diagnostics``, decided without ROS.

One health object per node turns the node's counters and state into a :class:`Health`: a level,
a message a user can act on and the key/values of the status. The node only converts that into
a ``diagnostic_msgs/DiagnosticArray`` (:mod:`continuum_statics.nodes.diagnostics_util`). The
levels are the ``DiagnosticStatus`` byte values as ints, so ``max()`` picks the worst.

Also here, because every health object reads them: the windows and rate meters of the counters,
and :class:`Problems`, the one throttled record of rejected input every node uses.
"""
from collections import deque
import math
import time
from typing import NamedTuple

import numpy as np

#: Levels as ints, equal to diagnostic_msgs/DiagnosticStatus OK, WARN, ERROR, STALE.
OK, WARN, ERROR, STALE = 0, 1, 2, 3
#: s a matched publisher of cable_states (or tip_pose, for tip_controller) may stay unheard
#: before the node names the transport.
UNHEARD_TIME = 5.0
#: Message prefix of a node that cannot serve yet (compiling kernels, waiting for its inputs).
STARTING = 'starting: '
#: A rejection of one kind is logged at most once in this many seconds.
THROTTLE_S = 2.0


class Health(NamedTuple):
    """One node's status: level (:data:`OK` ...), message, and key/values."""

    level: int
    message: str
    values: dict


class Problems:
    """The latest reason for each kind of rejected input, with counts, for diagnostics.

    :param warn: called with the text of a rejection to log (``logger.warning``), at most once
        per ``throttle`` seconds for each kind; None logs nothing
    :param clock: monotonic seconds
    """

    def __init__(self, warn=None, throttle=THROTTLE_S, clock=time.monotonic):
        self.counts = {}
        self.last_reason = ''
        self.last_time = None
        self._warn, self._throttle, self._clock = warn, throttle, clock
        self._logged = {}  # kind -> monotonic s of its last log line

    def add(self, kind, reason):
        """Record one rejected input of ``kind`` (e.g. 'cable_states') with its reason."""
        self.counts[kind] = self.counts.get(kind, 0) + 1
        reason = '%s: %s' % (kind, reason)
        # one huge bad message must not bloat every later diagnostics message
        self.last_reason = reason if len(reason) <= 300 else reason[:297] + '...'
        self.last_time = self._clock()

    def reject(self, kind, reason):
        """Record a dropped input and log it, throttled per kind (the one ``_reject`` rule)."""
        self.add(kind, reason)
        last = self._logged.get(kind)
        if self._warn is not None and (last is None or self.last_time - last >= self._throttle):
            self._logged[kind] = self.last_time
            self._warn('dropped %s: %s' % (kind, reason))

    def recent(self, window):
        """Return True if something was rejected in the last ``window`` seconds."""
        return self.last_time is not None and self._clock() - self.last_time < window

    def values(self):
        """Return key/values: a rejected count per kind and the last reason."""
        values = {'rejected_%s' % kind: count for kind, count in sorted(self.counts.items())}
        values['last_rejection'] = self.last_reason or 'none'
        return values


class RateMeter:
    """Events per second over the interval between two reports."""

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._count = 0
        self._since = clock()
        self.total = 0

    def tick(self, n=1):
        """Count ``n`` events."""
        self._count += n
        self.total += n

    def report(self):
        """Return the rate in Hz since the last report and start a new interval."""
        now = self._clock()
        elapsed = now - self._since
        rate = self._count / elapsed if elapsed > 0.0 else 0.0
        self._count, self._since = 0, now
        return rate


class ValueWindow:
    """Values collected since the last report (e.g. residuals, m): count, median and max."""

    def __init__(self, capacity=5000):
        self._capacity = capacity
        self._samples = deque(maxlen=capacity)

    def add(self, value):
        """Record one value."""
        self._samples.append(value)

    def report(self):
        """Return (count, median, max) and start a new window; (0, nan, nan) when empty."""
        # handed over, not iterated: another thread may be adding to the window
        window, self._samples = self._samples, deque(maxlen=self._capacity)
        samples = np.array(window, dtype=float)
        if samples.size == 0:
            return 0, math.nan, math.nan
        return samples.size, float(np.median(samples)), float(samples.max())


class TimingWindow(ValueWindow):
    """Durations (s) collected since the last report: median and max in ms."""

    def report(self):
        """Return (count, median ms, max ms) and start a new window; NaN-free (0 when empty)."""
        count, median, largest = super().report()
        return (count, median * 1e3, largest * 1e3) if count else (0, 0.0, 0.0)


def tendon_values(names, tensions, slack):
    """Diagnostic values of the tendon model: which cables are slack, model tensions (N).

    ``tensions``/``slack`` are the estimate's (None when the shape came from ideal taut cables).
    """
    if tensions is None or slack is None:
        return {'slack_cables': 'none', 'tension_estimates_n': 'not estimated (taut ideal cables)'}
    return {'slack_cables': ', '.join(n for n, s in zip(names, slack) if s) or 'none',
            'tension_estimates_n': ', '.join('%s %.4g' % (n, t) for n, t in zip(names, tensions))}


def load_values(load, age, expired, force_limit, torque_limit):
    """Diagnostic values of the tip load a node uses (N, N m, s)."""
    return {'tip_force_n': ' '.join('%.4g' % f for f in load[:3]),
            'tip_moment_nm': ' '.join('%.4g' % f for f in load[3:]),
            'max_tip_force_n': force_limit, 'max_tip_torque_nm': torque_limit,
            'tip_wrench_age_s': age, 'tip_wrench_expired': expired}


# -- statics --------------------------------------------------------------------------------------
class StaticsHealth:
    """The statics node's counters and the status they make.

    The node tells it what happened to each input (:meth:`received`, :meth:`rejected`,
    :meth:`estimated`, :meth:`published`) and asks for :meth:`report` at the diagnostics rate.
    """

    def __init__(self, cable_names, warn=None, passive=False, clock=time.monotonic):
        self.cable_names = tuple(cable_names)
        self.passive = passive
        self._clock = clock
        self.problems = Problems(warn, clock=clock)
        self.last = {'residual': math.nan, 'iterations': 0, 'converged': False,
                     'message': 'waiting for cable_states', 'time': None, 'tensions': False}
        if passive:
            self.last['message'] = 'passive rod (no cables): shape from gravity and tip_wrench'
        self.residuals = ValueWindow()
        self.solve_times = TimingWindow()
        self.cycle_times = TimingWindow()
        self.input_rate = RateMeter(clock)
        self.output_rate = RateMeter(clock)
        self.best_fits = 0  # published with a residual above the warn threshold
        self.capped = 0  # estimates left unfinished by max_iterations/max_model_runs
        self.empty_payloads = 0
        self.limit_rejections = 0
        self.not_converged = 0
        self.tensions_distrusted = 0
        self._started = clock()
        self._distrust = ('', None)  # (why the tensions were not used, monotonic time)
        self._lost_reported = 0

    def received(self, data):
        """Count one serialized ``cable_states`` (empty payloads too)."""
        self.input_rate.tick()
        if not data:
            self.empty_payloads += 1

    def rejected(self, reason, outside_limits=False):
        """Drop one cable_states; the status no longer shows the last estimate's values."""
        self.limit_rejections += bool(outside_limits)
        self.last.update(residual=math.nan, iterations=0, converged=False,
                         message='no estimate: the last cable_states was rejected')
        self.problems.reject('cable_states', reason)

    def estimated(self, result, solve_time):
        """Count an estimate (a :class:`~continuum_statics.control.shape_tracking` result)."""
        now = self._clock()
        self.solve_times.add(solve_time)
        if result.distrust:
            self.tensions_distrusted += 1
            self._distrust = (result.distrust, now)
        self.capped += result.capped
        estimate = result.estimate
        self.last.update(residual=result.residual, iterations=estimate.iterations,
                         converged=result.converged, message=result.message, time=now,
                         tensions=result.tensions_used, model_tensions=estimate.tensions,
                         slack=estimate.slack)
        self.residuals.add(result.residual)
        if not (estimate.converged or result.capped):
            self.not_converged += 1
        if result.rejection:
            self.problems.reject('cable_states', result.rejection)
        else:
            self.best_fits += result.best_fit

    def solved_passive(self, solve_time):
        """Count the passive rod's shape, solved and published."""
        self.solve_times.add(solve_time)
        self.last.update(residual=0.0, iterations=0, converged=True, time=self._clock())

    def published(self, cycle_time=None):
        """Count one published shape (``cycle_time`` s from arrival, when measured)."""
        self.output_rate.tick()
        if cycle_time is not None:
            self.cycle_times.add(cycle_time)

    def report(self, warn_residual, drop_residual, lost=0, skipped=0, publishers=0) -> Health:
        """Return the :class:`Health` of now (and start new windows).

        :param warn_residual: the warn threshold in force, m (``drop_residual`` likewise)
        :param lost: measurements the intake lost in all; ``skipped`` drained in all
        :param publishers: how many nodes publish ``cable_states``
        """
        now, last = self._clock(), self.last
        input_rate, output_rate = self.input_rate.report(), self.output_rate.report()
        solves, solve_median, solve_max = self.solve_times.report()
        _, cycle_median, cycle_max = self.cycle_times.report()
        _, residual_median, residual_max = self.residuals.report()
        lost_now, self._lost_reported = lost - self._lost_reported, lost
        level, message = OK, 'estimating the shape'
        if self.passive:
            message = last['message']
        elif (self.input_rate.total == 0 and publishers
              and now - self._started > UNHEARD_TIME):
            level, message = WARN, unheard_message('cable_states', now - self._started,
                                                   publishers, 'cable_driver')
        elif self.output_rate.total == 0:
            message = STARTING + (
                'waiting for the first cable_states (is cable_driver running?)'
                if last['time'] is None else 'no cable_states fits a shape yet: %s'
                % (self.problems.last_reason or last['message']))
        elif last['time'] is None or now - last['time'] > 1.0:
            level, message = WARN, 'no cable_states for over 1 s'
        elif residual_median > warn_residual:
            level, message = WARN, (
                'publishing best fits: residual median %.3g m > warn_residual %.3g m (cable '
                'slack, stretch or encoder noise above length_noise_std?)'
                % (residual_median, warn_residual))
        if self._distrust[1] is not None and now - self._distrust[1] < 2.0:
            level, message = WARN, self._distrust[0]
        if self.problems.recent(2.0):
            level, message = WARN, 'rejected ' + self.problems.last_reason
        if lost_now > 0:  # the node stalled (or the transport dropped): never under an OK
            level, message = WARN, '%d cable_states lost since the last report (%s)' % (
                lost_now, message)
        values = {
            'status': message,
            'state': 'starting' if self.output_rate.total == 0 else 'ready',
            'input_rate_hz': input_rate, 'output_rate_hz': output_rate, 'solves': solves,
            'received_total': self.input_rate.total, 'published_total': self.output_rate.total,
            'input_skipped_total': skipped, 'input_lost_total': lost,
            'empty_payloads_total': self.empty_payloads,
            'outside_limits_total': self.limit_rejections,
            'solve_time_median_ms': solve_median, 'solve_time_max_ms': solve_max,
            'cycle_time_median_ms': cycle_median, 'cycle_time_max_ms': cycle_max,
            'residual_m': last['residual'], 'residual_median_m': residual_median,
            'residual_max_m': residual_max, 'warn_residual_m': warn_residual,
            'max_residual_m': drop_residual, 'best_fits_total': self.best_fits,
            'iterations': last['iterations'], 'converged': last['converged'],
            'estimate_message': last['message'] or 'none',
            'not_converged_total': self.not_converged, 'iteration_capped_total': self.capped,
            'measured_tensions_used': last['tensions'],
            'tensions_distrusted_total': self.tensions_distrusted,
        }
        values.update(tendon_values(self.cable_names, last.get('model_tensions'),
                                    last.get('slack')))
        values.update(self.problems.values())
        return Health(level, message, values)


# -- cable_driver ---------------------------------------------------------------------------------
class DriverHealth:
    """The cable_driver's counters and the status they make with its command gate's state."""

    def __init__(self, backend_name, warn=None, has_cables=True, clock=time.monotonic):
        self.backend_name = backend_name
        self.has_cables = has_cables
        self.problems = Problems(warn, clock=clock)
        self.rate = RateMeter(clock)  # published cable_states
        self.empty_payloads = 0

    def report(self, gate, status, reconnects=0) -> Health:
        """Return the :class:`Health` of now.

        :param gate: the node's :class:`~continuum_statics.control.command_gate.CommandGate`
        :param status: the backend's last ``BackendStatus`` (level, message, values), or None
            while there is no backend (unconfigured)
        :param reconnects: connections regained after a loss
        """
        refusal = gate.refusal() if self.has_cables else ''
        values = {'backend': self.backend_name, 'lifecycle': gate.lifecycle_state(),
                  'accepts_commands': not refusal, 'refusal': refusal}
        if not self.has_cables:
            return Health(OK, 'robot has no cables: nothing to drive', values)
        if gate.finalized:
            return Health(OK, 'shut down (lifecycle finalized): actuators released; restart '
                              'cable_driver to drive the cables', values)
        if status is None:
            return Health(OK, 'unconfigured (lifecycle): configure and activate cable_driver '
                              'to drive the cables', values)
        level, message = status.level, status.message
        if not gate.connected:
            level, message = ERROR, 'connection lost: %s' % gate.connection_error
        elif gate.backend_error:
            level, message = ERROR, gate.backend_error
        elif level < ERROR and self.problems.recent(2.0):
            level, message = max(level, WARN), 'rejected ' + self.problems.last_reason
        elif level == OK and self.rate.total == 0:
            message = STARTING + 'waiting for the first reading (%s)' % message
        elif level == OK and not gate.active:
            message = 'inactive (lifecycle): torque off, commands refused (%s)' % message
        elif level == OK and gate.holding:
            message = '%s; holding position (no command)' % message
        values.update({
            'state': 'ready' if self.rate.total else 'starting',
            'connected': gate.connected,
            'reconnects': reconnects,
            'publish_rate_hz': self.rate.report(),
            'commands_accepted': gate.accepted,
            'commands_clamped': gate.clamped,
            'commands_refused': gate.refused,
            'holding': gate.holding,
        })
        values.update(self.problems.values())
        values['empty_payloads_total'] = str(self.empty_payloads)
        values.update(status.values)
        return Health(level, message, values)


# -- tip_controller -------------------------------------------------------------------------------
class ControllerHealth:
    """The tip_controller's status, read from its :class:`~.tip_control.TipControl`."""

    def __init__(self, control):
        self.control = control
        self._started = control.clock()

    def report(self, publishers=None, command_topic='cable_commands') -> Health:
        """Return the :class:`Health` of now.

        :param publishers: topic -> how many nodes publish it (``Node.count_publishers``: this
            node included for ``command_topic``); None: nobody else
        """
        publishers = publishers or (lambda topic: 0)
        control = self.control
        with control.lock:
            run = control.run
            goal, phase = run.goal, run.phase.value
            corrections, fraction, moved = run.corrections, run.fraction, run.moved_onto_model
        teleop, problems = control.teleop, control.problems
        level, message = OK, 'idle' if goal is None else 'moving to a goal (%s)' % phase
        if teleop.active:
            message = 'teleoperation (tip_twist)'
            if teleop.stopped:
                level, message = WARN, 'teleoperation ' + teleop.stopped
        missing = control.missing_state()
        if missing:
            message = STARTING + 'waiting for state: ' + missing
            unheard = _unheard(control, publishers, control.clock() - self._started)
            if unheard:
                level, message = WARN, unheard
        if problems.recent(5.0):
            level, message = WARN, problems.last_reason
        command_publishers = publishers(command_topic) or 0
        if command_publishers > 1:  # e.g. two bringups in one namespace: two loops fight
            level, message = WARN, (
                'another node also publishes %s (%d publishers): two controllers in one '
                'namespace?' % (command_topic, command_publishers))
        counts = control.counts
        values = {
            'state': 'starting' if missing else 'ready',
            'phase': phase,
            'teleoperation': teleop.active,
        }
        for outcome, count in counts.items():
            values['goals_' + outcome.value] = count
        values.update({
            'moved_onto_model_total': moved,
            'last_outcome': control.last_outcome,
            'have_tip_pose': control.tip is not None,
            'tip_source': control.tip_source,
            'have_tip_pose_measured': control.measured_tip is not None,
            'have_cable_states': control.measurement is not None,
        })
        if goal is not None:
            values['goal_m'] = '%.5f %.5f %.5f' % tuple(goal.position)
            values['tip_error_mm'] = goal.error * 1e3
            values['corrections'] = corrections
            values['ramp_fraction'] = fraction
        values.update(problems.values())
        return Health(level, message, values)


def _unheard(control, publishers, elapsed):
    """Name an input that has publishers and was never heard in UNHEARD_TIME s, or ''."""
    if elapsed <= UNHEARD_TIME:
        return ''
    for topic, state, node in (('cable_states', control.measurement, 'cable_driver'),
                               ('tip_pose', control.tip, 'statics')):
        if state is None:
            # the first input missing decides: statics publishes tip_pose for cable_states
            count = publishers(topic)
            if not count:
                return ''  # nobody publishes it yet: the node is still waiting for it
            return unheard_message(topic, elapsed, count, node)
    return ''


def unheard_message(topic, elapsed, count, node):
    """Return the WARN of a ``topic`` whose ``count`` publishers sent nothing in ``elapsed`` s."""
    return ('no %s in %.0f s from its %d publisher(s): is %s inactive or failing (its '
            '/diagnostics)? If this node was restarted after a crash, Fast DDS can go on '
            'delivering to the dead process (eProsima/Fast-DDS#5053): restart %s'
            % (topic, elapsed, count, node, node))
