"""Tip goals: goal position (and direction) -> solver state -> cable lengths (paper sec. V.B).

The unknowns are the solver state (u(0) and the section moments), always subject to the tip moment
balance, so every answer is an equilibrium of the robot. Two cases:

- as many bending freedoms as goal equations or fewer (one section; or a position and a direction
  with two sections): damped least squares on the goal; a goal off the reachable set converges to
  the nearest reachable tip and reports the remaining distance as ``error``;
- more freedoms (2+ sections for a position): the goal becomes an equality constraint and, among
  the solutions, the one whose section moments change least from the warm start is chosen (from a
  cold start: the smallest section moments, i.e. the least cable load): the least-squares solve
  reaches the goal first, then the solution slides along the goal's solution set.

Cable length limits are kept with an active set (a cable leaving its range is held at the limit as
one more constraint). Whatever happens, the answer's lengths are inside the limits: if the solve
ends outside them, the answer is the equilibrium furthest along the way from the start to it that
stays inside, reported as not reached.
"""
from dataclasses import dataclass, replace
import math

import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.description.layout import ProbeRows
from continuum_statics.core.rod.goal_tracking import GoalLimits, GoalRows
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.statics import bvp
from continuum_statics.core.statics import clearance as clear

#: Slack on the length limits (m) for round-off.
LIMIT_SLACK = 1e-9
#: Weight of a length-limit violation against the change of the section moments (m per m).
LIMIT_PENALTY = 1e3
_NO_DIRECTION = np.zeros(0)


@dataclass(frozen=True, eq=False)
class TipGoalSolution:
    """Result of :func:`solve_tip_goal`.

    :ivar shape: backbone at the solution (its ``state`` warm-starts the next solve)
    :ivar u0: base bending (1/m)
    :ivar cable_lengths: cable lengths to command (m), ``robot.cable_names`` order, in limits
    :ivar converged: the tip is within the tolerance of the goal (and of the direction)
    :ivar error: distance from the reached tip to the goal (m)
    :ivar iterations: Gauss-Newton iterations used, over all rounds
    :ivar limited_cables: names of cables held at a length limit
    :ivar message: why the goal was not reached, empty when it was
    :ivar waypoints: solutions to pass through, in order, before this one (a clearance goal
        whose direct path passes too close: :mod:`clearance`); empty for a direct path
    :ivar clearance: closest approach of the body to an obstacle on the way (m beyond the body
        radius), NaN without obstacles
    """

    shape: Shape
    u0: np.ndarray
    cable_lengths: np.ndarray
    converged: bool
    error: float
    iterations: int
    limited_cables: tuple
    message: str
    waypoints: tuple = ()
    clearance: float = math.nan

    @property
    def state(self):
        """Solver state x of the solution."""
        return self.shape.state


def solve_tip_goal(robot, goal_position, tip_force=(0.0, 0.0, 0.0), tolerance=None,
                   goal_direction=None, start=None, tip_moment=(0.0, 0.0, 0.0),
                   clearance=None, obstacles=None):
    """Find the equilibrium whose tip is at ``goal_position`` (m, base frame), lengths in limits.

    :param tip_force: external tip force (N); ``tip_moment`` external tip moment (N m)
    :param tolerance: position tolerance (m); default ``robot.solver.goal_tolerance``; the
        direction tolerance is tolerance / L (rad)
    :param goal_direction: unit vector (base frame) for the tip's local z axis, or None
    :param start: solver state to start from (the current estimate); default passive
    :param obstacles: base-frame obstacles (None: the robot file's); the whole body keeps
        ``clearance`` (m; None: the file's) from them at the answer and on the way there from
        ``start`` (:mod:`clearance`), or the goal is not reached and the message says where
    """
    goal = as_vector(goal_position, 3, 'goal_position')
    tip_force = as_vector(tip_force, 3, 'tip_force')
    tip_moment = as_vector(tip_moment, 3, 'tip_moment')
    tolerance = robot.solver.goal_tolerance if tolerance is None else float(tolerance)
    if not np.isfinite(tolerance) or tolerance <= 0.0:
        raise ValueError('tolerance must be a finite number > 0 m, got %r' % tolerance)
    clearance = robot.clearance if clearance is None else float(clearance)
    if not (math.isfinite(clearance) and clearance >= 0.0):
        raise ValueError('clearance must be a finite number >= 0 m, got %r' % clearance)
    obstacles = robot.obstacles_or_file(obstacles)
    direction = None
    if goal_direction is not None:
        direction = as_vector(goal_direction, 3, 'goal_direction')
        norm = np.linalg.norm(direction)
        if norm < 1e-9:
            raise ValueError('goal_direction must be a non-zero vector')
        direction = direction / norm
    solution = _solve_plain(robot, goal, direction, tip_force, tip_moment, tolerance, start)
    if not obstacles:
        return solution
    return _keep_clear(robot, solution, goal, direction, tip_force, tip_moment, tolerance,
                       start, obstacles, clearance)


