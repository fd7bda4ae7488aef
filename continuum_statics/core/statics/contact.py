"""Contact statics: the rod pressed on rigid, frictionless obstacles.

A contact c is a point force ``f_c n_c`` where the backbone's gap to an obstacle,
g(s) = d(r(s)) - rho (the obstacle's signed distance minus the body radius rho), has a local
minimum s_c; n_c is the obstacle's outward normal there. Signorini's conditions (frictionless
unilateral contact): f_c >= 0, g(s_c) >= 0, f_c g(s_c) = 0.

In the rod's equations a point force is a jump of the internal force n at s_c (eq. 3 with a
Dirac load; m stays continuous). It is split between the two integration nodes that bracket
s_c in proportion to their distance (the lever rule: the same resultant, the moment off by
O(kappa h^2) of the step h) and the kernel carries it as it carries the guide disks' weights
(:meth:`Robot.with_node_forces`), so every solver of the package (tensions, lengths, the
estimator) solves with contact unchanged. The magnitudes solve G(f) = g(s_c(f)) = 0 on the set of
active contacts by Newton's method with a finite-difference Jacobian (one solve per contact),
projected onto f >= 0: a contact whose force would turn negative lets go, and a new local
minimum of the gap below zero joins the set. The gap between nodes is that of the cubic Hermite
curve through the nodes' positions and tangents (error O(h^4)), so contacts are not tied to the
grid.

Not modelled: friction at the contact, the contact's moment (the body's radius is a clearance,
not a lever arm), obstacles that move or deform.
"""
from dataclasses import dataclass
import math

import numpy as np

from continuum_statics.core.description.layout import POSITION, ROTATION, STRETCH

#: Gap (m) within which an active contact counts as touching (and a free one as not inside):
#: a thousandth of the 0.1 mm the model is checked to, and of what a tracker sees.
GAP_TOLERANCE = 1e-7
#: A contact force is along its normal within this angle (rad): frictionless.
DIRECTION = 1e-6
#: Newton iterations on the contact forces at most.
MAX_ITERATIONS = 40
#: Contacts one solve may hold at most (a body lying along a plane needs a few).
MAX_CONTACTS = 24
#: Finite-difference step on a contact force, relative to the rod's load scale E I / L^2.
FORCE_STEP = 1e-5
#: A contact's point (relative to L) and normal settled when they move less than this.
MOVED = 1e-7
#: Steps from the robot at rest when a solve from the warm start lands deep in an obstacle
#: (smaller where a step fails, all tries at most MAX_STAGES).
STAGES, MAX_STAGES = 8, 48
#: Samples of the Hermite curve per interval when a gap minimum is located.
SAMPLES = 8


@dataclass(frozen=True, eq=False)
class Contact:
    """Where the body touches an obstacle and how hard (base frame, SI units).

    :ivar obstacle: the obstacle's name
    :ivar s: arc length along the backbone (m)
    :ivar point: (3,) the touching point on the obstacle's surface (m)
    :ivar normal: (3,) unit, from the obstacle towards the body (the force's direction)
    :ivar force: magnitude of the force on the body (N, >= 0)
    """

    obstacle: str
    s: float
    point: np.ndarray
    normal: np.ndarray
    force: float


class ContactError(RuntimeError):
    """The contact forces did not reach complementarity (the message says how far)."""


@dataclass
class _Active:
    obstacle: int
    s: float  # where its force is applied (m)
    vector: np.ndarray  # the force on the body (3,) N
    gap: float = 0.0
    point: np.ndarray = None
    normal: np.ndarray = None

    @property
    def force(self):
        return float(self.vector @ self.normal)


def shape_of(result):
    """Return the :class:`Shape` of a solver's result (a shape, a solution or an estimate)."""
    return getattr(result, 'shape', result)


