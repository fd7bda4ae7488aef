"""Slow, independent reference for displacement-driven statics with real (elastic) tendons.

The equilibrium of rod and frictionless cables when the motors hold cable lengths, solved in a
formulation of its own, for checking ``robot.solve_lengths`` (``core/statics/length_statics.py``):

- the unknowns are the cable tensions t (N), nothing else: the rod's boundary-value problem for
  given tensions is ``robot.solve_tensions`` (shooting on u(0)), the cable paths p(t) (m) are
  ``robot.cable_lengths`` of that shape (hole-to-hole spans, eq. 11 with the errata);
- the slack set is decided by an active-set iteration: for a guess of the taut set S, the taut
  equations p_j(t) = Lf_j (1 + t_j / EA_j) (j in S, t_j >= 0; t_j = 0 off S) are solved by
  bound-constrained least squares (``scipy.optimize.least_squares``, trf, t >= 0); a taut cable
  whose tension sits on its bound with a path shorter than its free length leaves S, a slack
  cable whose path has grown longer than its free length joins S; repeated until S settles;
- the answer is then checked against every condition of the contract on its own (taut: t >= 0,
  path = stretched length; slack: t = 0, path <= free length) and ``kkt_error`` says by how much
  it misses.

The free length follows the contract (docs, ``core/description/tendons.py``), computed here from
the tendon
parameters: a cable homed at the straight pose spans ``straight`` under its pretension, so
Lf = (length - straight) + straight / (1 + pretension / EA) + zero_offset, where ``straight``,
the straight-rod path of a cable, is the arc length of its end disk (its holes then lie on one
line parallel to the axis).

Frictionless only (uniform tension along each cable). Inextensible cables (EA = inf) are allowed,
but their tensions are not unique where a section has redundant taut cables: compare shapes there.
The BVP is solved to a tolerance 1000 times tighter than the robot file asks, so the reference is
not limited by the shooting tolerance of the code under test.
"""
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

#: Length tolerance (m): taut equations and the slack/taut decision.
PATH_TOLERANCE = 1e-12
#: Finite-difference step of the tension Jacobian, in units of E I / (L r).
FD_STEP = 1e-6


@dataclass
class ReferenceSolution:
    """Equilibrium found by :func:`solve_reference`.

    :ivar shape: backbone (``robot.solve_tensions`` at ``tensions``)
    :ivar tensions: (n,) N, uniform along each cable
    :ivar slack: (n,) bool, cables outside the taut set (t = 0)
    :ivar paths: (n,) m, hole-to-hole path of each cable in ``shape``
    :ivar free_lengths: (n,) m, unstretched lengths Lf
    :ivar kkt_error: (m) largest violation of the taut/slack conditions
    :ivar sweeps: active-set sweeps used
    :ivar evaluations: rod BVPs solved
    """

    shape: object
    tensions: np.ndarray
    slack: np.ndarray
    paths: np.ndarray
    free_lengths: np.ndarray
    kkt_error: float
    sweeps: int
    evaluations: int


def straight_lengths(robot):
    """Path (m) of every cable on the straight rod: the arc length of its end disk."""
    ends = np.zeros(len(robot.cable_names))
    for section in robot.sections:
        for j in section.cable_indices:
            ends[j] = section.end
    return ends


def tendon_parameters(robot):
    """(stiffness, pretension, zero_offset) arrays of the robot's cables."""
    tendons = robot.tendons
    return (np.array(tendons.stiffness, dtype=float), np.array(tendons.pretension, dtype=float),
            np.array(tendons.zero_offset, dtype=float))


def compliance_of(stiffness):
    """1 / EA, 0 for EA = inf."""
    stiffness = np.asarray(stiffness, dtype=float)
    return np.where(np.isinf(stiffness), 0.0, 1.0 / stiffness)


def free_lengths(robot, lengths):
    """Unstretched lengths Lf (m) of cables whose motors hold ``lengths`` (m)."""
    stiffness, pretension, zero_offset = tendon_parameters(robot)
    straight = straight_lengths(robot)
    homed = straight / (1.0 + pretension * compliance_of(stiffness))
    return (np.asarray(lengths, dtype=float) - straight) + homed + zero_offset


def motor_lengths(robot, tensions, paths):
    """Motor-side lengths (m) under which cables of ``tensions`` (N) span ``paths`` (m), taut.

    The inverse of :func:`free_lengths` for Lf = p / (1 + t / EA): how the tests build lengths
    from a known equilibrium.
    """
    stiffness, pretension, zero_offset = tendon_parameters(robot)
    compliance = compliance_of(stiffness)
    straight = straight_lengths(robot)
    free = np.asarray(paths, dtype=float) / (1.0 + np.asarray(tensions) * compliance)
    homed = straight / (1.0 + pretension * compliance)
    return free - homed + straight - zero_offset