def _solve_plain(robot, goal, direction, tip_force, tip_moment, tolerance, start):
    if start is None:
        return _solve(robot, goal, direction, tip_force, tip_moment, tolerance, None)
    # A warm start can lead the solve astray (another branch of the redundant solutions, a
    # limit on the way): a warm solve that fails is retried cold before it answers.
    warm = _solve(robot, goal, direction, tip_force, tip_moment, tolerance, start)
    if warm.converged:
        return warm
    cold = _solve(robot, goal, direction, tip_force, tip_moment, tolerance, None)
    return cold if cold.converged or cold.error < warm.error else warm


def _keep_clear(robot, solution, goal, direction, tip_force, tip_moment, tolerance, start,
                obstacles, clearance):
    """Return ``solution`` if it and its path keep clear, else a clear one, else a refusal."""
    if start is None:
        start = robot.passive_state(bvp.linear_guess(robot, tip_force, tip_moment))
    begin = robot.make_shape(start, tip_force, robot.integrate_state(start, tip_force))
    # a path may not come closer than the body already is (it may start resting on one)
    floor = min(clearance, clear.closest(robot, begin, obstacles).gap) - clear.SLACK
    problem = _Problem(robot, goal, direction, tip_force, tip_moment, tolerance, start)
    worst = clear.closest(robot, solution.shape, obstacles)
    if solution.converged and worst.gap >= clearance - clear.SLACK:
        path = clear.along_path(robot, begin, solution.shape, obstacles, tip_force, tip_moment,
                                floor, clearance)
        if path.gap >= floor:
            return replace(solution, clearance=min(worst.gap, path.gap))
        worst = path
    if not solution.converged:
        return replace(solution, clearance=worst.gap)
    found = None  # the first clear answer at the goal, whatever its path
    for plan in _plans(robot, begin.tip_position, goal, tip_force, tip_moment):
        if isinstance(plan, str):  # staged from the start to that answer
            if found is None:
                continue
            plan = _staged(robot, start, found.state, tip_force, tip_moment, plan) + [goal]
        legs, previous = [], begin
        for k, target in enumerate(plan):
            last = k == len(plan) - 1
            if isinstance(target, Shape):  # home or a stage: a given equilibrium
                shape, leg = target, None
            else:
                x = clear.solve_clear(robot, target, direction if last else None, tip_force,
                                      tip_moment, tolerance, start, (previous.state,
                                      solution.state, _arc_guess(robot, target)), obstacles,
                                      clearance)
                if x is None:
                    break
                leg = problem.answer(x, 0, '')  # judged against the goal: a waypoint is not it
                shape = leg.shape
                if last and leg.converged and found is None:
                    found = leg
            path = clear.along_path(robot, previous, shape, obstacles, tip_force, tip_moment,
                                    floor, clearance)
            if path.gap < floor:
                worst = path
                break
            legs.append(leg or _waypoint(robot, shape))
            previous = shape
        if len(legs) == len(plan) and legs[-1].converged:
            final = legs[-1]
            return replace(final, waypoints=tuple(legs[:-1]),
                           clearance=clear.closest(robot, final.shape, obstacles).gap)
    if found is not None:  # a clear answer no simple way reaches: search for a way
        way = clear.connect(robot, begin, found.shape, obstacles, tip_force, tip_moment, floor,
                            clearance, seed=int(np.abs(goal * 1e6).sum()) % 2 ** 32)
        if way is not None:
            return replace(found, waypoints=tuple(_waypoint(robot, shape)
                                                  for shape in way[1:-1]),
                           clearance=clear.closest(robot, found.shape, obstacles).gap)
    message = 'goal not reached with clearance: ' + worst.says(clearance)
    return replace(solution, converged=False, message=message, clearance=worst.gap)


