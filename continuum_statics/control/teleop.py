"""Resolved-rate teleoperation: a tip velocity followed through the model's equilibria.

The tip Jacobian of paper sec. V.B works inside each warm-started tip-goal solve.

Every control period the tip target advances by v dt (v capped at ``max_tip_speed``) and one
constrained Newton step (the probe's forward-difference Jacobian, the tip moment balance held)
moves the solver state there from the previous equilibrium, so each command is the cable-length
set of a shape of the robot at ~1 ms a step; a step that would move a cable faster than
``max_cable_speed`` is shortened. Where the target leaves the reachable set (the workspace
boundary, a cable at a length limit) the tip stops there and the run says why. With no twist for
``twist_timeout`` (the dead-man) the run ends and the cables hold; before that, a twist moves
the tip only for :func:`twist_hold` (about two message intervals of the stream), so the tip
travels no further after the last message than between two of them. An angular velocity turns the
tip direction goal (the tip's z axis) when the robot has the freedoms for it. No ROS.
"""
from dataclasses import dataclass

import numpy as np

from continuum_statics.core.description.layout import ProbeRows
from continuum_statics.core.rod.rotations import rotation_vector_matrix
from continuum_statics.core.statics.tendon_commands import command_for_state


@dataclass(frozen=True)
class TeleopSettings:
    """Limits of teleoperation (m/s, rad/s, s, m)."""

    max_tip_speed: float = 0.05
    max_tip_rate: float = 0.5
    twist_timeout: float = 0.5
    max_cable_speed: float = 0.02


#: Why a twist is not followed where the model has no equilibrium along it.
BOUNDARY = ('the workspace boundary: the robot has no freedom in that direction here (e.g. '
            'along the axis of a straight section, which its cables cannot shorten)')
#: A twist moves the tip for this many intervals of its stream (jitter of a 2x late message).
HOLD_INTERVALS = 2.5
#: How long the first twist of a stream moves the tip, s (its rate is not known yet).
FIRST_HOLD = 0.1


@dataclass(frozen=True, eq=False)
class Twist:
    """One ``tip_twist``: linear (3,) m/s and angular (3,) rad/s in the base frame."""

    linear: np.ndarray
    angular: np.ndarray
    received: float  # monotonic s
    hold: float = FIRST_HOLD  # s it moves the tip after it arrived (:func:`twist_hold`)


def twist_hold(previous, received, timeout):
    """Seconds a twist arriving at ``received`` moves the tip (monotonic s throughout).

    :param previous: arrival of the stream's previous twist, or None
    :param timeout: ``twist_timeout``, the longest hold
    """
    interval = None if previous is None else received - previous
    if interval is None or not 0.0 < interval <= timeout:
        return min(FIRST_HOLD, timeout)
    return min(HOLD_INTERVALS * interval, timeout)