class _Rod:
    """Cached shapes and paths of the rod for given tensions (one BVP per distinct t)."""

    def __init__(self, robot, tip_force, tip_moment):
        tolerance = robot.solver.bvp_tolerance * 1e-3
        self.robot = robot.with_solver(bvp_tolerance=tolerance, max_iterations=100)
        self.tip_force = np.asarray(tip_force, dtype=float)
        self.tip_moment = np.asarray(tip_moment, dtype=float)
        self.cache = {}
        self.last = None
        self.evaluations = 0

    def solve(self, tensions):
        tensions = np.maximum(np.asarray(tensions, dtype=float), 0.0)
        key = tensions.tobytes()
        if key not in self.cache:
            shape = self.robot.solve_tensions(tensions, self.tip_force, self.tip_moment,
                                              warm_start=self.last)
            self.evaluations += 1
            self.last = shape
            if len(self.cache) > 256:
                self.cache.clear()
            self.cache[key] = (shape, self.robot.cable_lengths(shape))
        return self.cache[key]


def solve_reference(robot, lengths, tip_force=(0.0, 0.0, 0.0), tip_moment=(0.0, 0.0, 0.0),
                    taut=None, tensions=None, max_sweeps=None):
    """Frictionless equilibrium for motor-held ``lengths`` (m), by tensions and an active set.

    ``taut`` (bool per cable) and ``tensions`` (N) may start the iteration (default: the cables
    that the unloaded rod already stretches, at zero tension). Raises ``RuntimeError`` when the
    active set does not settle.
    """
    n = len(robot.cable_names)
    stiffness, pretension, _ = tendon_parameters(robot)
    if np.any(robot.tendons.friction != 0.0):
        raise ValueError('the reference is frictionless')
    compliance = compliance_of(stiffness)
    free = free_lengths(robot, lengths)
    rod = _Rod(robot, tip_force, tip_moment)
    radius = float(np.mean(np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1])))
    t_scale = robot.c[0] / (robot.length * radius)  # N: the tension that bends by ~1 rad
    p_scale = 1e-3  # m: residuals in mm
    t = np.zeros(n) if tensions is None else np.maximum(np.asarray(tensions, dtype=float), 0.0)
    if taut is None:
        _, paths = rod.solve(t)
        taut = paths > free + PATH_TOLERANCE
        t = np.zeros(n) if tensions is None else t
    taut = np.array(taut, dtype=bool)
    t[~taut] = 0.0
    sweeps = 0
    for sweeps in range(1, (max_sweeps or 3 * n + 3) + 1):
        index = np.flatnonzero(taut)
        if index.size:
            def residual(x, index=index):
                trial = np.zeros(n)
                trial[index] = x * t_scale
                _, paths = rod.solve(trial)
                stretched = free[index] * (1.0 + trial[index] * compliance[index])
                return (paths[index] - stretched) / p_scale

            def jacobian(x, residual=residual):
                # forward differences with an absolute step (t >= 0 stays feasible)
                base = residual(x)
                columns = [(residual(x + step) - base) / FD_STEP
                           for step in np.eye(x.size) * FD_STEP]
                return np.array(columns).T

            fit = least_squares(residual, t[index] / t_scale, jac=jacobian,
                                bounds=(0.0, np.inf), method='trf', xtol=1e-15, ftol=1e-15,
                                gtol=1e-15, max_nfev=200)
            t = np.zeros(n)
            t[index] = fit.x * t_scale
        _, paths = rod.solve(t)
        stretched = free * (1.0 + t * compliance)
        # taut cable on its bound whose path is shorter than its free length: it goes slack
        drop = taut & (t <= 1e-12 * t_scale) & (paths < free - PATH_TOLERANCE)
        # slack cable whose path is longer than its free length: it must pull
        add = ~taut & (paths > free + PATH_TOLERANCE)
        if not drop.any() and not add.any():
            error = _kkt_error(t, paths, free, stretched, taut, t_scale)
            if error > 1e3 * PATH_TOLERANCE:
                raise RuntimeError('reference did not converge (KKT error %.3g m, taut %s, '
                                   'tensions %s)' % (error, taut.tolist(), t.tolist()))
            shape, paths = rod.solve(t)
            return ReferenceSolution(shape=shape, tensions=t, slack=~taut | (t <= 0.0),
                                     paths=paths, free_lengths=free, kkt_error=error,
                                     sweeps=sweeps, evaluations=rod.evaluations)
        taut = (taut & ~drop) | add
    raise RuntimeError('reference active set did not settle in %d sweeps' % sweeps)


def _kkt_error(t, paths, free, stretched, taut, t_scale):
    """Largest violation (m) of: t >= 0; taut p = Lf (1 + t / EA); slack t = 0, p <= Lf."""
    errors = [0.0]
    if np.any(taut):
        errors.append(np.max(np.abs(paths[taut] - stretched[taut])))
    if np.any(~taut):
        errors.append(np.max(np.maximum(paths[~taut] - free[~taut], 0.0)))
        errors.append(np.max(np.abs(t[~taut])) / t_scale * 1e-3)
    errors.append(np.max(np.maximum(-t, 0.0)) / t_scale * 1e-3)
    return float(max(errors))