def _plans(robot, tip0, goal, tip_force, tip_moment):
    """Yield the sequences of targets a clear goal tries, in order.

    Direct; split on the tip's straight line; down to the goal's height near the base axis,
    then out (under a shelf); staged section by section (a name, built once a clear answer is
    known); back through home (the rod with no cable load), then on.
    """
    yield [goal]
    for count in clear.MAX_LEGS:
        yield [tip0 + (goal - tip0) * k / count for k in range(1, count)] + [goal]
    # down to the goal's height near the base axis, then out to it (under a shelf)
    axis, base = robot.base_rotation[:, 2], robot.base_position
    height = (goal - base) @ axis
    inward = base + height * axis + 0.3 * (goal - base - height * axis)
    yield [inward, 0.5 * (inward + goal), goal]
    yield 'base first'  # staged, section by section, to the first clear answer
    yield 'tip first'
    home = bvp.solve_loaded(robot, robot.passive_state(), None, tip_force, tip_moment)
    yield [robot.make_shape(home, tip_force, robot.integrate_state(home, tip_force)), goal]


def _staged(robot, start, goal_state, tip_force, tip_moment, order):
    """Return the equilibria that move one section at a time from ``start`` to the goal's.

    How an operator reaches under a shelf: curl the tip section in first (``'tip first'``),
    then swing the others, or the reverse (``'base first'``); empty with one section.
    """
    stages, x = [], np.array(start, dtype=float)
    sections = range(len(robot.sections) - 1)
    if order == 'tip first':
        sections = range(len(robot.sections) - 1, 0, -1)
    for k in sections:
        first, rank = robot.section_state_index[k], robot.section_ranks[k]
        if first < 0:
            continue
        x = x.copy()
        x[first:first + rank] = goal_state[first:first + rank]
        state, converged = bvp.solve_fixed_loads(robot, x, None, tip_force, tip_moment)
        if not converged:
            return []
        stages.append(robot.make_shape(state, tip_force, robot.integrate_state(state,
                                                                                tip_force)))
    return stages


def _waypoint(robot, shape):
    """Return a waypoint at ``shape`` (home, a stage, a search node): its lengths only."""
    return TipGoalSolution(shape=shape, u0=shape.u0, cable_lengths=robot.cable_lengths(shape),
                           converged=False, error=math.nan, iterations=0, limited_cables=(),
                           message='waypoint')