class TeleopRun:
    """Teleoperation in progress: ``active`` until the dead-man ends it."""

    def __init__(self, robot, settings=TeleopSettings()):
        self.robot = robot
        self.settings = settings
        self.limits = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)
        self.active = False
        self.state = None  # the shape (an equilibrium) commanded last
        self.x = None  # its solver state
        self.fixed = None  # its fixed cable tensions (N), held while the section moments move
        self.commanded = None  # its cable lengths (m)
        self.target = None  # where the twist has taken the tip so far (m, base frame)
        self.direction = None  # its tip z axis while an angular twist steers it, else None
        self.stopped = ''  # why the tip does not follow the twist ('' while it does)
        self.reason = ''  # why the run ended

    def start(self, state, commanded):
        """Start from an equilibrium (an estimate or a solution) and the lengths commanded."""
        shape = getattr(state, 'shape', state)
        self.x = np.array(shape.state, dtype=float)
        # a shape of measured lengths may carry its cables' tensions (the tendon model): they
        # stay, and the twist moves the section moments on top of them
        self.fixed = self.robot.tensions_or_zero(getattr(shape, 'fixed_tensions', None)).copy()
        self.state = shape
        self.commanded = np.clip(np.asarray(commanded, dtype=float), self.limits[:, 0],
                                 self.limits[:, 1])
        self.target = np.array(shape.tip_position, dtype=float)
        self.direction = None
        self.active, self.stopped, self.reason = True, '', ''

    def stop(self, reason):
        """End the run (the cables hold the last command)."""
        self.active, self.reason = False, reason

    def tick(self, now, dt, twist, load):
        """Advance one control period of ``dt`` s; return the command (m), or None once ended."""
        if not self.active:
            return None
        settings = self.settings
        age = now - twist.received
        if age > settings.twist_timeout:
            self.stop('dead-man: no tip_twist for %.2f s (twist_timeout %.3g s)'
                      % (age, settings.twist_timeout))
            return None
        velocity = _capped(np.asarray(twist.linear, dtype=float), settings.max_tip_speed)
        rate = _capped(np.asarray(twist.angular, dtype=float), settings.max_tip_rate)
        if age > twist.hold:  # the stream paused: hold until it resumes or the dead-man
            velocity, rate = np.zeros(3), np.zeros(3)
        if not (velocity.any() or rate.any()):
            self.stopped = ''
            return self.commanded
        fraction, why = 1.0, ''
        for _ in range(4):  # shorten the step until no cable moves faster than allowed
            step = self._step(velocity * dt * fraction, rate * dt * fraction, load)
            if step is None:
                why = BOUNDARY
                break
            x, lengths, tip, direction = step
            change = float(np.max(np.abs(lengths - self.commanded)))
            budget = settings.max_cable_speed * dt
            if change <= budget * 1.05:
                break
            fraction *= 0.9 * budget / change
        else:
            why = 'the cable speed limit'
        if step is not None and not why:
            outside = np.flatnonzero((lengths < self.limits[:, 0]) |
                                     (lengths > self.limits[:, 1]))
            wanted = velocity * dt * fraction
            moved = tip - self.state.tip_position
            if outside.size:
                why = 'the length limit of ' + ', '.join(self.robot.cable_names[i]
                                                        for i in outside)
            elif velocity.any() and moved @ wanted < 0.5 * (wanted @ wanted):
                why = BOUNDARY + ' (the tip moved %.0f %% of the step asked)' % (
                    100.0 * max(0.0, moved @ wanted) / (wanted @ wanted))
        if why:
            self.stopped = 'stopped at %s: the tip cannot follow the twist further' % why
            return self.commanded
        self.stopped = ''
        # the target integrates v dt exactly, so the linearisation's small errors do not add
        # up; where the tip could not follow (along a boundary) it restarts from the tip
        target = self.target + velocity * dt * fraction
        lag = float(np.linalg.norm(tip - target))
        self.target = target if lag <= 0.25 * float(np.linalg.norm(wanted)) + 1e-6 else tip
        self.x, self.commanded, self.direction = x, lengths, direction
        states = self.robot.integrate_state(x, load[:3], self.fixed)
        self.state = self.robot.make_shape(x, load[:3], states, self.fixed)
        return self.commanded

    def _step(self, move, turn, load):
        """One constrained Newton step of the state towards the moved tip (and turned axis).

        Rows: tip position to ``target + move`` and the tip moment balance (equilibrium), plus
        the tip axis when turning; the least-norm step spreads the motion over the sections.
        Returns (state, its cable lengths, its tip, direction goal) or None if not finite.
        """
        robot = self.robot
        n = len(robot.cable_names)
        # copies: the node's zero load is read-only, and numba compiles another signature for
        # a read-only array (seconds on a cold cache, in the middle of a twist)
        force, moment = np.array(load[:3], dtype=float), np.array(load[3:], dtype=float)
        probed = robot.probe(self.x, robot.state_size, force, moment, self.fixed)
        values, jac = probed.values, probed.jacobian
        probe = ProbeRows(n)
        rows = [jac[probe.tip], jac[probe.balance]]
        rhs = [self.target + move - values[probe.tip], -values[probe.balance]]
        direction = self.direction
        if turn.any():
            axis = direction if direction is not None else values[probe.axis]
            direction = rotation_vector_matrix(turn) @ axis
            rows.append(jac[probe.axis] * robot.length)
            rhs.append((direction - values[probe.axis]) * robot.length)
        delta = np.linalg.lstsq(np.vstack(rows), np.concatenate(rhs), rcond=1e-10)[0]
        x = self.x + delta
        values = robot.probe(x, 0, force, moment, self.fixed).values
        if not np.all(np.isfinite(values)):
            return None
        try:  # the motors' lengths: the stretch of the tensions this state needs
            lengths = command_for_state(robot, x, values[probe.lengths].copy(),
                                        self.fixed).lengths
        except ValueError:  # more tension than tension_limits allow: as far as it goes
            return None
        return x, lengths, values[probe.tip].copy(), direction


def _capped(vector, limit):
    """``vector`` scaled down to norm ``limit`` when longer."""
    norm = float(np.linalg.norm(vector))
    return vector * (limit / norm) if norm > limit else vector
