"""Tip goals that keep the whole body clear of obstacles (ARCHITECTURE, "Obstacles and contact").

Among the equilibria whose tip is at the goal, the one whose section moments change least from
the start while every backbone node keeps ``clearance`` (plus the body radius) from every
obstacle: a small nonlinear program in the solver state x (u(0) and up to two moment coordinates
per section), solved by SLSQP. Its constraints are the goal (tip position, and direction when
given), the tip moment balance (every answer is an equilibrium, sec. III.E), the node gaps and
the cable length limits; their Jacobians are forward differences of one batched kernel call
(the IVPs of x and of x + h e_k). Redundancy (two and three sections) is what leaves room to
bend around an obstacle; a single section has none and refuses what it cannot do.

The controller moves along the equilibria between the start and the answer
(:meth:`Robot.equilibrium_between`), so that path is checked too, at every step a ramp would
command. When it passes too close, the goal is split into legs through intermediate tip goals
on the straight line to the goal, each solved with clearance and its path checked; the answer
carries them as ``waypoints``. A goal no such path reaches is refused with the place the body
would pass closest ("... 2.1 mm from obstacle 'shelf' at s = 0.210 m").
"""
import math

import numpy as np
from scipy.optimize import minimize

from continuum_statics.core.description.layout import MOMENT_AT, POSITION, ROTATION_AT
from continuum_statics.core.statics import contact

#: Steps along the start -> answer path at which clearance is checked (a ramp's resolution).
PATH_STEPS = 16
#: Legs a goal may be split into when the direct path passes too close.
MAX_LEGS = (2, 4)
#: Clearance slack (m) for round-off between nodes and the Hermite curve.
SLACK = 2e-6


class Clearance:
    """The closest approach of a body (or a path) to the obstacles.

    :ivar gap: m beyond the body radius (negative: inside)
    :ivar obstacle: name of the obstacle closest
    :ivar s: arc length of the closest point (m)
    """

    __slots__ = ('gap', 'obstacle', 's')

    def __init__(self, gap, obstacle, s):
        self.gap, self.obstacle, self.s = gap, obstacle, s

    def says(self, clearance):
        """Return the refusal's words: where the body would pass and how close."""
        return ('the body would pass %.1f mm from obstacle %r at s = %.3f m (clearance %.1f mm)'
                % (self.gap * 1e3, self.obstacle, self.s, clearance * 1e3))


def closest(robot, shape, obstacles):
    """Return the :class:`Clearance` of one shape (Hermite-refined between nodes)."""
    gap, index, s = contact.nearest(obstacles, robot.body_radius, shape)
    return Clearance(gap, obstacles[index].name, s)


def along_path(robot, start, goal, obstacles, tip_force, tip_moment, floor):
    """Return the closest approach on the equilibria from ``start`` to ``goal`` (both results).

    ``floor``: gaps at or above it stop the scan early (the path is clear enough).
    """
    worst, warm = None, start
    for k in range(1, PATH_STEPS + 1):
        step = robot.equilibrium_between(start, goal, k / PATH_STEPS, tip_force, tip_moment,
                                         warm_start=warm)
        warm = step
        here = closest(robot, step.shape, obstacles)
        if worst is None or here.gap < worst.gap:
            worst = here
        if worst.gap < floor:
            break
    return worst


def solve_clear(robot, goal, direction, tip_force, tip_moment, tolerance, start, guesses,
                obstacles, clearance):
    """Solver state of a goal kept clear, or None; see the module docstring.

    :param start: solver state the moments should change least from
    :param guesses: states to start SLSQP from, in order (the plain solution first)
    """
    problem = _Program(robot, goal, direction, tip_force, tip_moment, start, obstacles,
                       clearance)
    for guess in guesses:
        x = problem.solve(np.array(guess, dtype=float))
        for _ in range(2):  # nodes clear, the curve between them short: ask that much more
            if x is None:
                break
            tip_error, balance, gap = problem.judge(x)
            if tip_error > tolerance or balance > 1e-6:
                break
            if gap >= clearance - SLACK:
                return x
            problem.margin += clearance - gap + SLACK
            x = problem.solve(x)
        problem.margin = 0.0
    return None