def _solve(robot, goal, direction, tip_force, tip_moment, tolerance, start):
    """One tip-goal solve from ``start`` (None: the passive rod); see :func:`solve_tip_goal`."""
    if start is None:
        start = robot.passive_state(bvp.linear_guess(robot, tip_force, tip_moment))
    problem = _Problem(robot, goal, direction, tip_force, tip_moment, tolerance, start)
    if not len(robot.cable_names):
        return problem.answer(start, 0, 'robot has no cables: nothing can move the tip')
    # least squares on the goal first (robust from far away), from the start, then (if that
    # ends in a local minimum) from the passive rod and from the circular arc through the goal
    passive = robot.passive_state(bvp.linear_guess(robot, tip_force, tip_moment))
    x, iterations, reached, best = start, 0, False, math.inf
    for x0 in (start, passive, _arc_guess(robot, goal)):
        problem.held, problem.held_at = [], []
        trial, more, trial_reached = problem.solve(x0, redundant=False)
        iterations += more
        error = problem.distance(trial)
        if error < best:
            x, best, reached, held = trial, error, trial_reached, (problem.held, problem.held_at)
        if reached:
            break
    problem.held, problem.held_at = held
    if reached and robot.observable_bending > problem.goal_rows:
        polished, more, still = problem.solve(x, redundant=True)
        iterations += more
        if still:
            x = polished
    return problem.answer(x, iterations, '')