def solve_in_contact(robot, obstacles, radius, solve, warm_start=None, scaled=None):
    """Solve with the contact forces the obstacles put on the body.

    Each contact's force is a vector v (3 unknowns); its equations are the gap at its point
    (= 0) and v's two components across the normal there (= 0: frictionless), so Newton's
    method sees how the normal turns with the shape (a rod sliding round a sphere) instead of
    a fixed point on the direction. A contact whose force would pull lets go (v = 0). The
    Jacobian (one solve per force component) is kept while the steps converge (chord steps,
    one solve each) and handed to the next call with the contacts (a warm start's).

    A body whose contact-free shape lies deep in an obstacle (its centreline inside) has no
    side to be pushed out of: a real one came onto it from outside. Then, and when Newton's
    method fails, the inputs are applied in :data:`STAGES` steps from the robot at rest
    (``scaled``), each step's contacts starting the next (a quarter of the step where one
    fails: a contact sliding off an edge), so the body comes onto the obstacle from the side
    it starts on.

    :param solve: ``solve(robot_like, warm_start) -> result`` the contact-free solver (a result
        with a ``shape``, or a shape), called on copies of ``robot`` with contact forces
    :param obstacles: obstacles in the base frame; ``radius`` the body radius (m)
    :param warm_start: a previous result: its shape's contacts start the forces
    :param scaled: ``scaled(fraction)``: ``solve`` with its inputs that fraction of the way
        from the robot at rest (no cable and no tip load), or None (no staging)
    :returns: the result whose shape holds ``contacts`` (a tuple of :class:`Contact`)
    :raises ContactError: no complementary set of forces within the iteration limit (its
        ``free`` is the contact-free result)
    """
    try:
        return _solve_contacts(robot, obstacles, radius, solve, warm_start, scaled is not None)
    except ContactError as error:
        if scaled is None or getattr(error, 'pinned', False):
            raise
        failed = error
    staged, done, step, tries = None, 0.0, 1.0 / STAGES, 0
    while done < 1.0:
        fraction = min(1.0, done + step)
        tries += 1
        try:
            staged = _solve_contacts(robot, obstacles, radius, scaled(fraction), staged, False)
        except ContactError:
            if tries >= MAX_STAGES:
                raise failed from None
            step *= 0.25  # a contact slid off an edge or round a corner: smaller steps there
            continue
        done, step = fraction, min(2.0 * step, 1.0 / STAGES)
    return staged


