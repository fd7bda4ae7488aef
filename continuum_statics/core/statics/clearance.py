"""Tip goals that keep the whole body clear of obstacles (doc/obstacles.md).

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

from continuum_statics.core.description.layout import MOMENT_AT, POSITION, ROTATION_AT
from continuum_statics.core.statics import bvp, contact

#: Nodes an RRT-connect search adds at most before the goal is refused.
MAX_TREE_NODES = 60
#: The finest step of a way's bisection (a fraction of the way): where the equilibria jump
#: (the solve switches branch), no finer step makes the body's motion small.
FINEST = 1.0 / 4096
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


def along_path(robot, start, goal, obstacles, tip_force, tip_moment, floor, clearance=0.0):
    """Return the closest approach on the equilibria from ``start`` to ``goal`` (both results).

    By bisection: a stretch of the way between two checked equilibria needs no check inside
    when its closer end clears the floor by the most any node moves across it (a gap changes
    no faster than the body moves, and a node's way is taken as at most twice its straight
    displacement); otherwise its middle is solved and both halves
    are judged the same way, down to stretches that move no node more than a quarter of the
    clearance (0.5 mm at the finest). The search stops at the first gap below ``floor``.
    """
    radius = robot.body_radius
    resolution = max(0.25 * clearance, 5e-4)

    def gap(shape):
        return float(np.min(contact.gaps(obstacles, radius, shape.positions, False)[0]))

    ends = [(0.0, start, gap(start)), (1.0, goal, gap(goal))]
    worst = min(ends[1:], key=lambda end: end[2])
    stack = [tuple(ends)]
    while stack and worst[2] >= floor:
        a, b = stack.pop()
        move = float(np.max(np.linalg.norm(b[1].positions - a[1].positions, axis=1)))
        if min(a[2], b[2]) - move >= floor or move <= resolution or b[0] - a[0] < FINEST:
            continue  # clear, fine enough, or a jump no finer step removes (a solve's branch)
        fraction = 0.5 * (a[0] + b[0])
        middle = robot.equilibrium_between(start, goal, fraction, tip_force, tip_moment,
                                           warm_start=a[1]).shape
        checked = (fraction, middle, gap(middle))
        worst = min(worst, checked, key=lambda end: end[2])
        stack += [(checked, b), (a, checked)]
    return closest(robot, worst[1], obstacles)  # between the nodes of the closest one


def connect(robot, start, goal, obstacles, tip_force, tip_moment, floor, clearance, seed=0):
    """Return equilibria from ``start`` to ``goal`` (shapes) whose way keeps clear, or None.

    A bidirectional rapidly-exploring random tree (RRT-connect, Kuffner & LaValle 2000) over
    the section moment coordinates of the solver state: each node an equilibrium (u(0)
    solved, :func:`bvp.solve_fixed_loads`) that clears, each edge the equilibria between two
    nodes (what the controller commands) checked by :func:`along_path`. The path found is
    shortened by skipping nodes whose neighbours see each other. For goals no straight or
    staged way reaches (under a shelf from above it).
    """
    rng = np.random.default_rng(seed)
    moments = slice(3, None)
    bound = 1.5 * max(float(np.max(np.abs(start.state[moments]), initial=0.0)),
                      float(np.max(np.abs(goal.state[moments]), initial=0.0)),
                      2.0 / robot.length)
    reach = 0.3 * bound  # the longest edge, in the moment coordinates (1/m)
    trees = ([start], [goal])
    parents = ({0: None}, {0: None})

    def clear(a, b):
        return along_path(robot, a, b, obstacles, tip_force, tip_moment, floor,
                          clearance).gap >= floor

    def node(q, near):
        x = np.concatenate([near.state[:3], q])
        state, converged = bvp.solve_fixed_loads(robot, x, None, tip_force, tip_moment)
        if not converged:
            return None
        shape = robot.make_shape(state, tip_force, robot.integrate_state(state, tip_force))
        lengths = robot.cable_lengths(shape)
        limits = robot.cable_length_limits
        if np.any(lengths < limits[:, 0]) or np.any(lengths > limits[:, 1]):
            return None
        return shape

    def extend(k, q):
        """Grow tree ``k`` one edge toward ``q``; the new node's index or None."""
        tree = trees[k]
        distances = [np.linalg.norm(n.state[moments] - q) for n in tree]
        nearest = int(np.argmin(distances))
        base = tree[nearest]
        step = q - base.state[moments]
        if distances[nearest] > reach:
            step *= reach / distances[nearest]
        new = node(base.state[moments] + step, base)
        if new is None or not clear(base, new):
            return None
        tree.append(new)
        parents[k][len(tree) - 1] = nearest
        return len(tree) - 1

    for _ in range(MAX_TREE_NODES):
        k = len(trees[0]) > len(trees[1])  # grow the smaller tree
        added = extend(int(k), rng.uniform(-bound, bound, len(start.state) - 3))
        if added is None:
            continue
        target = trees[int(k)][added].state[moments]
        other = extend(int(not k), target)  # and the other one toward the new node
        while other is not None:
            if np.linalg.norm(trees[int(not k)][other].state[moments] - target) < 1e-9:
                half = [_branch(trees[int(k)], parents[int(k)], added),
                        _branch(trees[int(not k)], parents[int(not k)], other)]
                if k:
                    half.reverse()
                path = half[0][::-1] + half[1][1:]
                return _shortened(path, clear)
            other = extend(int(not k), target)
    return None


def _branch(tree, parents, index):
    """Return the nodes from ``index`` up to the tree's root."""
    branch = []
    while index is not None:
        branch.append(tree[index])
        index = parents[index]
    return branch


def _shortened(path, clear):
    """Drop the nodes a path does not need (its neighbours see each other), ends kept."""
    kept, i = [path[0]], 0
    while i < len(path) - 1:
        j = len(path) - 1
        while j > i + 1 and not clear(path[i], path[j]):
            j -= 1
        kept.append(path[j])
        i = j
    return kept


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
        gaps = contact.gaps(self.obstacles, robot.body_radius, positions, False)[0]
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
        from scipy.optimize import minimize  # here: its import is ~0.5 s of a node's start

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