class _Program:
    """The nonlinear program of one clear goal; evaluations are cached per state."""

    def __init__(self, robot, goal, direction, tip_force, tip_moment, start, obstacles,
                 clearance):
        self.robot, self.goal, self.obstacles = robot, goal, obstacles
        self.tip_force, self.tip_moment = tip_force, tip_moment
        self.reference = np.array(start, dtype=float)
        self.clearance = clearance
        self.margin = 0.0  # m asked of the nodes beyond the clearance
        self.fixed = np.zeros(len(robot.cable_names))
        self.step = robot.bending_step()
        self.scale = 1.0 / robot.length  # m -> the units of x's bending (1/m L)
        self.axes = None
        if direction is not None:  # two directions across the goal's: the tip axis' error
            helper = np.eye(3)[int(np.argmin(np.abs(direction)))]
            first = np.cross(direction, helper)
            first /= np.linalg.norm(first)
            self.axes = np.stack([first, np.cross(direction, first)])
        self._key, self._value = None, None

    def _evaluate(self, x):
        """Constraint rows (equalities, inequalities) at x and their Jacobians (cached)."""
        key = x.tobytes() + bytes(str(self.margin), 'ascii')
        if key == self._key:
            return self._value
        robot = self.robot
        n = len(x)
        batch = np.repeat(x[None], n + 1, axis=0)
        batch[1:] += self.step * np.eye(n)
        moments = np.empty((n + 1, len(robot.section_ranks), 3))
        tensions = np.empty((n + 1, len(robot.cable_names)))
        for b in range(n + 1):
            moments[b], tensions[b] = robot.loads(batch[b], self.fixed)
        forces = np.repeat(self.tip_force[None], n + 1, axis=0)
        states = robot.model.integrate(forces, np.ascontiguousarray(batch[:, :3]), moments,
                                       tensions)
        tip = states[:, -1]
        rows = [(tip[:, POSITION] - self.goal) * self.scale,
                (tip[:, MOMENT_AT:MOMENT_AT + 3] - self.tip_moment) * robot.length / robot.c[0]]
        if self.axes is not None:
            axis = tip[:, ROTATION_AT + 2:ROTATION_AT + 9:3]  # column 2 of R
            rows.append(axis @ self.axes.T)
        equal = np.concatenate(rows, axis=1)
        positions = states[:, :, POSITION].reshape(-1, 3)
        gaps, _ = contact.gaps(self.obstacles, robot.body_radius, positions)
        gaps = gaps.reshape(len(self.obstacles), n + 1, -1)[:, :, 1:]  # the base node is fixed
        clear = (np.moveaxis(gaps, 1, 0).reshape(n + 1, -1) - self.clearance - self.margin
                 - SLACK)
        lengths = robot.model.cable_lengths(states)
        limits = robot.cable_length_limits
        inside = np.concatenate([lengths - limits[:, 0], limits[:, 1] - lengths], axis=1)
        unequal = np.concatenate([clear, inside], axis=1) * self.scale
        self._key = key
        self._value = (equal[0], (equal[1:] - equal[0]).T / self.step, unequal[0],
                       (unequal[1:] - unequal[0]).T / self.step, states[0])
        return self._value

    def solve(self, x0):
        """Return the SLSQP solution from ``x0``, or None when it failed."""
        moments = slice(3, None)
        reference = self.reference

        def objective(x):
            change = x[moments] - reference[moments]
            return float(change @ change), np.concatenate([np.zeros(3), 2.0 * change])

        constraints = [
            {'type': 'eq', 'fun': lambda x: self._evaluate(x)[0],
             'jac': lambda x: self._evaluate(x)[1]},
            {'type': 'ineq', 'fun': lambda x: self._evaluate(x)[2],
             'jac': lambda x: self._evaluate(x)[3]},
        ]
        try:
            result = minimize(objective, x0, jac=True, method='SLSQP', constraints=constraints,
                              options={'maxiter': 100, 'ftol': 1e-12})
        except (ValueError, np.linalg.LinAlgError):
            return None
        return result.x if np.all(np.isfinite(result.x)) else None

    def judge(self, x):
        """Return (tip error m, balance, closest gap m) of state x, the gap Hermite-refined."""
        equal, _, _, _, states = self._evaluate(x)
        shape = self.robot.make_shape(x, self.tip_force, states.copy())
        tip_error = float(np.linalg.norm(equal[:3])) / self.scale
        balance = float(np.linalg.norm(equal[3:6]))
        gap = closest(self.robot, shape, self.obstacles).gap
        return tip_error, balance, gap if math.isfinite(gap) else -math.inf