def _solve_contacts(robot, obstacles, radius, solve, warm_start, refuse_deep):
    """Newton's method of :func:`solve_in_contact` from ``warm_start`` (no staging)."""
    names = [obstacle.name for obstacle in obstacles]
    warm = getattr(shape_of(warm_start), 'contacts', ())
    active = [_Active(names.index(c.obstacle), c.s, c.force * np.asarray(c.normal))
              for c in warm if c.obstacle in names]
    jacobian = getattr(warm, 'jacobian', None) if len(active) == len(warm) else None
    # from the warm start's contacts straight away; the contact-free result only without
    free = None if active else solve(robot, warm_start)
    result = solve(_loaded(robot, active), warm_start) if active else free
    table = None  # the free shape's gaps, scanned once
    if free is not None:
        table = gaps(obstacles, radius, shape_of(free).positions, False)[0]
        if refuse_deep and float(np.min(table)) < -radius:
            error = ContactError('the contact-free shape lies deep inside an obstacle')
            error.free = free
            raise error
    scale = FORCE_STEP * robot.c[0] / robot.length ** 2
    last, taken = math.inf, None  # the gaps' size, the last (residual, step) for Broyden
    for _ in range(MAX_ITERATIONS):
        shape = shape_of(result)
        moved = {}
        for contact in active:  # follow each contact's gap minimum as the shape moves
            applied = contact.s
            _measure(contact, obstacles, radius, shape, _refined_minimum(
                obstacles[contact.obstacle], radius, shape, contact.s, 1e-3 * robot.length))
            moved[id(contact)] = abs(contact.s - applied) / robot.length
        kept = [c for c in active if c.force > 0.0 or c.gap < -GAP_TOLERANCE]
        released = len(kept) < len(active)
        moved = max((moved[id(c)] for c in kept), default=0.0)
        fresh = _penetrations(obstacles, radius, shape, kept,
                              table if result is free else None)
        if not fresh and moved <= MOVED and all(_settled(c, scale) for c in kept):
            if released:  # the shape still carries the force of a contact that let go
                active, jacobian = kept, None
                result = solve(_loaded(robot, active), result)
                continue
            return _with_contacts(result, obstacles, kept, jacobian)  # forces where reported
        if not kept and not fresh:  # every contact let go: the shape without them
            active, jacobian = [], None
            result = solve(_loaded(robot, active), result)
            continue
        if fresh or len(kept) != len(active):
            jacobian = taken = None  # another set of contacts
        active = kept + fresh[:max(0, MAX_CONTACTS - len(kept))]
        bases = [_across(c.normal) for c in active]
        residual = np.concatenate([_residual(c, c.gap, c.normal, t) for c, t in
                                   zip(active, bases)])
        size = float(np.linalg.norm(residual[::3])) / robot.length  # the gaps, relative
        if jacobian is not None and taken is not None:  # Broyden's update of the last step
            change = residual - taken[0] - jacobian @ taken[1]
            jacobian = jacobian + np.outer(change, taken[1]) / float(taken[1] @ taken[1])
        if jacobian is None or (size > last and size * robot.length > 100.0 * GAP_TOLERANCE):
            # no Jacobian for these contacts, or the updated one diverged: a fresh one
            if moved > MOVED:  # the nominal of this loading, the forces at their points
                result = solve(_loaded(robot, active), result)
                shape = shape_of(result)
                for contact in active:
                    _measure(contact, obstacles, radius, shape, contact.s)
                residual = np.concatenate([_residual(c, c.gap, c.normal, t) for c, t in
                                           zip(active, bases)])
            jacobian = _jacobian(robot, obstacles, radius, solve, active, bases, residual,
                                 result, scale)
            taken = None
            pinned = [names[c.obstacle] for k, c in enumerate(active) if np.linalg.norm(
                jacobian[3 * k]) * robot.c[0] < 1e-9 * robot.length ** 3]
            if pinned:  # no force there moves the body: what is given fixes the shape
                error = ContactError('no contact force moves the body at %s: the inputs fix '
                                     'the shape there (gap %.3g mm)' % (pinned, 1e3 * max(
                                         abs(c.gap) for c in active)))
                error.pinned = True  # staging cannot change that
                error.free = free if free is not None else solve(robot, warm_start)
                raise error
        last = size
        try:
            step = np.linalg.solve(jacobian, -residual)
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(jacobian, -residual, rcond=None)[0]
        before = np.concatenate([c.vector for c in active])
        for k, contact in enumerate(active):
            contact.vector = contact.vector + step[3 * k:3 * k + 3]
            if contact.vector @ contact.normal <= 0.0:
                contact.vector = np.zeros(3)  # a frictionless contact cannot pull: it lets go
        taken = (residual, np.concatenate([c.vector for c in active]) - before)
        if not np.any(taken[1]):
            taken = None
        result = solve(_loaded(robot, active), result)
    worst = max((abs(c.gap) for c in active), default=0.0)
    error = ContactError('contact forces on %s did not converge in %d iterations (gap %.3g m '
                         'off, tolerance %g m)' % (sorted({names[c.obstacle] for c in active}),
                                                   MAX_ITERATIONS, worst, GAP_TOLERANCE))
    error.free = free if free is not None else solve(robot, warm_start)
    raise error


def _jacobian(robot, obstacles, radius, solve, active, bases, residual, result, scale):
    """Return d residual / d v at fixed points, one solve per force component.

    A gap minimum's point moves the gap to second order only, so fixed points suffice.
    """
    jacobian = np.empty((len(residual), len(residual)))
    for k, contact in enumerate(active):
        for axis in range(3):
            contact.vector[axis] += scale
            pushed = shape_of(solve(_loaded(robot, active), result))
            column = [_residual(other, *_gap_at(obstacles[other.obstacle], radius, pushed,
                                                other.s)[::2], t)
                      for other, t in zip(active, bases)]
            contact.vector[axis] -= scale
            jacobian[:, 3 * k + axis] = (np.concatenate(column) - residual) / scale
    return jacobian