class _Problem:
    """One tip-goal solve: the rows of the goal, the held cables and the final answer."""

    def __init__(self, robot, goal, direction, tip_force, tip_moment, tolerance, start):
        self.robot, self.goal, self.direction = robot, goal, direction
        self.tip_force, self.tip_moment, self.tolerance = tip_force, tip_moment, tolerance
        self.start = np.array(start, dtype=float)
        self.goal_rows = 3 if direction is None else 5
        n = len(robot.cable_names)
        rows = ProbeRows(n)
        self.cables, self.balance = rows.lengths, rows.balance
        self.limits = robot.cable_length_limits
        radius = np.max(np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1]),
                            initial=1e-3)
        self.held_scale = 1.0 / radius  # m of cable -> rad of bending, like the balance rows
        self.held, self.held_at = [], []
        self._fixed = np.zeros(n)

    def distance(self, x):
        """Distance (m) from the tip of state ``x`` to the goal, inf when not finite."""
        values = self.robot.probe(x, 0, self.tip_force, self.tip_moment).values
        error = float(np.linalg.norm(values[0:3] - self.goal))
        return error if np.isfinite(error) else math.inf

    def solve(self, x, redundant):
        """Active-set rounds of the constrained solve; (state, iterations, goal reached)."""
        robot = self.robot
        length = robot.length
        reference = self.start
        iterations = 0
        while True:
            rows = GoalRows(self.goal, _NO_DIRECTION if self.direction is None else
                            self.direction, np.array(self.held, dtype=np.int64),
                            np.array(self.held_at, dtype=float), self.held_scale, self.limits,
                            LIMIT_PENALTY, redundant, reference)
            result = robot.model.goal_solve(
                self.tip_force, self.tip_moment, self._fixed, np.array(x, dtype=float), rows,
                GoalLimits(robot.solver.max_iterations, 0.01 * self.tolerance, length))
            if not result.finite:
                raise ValueError('the rod model is not finite at the start state %s (1/m): is '
                                 'the tip load far beyond what the rod can carry?'
                                 % np.round(x, 4).tolist())
            iterations += result.iterations
            x = result.x
            lengths = result.values[self.cables]
            violated = [i for i in range(len(lengths)) if i not in self.held and not (
                self.limits[i, 0] - LIMIT_SLACK <= lengths[i] <= self.limits[i, 1] + LIMIT_SLACK)]
            if not violated:
                break
            for i in violated:
                self.held.append(i)
                self.held_at.append(float(np.clip(lengths[i], *self.limits[i])))
        values = result.values
        reached = (np.linalg.norm(values[0:3] - self.goal) <= self.tolerance
                   and np.linalg.norm(values[self.balance]) <= 1e-6)
        return x, iterations, reached

    def answer(self, x, iterations, message):
        """Build the solution record for state ``x``, pulled back inside the length limits."""
        robot = self.robot
        states = robot.integrate_state(x, self.tip_force)
        shape = robot.make_shape(x, self.tip_force, states)
        lengths = robot.cable_lengths(shape)
        notes = [message] if message else []
        if not _inside(lengths, self.limits):
            shape, lengths = self._inside_limits(shape)
            notes.append('the solution leaves the cable length limits; stopped at the last '
                         'equilibrium inside them')
        lengths = np.clip(lengths, self.limits[:, 0], self.limits[:, 1])  # round-off (1e-9 m)
        error = float(np.linalg.norm(shape.tip_position - self.goal))
        converged = error <= self.tolerance and not notes
        if self.direction is not None:
            angle = float(np.arccos(np.clip(shape.tip_rotation[:, 2] @ self.direction, -1, 1)))
            converged = converged and angle <= self.tolerance / robot.length
            if angle > self.tolerance / robot.length:
                notes.append('tip direction %.3g rad from the goal direction' % angle)
        limited = tuple(robot.cable_names[i] for i in sorted(self.held))
        if not converged:
            text = 'goal not reached: tip %.3g m from goal (tolerance %.3g m)' % (
                error, self.tolerance)
            if limited:
                text += '; cable(s) at length limit: ' + ', '.join(limited)
            elif not notes and robot.routing.straight:
                text += '; nearest reachable tip (goal outside the reachable set)'
            elif not notes:
                # routed cables: the unknowns are section moments carried by least-norm
                # tensions, so a tip only another tension mix reaches (co-contraction, a helix
                # pulled with its neighbours) is outside this set though the robot reaches it
                text += ('; nearest tip of least-norm tensions (routed cables: a tip that only '
                         'co-contraction reaches is outside this set)')
            notes.insert(0, text)
        return TipGoalSolution(shape=shape, u0=shape.u0, cable_lengths=lengths,
                               converged=converged, error=error, iterations=iterations,
                               limited_cables=limited, message='; '.join(notes))

    def _inside_limits(self, target):
        """Furthest equilibrium inside the limits on the way from the start to ``target``."""
        robot = self.robot
        start = robot.make_shape(self.start, self.tip_force,
                                 robot.integrate_state(self.start, self.tip_force))
        if not _inside(robot.cable_lengths(start), self.limits):
            start = robot.make_shape(robot.passive_state(), self.tip_force,
                                     robot.integrate_state(robot.passive_state(),
                                                           self.tip_force))
        best = robot.equilibrium_between(start, target, 0.0, self.tip_force, self.tip_moment)
        low, high = 0.0, 1.0
        for _ in range(30):
            middle = 0.5 * (low + high)
            trial = robot.equilibrium_between(start, target, middle, self.tip_force,
                                              self.tip_moment, warm_start=best)
            if trial.converged and _inside(trial.cable_lengths, self.limits):
                low, best = middle, trial
            else:
                high = middle
            if high - low < 1e-4:
                break
        return best.shape, best.cable_lengths


def _arc_guess(robot, goal):
    """State of the circular arc from the base, tangent to its axis, through the goal.

    The whole rod bends at the curvature kappa = 2 rho / (rho^2 + z^2) of that arc (rho, z: the
    goal's distance from and along the base axis), carried by the tip section's cables.
    """
    local = robot.base_rotation.T @ (goal - robot.base_position)
    rho = float(np.hypot(local[0], local[1]))
    x = robot.passive_state()
    if rho < 1e-9 or not robot.sections:
        return x
    kappa = 2.0 * rho / (rho ** 2 + local[2] ** 2)
    u = kappa * np.array([-local[1], local[0], 0.0]) / rho  # e3 x (direction of the goal)
    x[:3] = u
    k = len(robot.sections) - 1
    first, rank = robot.section_state_index[k], robot.section_ranks[k]
    if rank:
        x[first:first + rank] = robot.section_bases[k, :, :rank].T @ u
    return x


def _inside(lengths, limits):
    return bool(np.all(lengths >= limits[:, 0] - LIMIT_SLACK)
                and np.all(lengths <= limits[:, 1] + LIMIT_SLACK))
