"""Resolved-rate teleoperation: a tip velocity followed through the model's equilibria.

The tip Jacobian of paper sec. V.B works inside each warm-started tip-goal solve.

Every control period the tip target advances by v dt (v capped at ``max_tip_speed``) and the
equilibrium with its tip there is solved from the previous one, so each command is the
cable-length set of a shape of the robot; a step that would move a cable faster than
``max_cable_speed`` is shortened. Where the target leaves the reachable set (the workspace
boundary, a cable at a length limit) the tip stops there and the run says why. With no twist for
``twist_timeout`` (the dead-man) the run ends and the cables hold. An angular velocity turns the
tip direction goal (the tip's z axis) when the robot has the freedoms for it. No ROS.
"""
from dataclasses import dataclass

import numpy as np

from continuum_statics.core.rotations import rotation_vector_matrix


@dataclass(frozen=True)
class TeleopSettings:
    """Limits of teleoperation (m/s, rad/s, s, m)."""

    max_tip_speed: float = 0.05
    max_tip_rate: float = 0.5
    twist_timeout: float = 0.5
    max_cable_speed: float = 0.02
    step_tolerance: float = 1e-5  # the solve's; a step within 10x of it is taken (m)


@dataclass(frozen=True, eq=False)
class Twist:
    """One ``tip_twist``: linear (3,) m/s and angular (3,) rad/s in the base frame."""

    linear: np.ndarray
    angular: np.ndarray
    received: float  # monotonic s


class TeleopRun:
    """Teleoperation in progress: ``active`` until the dead-man ends it."""

    def __init__(self, robot, settings=TeleopSettings()):
        self.robot = robot
        self.settings = settings
        self.limits = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)
        self.active = False
        self.state = None  # the equilibrium commanded last
        self.commanded = None  # its cable lengths (m)
        self.target = None  # where the twist has taken the tip so far (m, base frame)
        self.direction = None  # its tip z axis while an angular twist steers it, else None
        self.stopped = ''  # why the tip does not follow the twist ('' while it does)
        self.reason = ''  # why the run ended

    def start(self, state, commanded):
        """Start from an equilibrium (an estimate or a solution) and the lengths commanded."""
        self.state = state
        self.commanded = np.clip(np.asarray(commanded, dtype=float), self.limits[:, 0],
                                 self.limits[:, 1])
        self.target = np.array(state.shape.tip_position, dtype=float)
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
        if not (velocity.any() or rate.any()):
            self.stopped = ''
            return self.commanded
        fraction = 1.0
        for _ in range(4):  # shorten the step until no cable moves faster than allowed
            solution, direction = self._solve(velocity * dt * fraction, rate * dt * fraction,
                                              load)
            lengths = np.asarray(solution.cable_lengths, dtype=float)
            change = float(np.max(np.abs(lengths - self.commanded)))
            budget = settings.max_cable_speed * dt
            if change <= budget * 1.05 or not np.isfinite(change):
                break
            fraction *= 0.9 * budget / change
        wanted = float(np.linalg.norm(velocity)) * dt * fraction
        if not (np.all(np.isfinite(lengths)) and change <= budget * 1.05
                and solution.error <= max(0.5 * wanted, 10.0 * settings.step_tolerance)):
            limited = ', '.join(solution.limited_cables)
            self.stopped = ('stopped at %s: the tip cannot follow the twist further' % (
                'the length limit of ' + limited if limited else 'the workspace boundary'))
            return self.commanded
        self.stopped = ''
        # the target integrates v dt exactly: the solver's small errors do not add up
        self.state, self.commanded = solution, lengths
        self.target = self.target + velocity * dt * fraction
        self.direction = direction
        return self.commanded

    def _solve(self, step, turn, load):
        """Solve the equilibrium with the tip ``step`` (m) on and its axis turned by ``turn``."""
        direction = self.direction
        if turn.any():
            axis = direction if direction is not None else self.state.shape.tip_rotation[:, 2]
            direction = rotation_vector_matrix(turn) @ axis
        solution = self.robot.solve_tip_goal(
            self.target + step, tip_force=load[:3], tip_moment=load[3:],
            tolerance=self.settings.step_tolerance, goal_direction=direction,
            warm_start=self.state)
        return solution, direction


def _capped(vector, limit):
    """``vector`` scaled down to norm ``limit`` when longer."""
    norm = float(np.linalg.norm(vector))
    return vector * (limit / norm) if norm > limit else vector