def _across(normal):
    """Return two unit vectors (2, 3) across the unit ``normal``."""
    x, y, z = normal
    if abs(x) < 0.9:  # normal x e1, then normal x that
        first = np.array([0.0, z, -y]) / math.hypot(y, z)
    else:  # normal x e2
        first = np.array([-z, 0.0, x]) / math.hypot(x, z)
    a, b, c = first
    return np.array([first, (y * c - z * b, z * a - x * c, x * b - y * a)])


def _residual(contact, gap, normal, across):
    """Return [gap (m); v across the normal (N), in the basis ``across``] of one contact."""
    tangential = contact.vector - (contact.vector @ normal) * normal
    return np.concatenate([[gap], across @ tangential])


def _settled(contact, scale):
    tangential = contact.vector - contact.force * contact.normal
    return (abs(contact.gap) <= GAP_TOLERANCE
            and float(np.linalg.norm(tangential)) <= DIRECTION * max(
                float(np.linalg.norm(contact.vector)), scale))


def gaps(obstacles, radius, positions, normals=True):
    """Gaps (n_obstacles, n) of points to each obstacle (m) and their normals (.., 3).

    ``normals=False``: the gaps only (normals None).
    """
    table = [obstacle.distance(positions, normals) for obstacle in obstacles]
    return (np.array([d for d, _ in table]) - radius,
            np.array([n for _, n in table]) if normals else None)


def nearest(obstacles, radius, shape):
    """(gap m, obstacle index, s m) of the backbone's point nearest any obstacle.

    Located between nodes on the Hermite curve, as contacts are.
    """
    table = gaps(obstacles, radius, shape.positions, False)[0]
    k, node = np.unravel_index(np.argmin(table), table.shape)
    s = _refined_minimum(obstacles[k], radius, shape, shape.s[node])
    return _gap_at(obstacles[k], radius, shape, s)[0], int(k), s


def _loaded(robot, active):
    """Return a copy of ``robot`` carrying the active contacts' forces at their nodes."""
    forces = np.zeros((len(robot.s_grid), 3))
    s_grid = robot.s_grid
    for contact in active:
        k = min(max(int(np.searchsorted(s_grid, contact.s)) - 1, 0), len(s_grid) - 2)
        t = (contact.s - s_grid[k]) / (s_grid[k + 1] - s_grid[k])
        forces[k] += (1.0 - t) * contact.vector
        forces[k + 1] += t * contact.vector
    return robot.with_node_forces(forces)


def _measure(contact, obstacles, radius, shape, s):
    contact.s = s
    contact.gap, contact.point, contact.normal = _gap_at(obstacles[contact.obstacle], radius,
                                                         shape, s)


def _penetrations(obstacles, radius, shape, active, table=None):
    """Return new contacts: gap minima below -tolerance away from the active contacts.

    ``table``: the shape's node gaps when already known.
    """
    if table is None:
        table = gaps(obstacles, radius, shape.positions, False)[0]
    if not active and float(np.min(table)) >= -GAP_TOLERANCE:
        return []  # nothing inside anything: the usual case, one comparison
    s_grid = shape.s
    fresh = []
    for k, row in enumerate(table):
        inside = np.nonzero(row < -GAP_TOLERANCE)[0]
        for node in inside[inside > 0]:
            if row[node] > row[node - 1] or (node + 1 < len(row) and row[node] > row[node + 1]):
                continue  # not a local minimum
            s = _refined_minimum(obstacles[k], radius, shape, s_grid[node])
            near = [c for c in active + fresh if c.obstacle == k
                    and abs(c.s - s) <= 2.0 * (s_grid[1] - s_grid[0]) + 1e-12]
            if near:
                continue
            contact = _Active(k, s, np.zeros(3))
            _measure(contact, obstacles, radius, shape, s)
            fresh.append(contact)
    return sorted(fresh, key=lambda c: c.gap)


def _curve(shape, s):
    """Backbone point at arc lengths ``s`` (m): the cubic Hermite of the nodes and tangents."""
    s_grid, states = shape.s, shape.states
    s = np.atleast_1d(s)
    k = np.minimum(np.maximum(np.searchsorted(s_grid, s) - 1, 0), len(s_grid) - 2)
    h = (s_grid[k + 1] - s_grid[k])[:, None]
    t = (s[:, None] - s_grid[k][:, None]) / h
    ends = np.concatenate([k, k + 1])
    rows = states[ends]
    # r' = R v (eq. 1) at the interval's two nodes: R row-major, v = (v - e3) + e3
    rotation = rows[:, ROTATION].reshape(-1, 3, 3)
    stretch = rows[:, STRETCH] + (0.0, 0.0, 1.0)
    tangents = (rotation @ stretch[:, :, None])[:, :, 0]
    count = len(s)
    m0, m1 = tangents[:count] * h, tangents[count:] * h
    p0, p1 = rows[:count, POSITION], rows[count:, POSITION]
    t2 = t * t
    t3 = t2 * t
    return ((2 * t3 - 3 * t2 + 1) * p0 + (t3 - 2 * t2 + t) * m0 + (3 * t2 - 2 * t3) * p1
            + (t3 - t2) * m1)


def _gap_at(obstacle, radius, shape, s):
    """(gap m, touching point on the surface, normal) at arc length ``s``."""
    point = _curve(shape, s)
    distance, normal = obstacle.distance(point)
    return float(distance[0] - radius), point[0] - (distance[0]) * normal[0], normal[0]


def _refined_minimum(obstacle, radius, shape, s, width=None):
    """Arc length (m) of the gap's local minimum nearest ``s`` on the Hermite curve.

    Nine samples across ``width`` (m) each side (default one interval), then the vertex of the
    parabola through the best three, again round it on a bracket a sixteenth as wide, until
    the bracket is a thousandth of the rod or the vertex stays put (the gap is smooth, a
    parabola to round-off that close to its minimum); a minimum at the bracket's edge slides
    the bracket (a contact sliding along).
    """
    s_grid = shape.s
    length = s_grid[-1]
    if width is None:
        node = min(int(np.searchsorted(s_grid, s)), len(s_grid) - 1)
        width = s_grid[node] - s_grid[max(node - 1, 0)] or s_grid[1]
    vertex = math.inf
    for _ in range(16):
        grid = np.clip(np.linspace(s - width, s + width, 9), 0.0, length)
        values = obstacle.distance(_curve(shape, grid))[0]
        best = int(np.argmin(values))
        if best in (0, 8):
            if grid[best] in (0.0, length):
                return float(grid[best])  # at the rod's end
            s = float(grid[best])  # past the bracket: slide it there
            continue
        (x0, x1, x2), (a, b, c) = grid[best - 1:best + 2], values[best - 1:best + 2]
        # vertex of the parabola through three points (spacing uneven only when clipped)
        top = (x1 - x0) ** 2 * (b - c) - (x1 - x2) ** 2 * (b - a)
        bottom = (x1 - x0) * (b - c) - (x1 - x2) * (b - a)
        new = float(x1 - 0.5 * top / bottom) if bottom != 0.0 else float(x1)
        new = min(max(new, x0), x2)
        if abs(new - vertex) <= 1e-8 * length or width <= 1e-3 * length:
            return new  # on a bracket this narrow the gap is a parabola to round-off
        s, vertex, width = new, new, width / 16.0
    return float(s)


class Contacts(tuple):
    """A shape's contacts (a tuple of :class:`Contact`) and the solve's Jacobian.

    The Jacobian is kept for the next call that starts from these contacts.
    """

    jacobian = None


def _with_contacts(result, obstacles, active, jacobian):
    shape = shape_of(result)
    touching = [c for c in active if c.force > 0.0]
    contacts = Contacts(Contact(obstacles[c.obstacle].name, c.s, c.point, c.normal, c.force)
                        for c in touching)
    if len(touching) == len(active):  # the Jacobian's columns are these contacts'
        contacts.jacobian = jacobian
    shape.contacts = contacts
    return result
