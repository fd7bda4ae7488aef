"""Tip-load estimation: the wrench on the tip that best explains what the robot measures (no ROS).

Intrinsic force sensing (Xu & Simaan: the wrench from actuation forces and the statics model)
and deflection-based sensing (Rucker & Webster 2011: the wrench whose deflection matches a
measured tip, with a probabilistic estimator) are one weighted least-squares problem here.
Unknowns: the tip wrench w = [force (N); moment (N m)], base frame, through a load model
(``load=``), a linear map w = B p of a few parameters p (:func:`load_model`): ``'force'`` (p the
force, 3 unknowns, the default), ``'wrench'`` (6, also ``moment=True``), ``('direction', d)`` (1:
the force's magnitude in N along the unit vector d) and ``'weight'`` (1: a payload's mass m in
kg, w = m g with g the robot file's gravity, the same vector that weighs the rod; Rucker &
Webster 2011 estimate a tip load from its deflection the same way, and a hanging mass is what
their experiment and Jones et al.'s Table II apply).
Measurements y, each optional: motor tensions, cable lengths, tip position (the robot file's
tracked point, ``tip_marker`` in the tip frame), tip orientation. A forward model driven by the
measurements the statics take as inputs predicts the others:

============================  ==========================  ======================
measured                      forward model                predicts
============================  ==========================  ======================
lengths, real tendons         ``solve_lengths(L, w)``      tensions, tip
tensions                      ``solve_tensions(T, w)``     cable paths, tip
lengths, ideal cables         ``estimate_shape(L, w)``     tip
neither                       ``solve_bvp(w)``             tip
============================  ==========================  ======================

The noise of the inputs reaches the predictions through the model, so the residual e = f(u, w)
- y has covariance C = R_y + J_u R_u J_u^T (u: the inputs, J_u = df/du). With a zero-mean
Gaussian prior P on p (standard deviation: the largest plausible tip load, see
:func:`plausible_tip_load`; for a mass, that force over ``|g|``) the estimate minimises
e^T C^-1 e + p^T P^-1 p by Gauss-Newton (Levenberg-Marquardt), and its covariance is
Cov_p = (J_p^T C^-1 J_p + P^-1)^-1 with J_p = J_w B (the maximum a posteriori estimate and its
Laplace covariance, as in Rucker & Webster's deflection-based estimator); the wrench's is
B Cov_p B^T. The prior is what keeps a direction the measurements cannot see at zero with a
large variance instead of a made-up value; those directions are named in the message, and so
is a seen direction whose standard deviation exceeds :data:`POORLY_SEEN` of the estimate. J_p
(one forward solve per column of B) and J_u are forward differences of the solvers, each
warm-started from the nominal solve.

Friction acts against each cable's last direction of motion, which the estimate carries; a
cable that came back from the furthest point of its motion by less than the encoders' noise
deadband may or may not have turned its friction (:func:`_possible_turns`). The hypotheses
(none turned, all of them, each one alone) are weighed by likelihood and the estimate is their
mixture (moments matched): one of them when the tensions tell them apart, a wide covariance
when they do not.
"""
import copy
import dataclasses
from dataclasses import dataclass, field
import math

import numpy as np

from continuum_statics.core.description.inputs import as_vector
from continuum_statics.core.estimation import gates
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.statics.bvp import ConvergenceError
from continuum_statics.core.statics.length_statics import MOTION_THRESHOLD, turned_state

#: A friction turn whose best explanation is this much less likely (-2 log of the likelihood
#: ratio: 1e-6) than keeping the friction is left out; this much likelier, it is fitted to the
#: end and carried on (:func:`_turned_step`).
TURN_MARGIN = 2.0 * math.log(1e6)
#: Default measurement standard deviations (``noise`` keys): length m (encoder and spool),
#: tension N (a load cell or motor current; a string 'P%' is P percent of each reading), tip
#: position m (an optical tracker), tip angle rad.
DEFAULT_NOISE = {'length': 20e-6, 'tension': 0.05, 'tip_position': 0.5e-3, 'tip_angle': 0.01}
#: Levenberg-Marquardt iterations per estimate (a warm one needs one or two; a cold one far
#: from zero up to ~20 at STEP_LIMIT each).
MAX_ITERATIONS = 25
#: Refresh the residual's weights once the load moved by this fraction of its prior scale...
REWEIGH = 0.1
#: ... or an input by this many of its difference steps (3e-3 L of cable, 3e-2 E I / (L r)).
REWEIGH_INPUT = 3000.0
#: The load Jacobian is refreshed once the load moved by this fraction of the prior scale
#: (a tenth of E I / L^2: the bend, and with it what couples to what, has changed).
REJACOBIAN = 0.01
#: Largest step, as a fraction of the prior scale (0.1: E I / L^2 of force).
STEP_LIMIT = 0.1
#: Converged when an iteration lowers the objective (a chi-square) by less than this.
OBJECTIVE_TOLERANCE = 1e-4
#: Levenberg damping at the start, relative to the largest curvature: cold, warm.
COLD_DAMPING, WARM_DAMPING = 1e-3, 1e-9
#: Converged when the next Gauss-Newton step would be below this many standard deviations.
STEP_TOLERANCE = 0.05
#: Forward-difference steps relative to the load scales E I / L^2 (N) and E I / L (N m).
LOAD_STEP = 1e-5
#: Length (relative to L) and tension (relative to E I / (L r)) steps of the input sensitivities.
LENGTH_STEP, TENSION_STEP = 1e-6, 1e-5
#: The smallest tension standard deviation (N) of a 'P%' noise figure (a zero reading).
MIN_TENSION_NOISE = 1e-3
#: A seen direction of the estimated force (or moment) is named as poorly seen when its standard
#: deviation exceeds this fraction of the estimate's magnitude: worse than the accuracy force
#: sensing publishes, 5-15 % of the magnitude (Xiao & Chen 2021, FBG; Eyberg et al. 2026, 14 %).
#: Only while the estimate stands clear of zero (a load at all, not noise about none): its
#: chi-square distance from zero beyond the THREE_SIGMA quantile.
POORLY_SEEN = 0.2
#: The load models of ``load=`` (:func:`load_model`).
LOAD_MODELS = ('weight', 'force', 'direction', 'wrench')


class _ForwardFailed(Exception):
    """The forward solve found no equilibrium for these loads."""


def plausible_tip_load(robot):
    """Return (force N, moment N m): the largest plausible tip load of the rod.

    10 E I / L^2 bends a cantilever far beyond 90 degrees; 2 pi E I / L curls it into a full
    circle. Larger loads are bad input; the estimator's prior has these standard deviations.
    """
    stiffness, length = float(robot.c[0]), float(robot.length)
    return 10.0 * stiffness / length ** 2, 2.0 * math.pi * stiffness / length


@dataclass(frozen=True, eq=False)
class LoadModel:
    """A load model: the tip wrench w (6,) = ``basis`` @ p of the parameters p (k,).

    :ivar name: 'weight', 'force', 'direction' or 'wrench'
    :ivar basis: B (6, k)
    :ivar prior: (k,) standard deviations of the zero-mean prior on p, in p's units
    :ivar steps: (k,) forward-difference steps of p
    :ivar size: rows of the wrench the estimate reports (3: the force; 6: force and moment)
    """

    name: str
    basis: np.ndarray
    prior: np.ndarray
    steps: np.ndarray
    size: int

    def same(self, other):
        """Return True if ``other`` has the same parameters (a warm start's p carries over)."""
        return isinstance(other, LoadModel) and other.basis.shape == self.basis.shape and \
            bool(np.array_equal(other.basis, self.basis))


def load_model(robot, load=None, moment=False, prior=None):
    """Return the :class:`LoadModel` of ``load`` (see the module docstring); checked.

    ``load``: 'weight' | 'force' | ('direction', (dx, dy, dz)) | 'wrench' (None: 'force', or
    'wrench' with ``moment=True``). ``prior``: the prior's standard deviation(s) in the model's
    units (kg for 'weight', N for a force, N m for a moment; a number or one per parameter;
    None: :func:`plausible_tip_load`, for a mass that force over ``|g|``).
    """
    if moment and load not in (None, 'wrench'):
        raise ValueError("moment=True is load='wrench'; it cannot go with load=%r" % (load,))
    load = ('wrench' if moment else 'force') if load is None else load
    force_scale, moment_scale = plausible_tip_load(robot)
    zero = np.zeros(3)
    if isinstance(load, str) and load == 'force':
        basis, scale = np.vstack([np.eye(3), np.zeros((3, 3))]), np.full(3, force_scale)
        name, size = 'force', 3
    elif isinstance(load, str) and load == 'wrench':
        basis, scale = np.eye(6), np.concatenate([np.full(3, force_scale),
                                                  np.full(3, moment_scale)])
        name, size = 'wrench', 6
    elif isinstance(load, str) and load == 'weight':
        gravity = np.asarray(robot.gravity, dtype=float)
        magnitude = float(np.linalg.norm(gravity))
        if not magnitude > 0.0:
            raise ValueError("load='weight' needs gravity, but robot %r has gravity %s in its "
                             "file: give the file's gravity (m/s^2, base frame) or estimate "
                             "load='force'" % (robot.name, np.round(gravity, 6).tolist()))
        basis = np.concatenate([gravity, zero])[:, None]
        scale, name, size = np.array([force_scale / magnitude]), 'weight', 3
    elif isinstance(load, (tuple, list)) and len(load) == 2 and load[0] == 'direction':
        try:
            direction = np.asarray(load[1], dtype=float).reshape(3)
        except (TypeError, ValueError):
            raise ValueError("load=('direction', d): d must be 3 numbers (dx, dy, dz), got %r"
                             % (load[1],)) from None
        norm = float(np.linalg.norm(direction))
        if not (np.all(np.isfinite(direction)) and norm > 0.0):
            raise ValueError("load=('direction', d): d must be a finite, non-zero vector "
                             "(dx, dy, dz), got %s" % direction.tolist())
        basis = np.concatenate([direction / norm, zero])[:, None]
        scale, name, size = np.array([force_scale]), 'direction', 3
    else:
        raise ValueError("load must be 'weight', 'force', ('direction', (dx, dy, dz)) or "
                         "'wrench', got %r" % (load,))
    if prior is not None:
        values = np.asarray(prior, dtype=float).reshape(-1)
        if values.size == 1:
            values = np.full(len(scale), float(values[0]))
        if values.size != len(scale) or not np.all(np.isfinite(values)) or \
                not np.all(values > 0.0):
            raise ValueError('load_prior for load %r must be one or %d finite standard '
                             'deviation(s) > 0, got %r' % (name, len(scale), prior))
        scale = values
    # the difference steps move the wrench by LOAD_STEP of its scale (E I / L^2 of force,
    # E I / L of moment), whatever p's units: a column b of B moves it by its norm per unit of p
    wrench_scale = np.concatenate([np.full(3, force_scale), np.full(3, moment_scale)])
    steps = LOAD_STEP * np.array([1.0 / np.linalg.norm(column / wrench_scale)
                                  for column in basis.T])
    return LoadModel(name, basis, scale, steps, size)


@dataclass(frozen=True, eq=False)
class WrenchEstimate:
    """Result of :func:`estimate_tip_wrench` (base frame).

    :ivar force: (3,) N
    :ivar moment: (3,) N m (zeros unless estimated)
    :ivar covariance: (3, 3) N^2, or (6, 6) [force; moment] with the moment
    :ivar shape: the backbone under that load
    :ivar converged: Gauss-Newton converged and every forward solve found an equilibrium
    :ivar message: directions the measurements do not determine, and what limited the estimate
    :ivar unseen: (k, 3 or 6) unit directions of w the measurements do not determine
    :ivar iterations: Gauss-Newton iterations
    :ivar chi2: weighted squared residual per measurement (about 1 when the noise is right)
    :ivar solution: the forward solve's result (warm-starts the next estimate's solves)
    :ivar load: the :class:`LoadModel` estimated
    :ivar parameters: (k,) its parameters p (w = B p): N, N m, or kg for 'weight'
    :ivar parameter_covariance: (k, k) of p
    :ivar mass: kg, the payload's mass with ``load='weight'`` (else None)
    :ivar mass_sigma: kg, its standard deviation (else None)
    """

    force: np.ndarray
    moment: np.ndarray
    covariance: np.ndarray
    shape: Shape
    converged: bool
    message: str
    unseen: np.ndarray
    iterations: int
    chi2: float
    solution: object = None
    weights: object = None  # the residual's whitener, reused by the next warm estimate
    measurements: int = 0  # how many scalar measurements chi2 is the mean over
    friction_reference: object = None  # free lengths (m) where each cable last moved
    friction_peak: object = None  # free lengths (m) furthest along each cable's motion since
    fitted: object = None  # the p that ``solution`` and ``weights`` belong to (a warm start's)
    load: object = None
    parameters: object = None
    parameter_covariance: object = None
    mass: object = None
    mass_sigma: object = None

    @property
    def dof(self):
        """Degrees of freedom of the residual: measurements less the seen load directions."""
        unknowns = len(self.covariance if self.parameter_covariance is None
                       else self.parameter_covariance)
        return self.measurements - (unknowns - len(self.unseen))

    def explains(self, probability=gates.LOAD_GATE_PROBABILITY):
        """Return True if the measurements pass the chi-square gate.

        The weighted squared residual against the gate of (measurements - seen load directions)
        degrees of freedom (:mod:`~continuum_statics.core.estimation.gates`).
        """
        if not np.isfinite(self.chi2):
            return False
        return gates.passes(self.chi2 * self.measurements, self.dof, probability)

    @property
    def sigma(self):
        """Standard deviations of [force (N); moment (N m)] (3 or 6,)."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def wrench(self):
        """(6,) [force; moment]."""
        return np.concatenate([self.force, self.moment])

    @property
    def state(self):
        """Solver state of the shape (warm starts)."""
        return self.shape.state


def noise_levels(noise):
    """Merge ``noise`` (a mapping of :data:`DEFAULT_NOISE` keys) with the defaults; checked."""
    levels = dict(DEFAULT_NOISE)
    for key, value in dict(noise or {}).items():
        if key not in DEFAULT_NOISE:
            raise ValueError('noise: unknown key %r (known: %s)'
                             % (key, ', '.join(DEFAULT_NOISE)))
        if key == 'tension' and isinstance(value, str) and value.strip().endswith('%'):
            fraction = float(value.strip()[:-1]) / 100.0
            if not (math.isfinite(fraction) and fraction > 0.0):
                raise ValueError('noise tension %r must be a positive percentage' % value)
            levels[key] = value.strip()
            continue
        value = float(value)
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError('noise %s must be finite and > 0, got %r' % (key, value))
        levels[key] = value
    return levels


def slack_band(level):
    """How far below zero (N) a measured tension is still a slack cable's zero: 3 sigma."""
    return 3.0 * float(tension_sigma(level, [0.0])[0])


def tension_sigma(level, tensions):
    """Per-cable tension standard deviations (N) of a noise level (N or 'P%')."""
    if isinstance(level, str):
        return np.maximum(float(level[:-1]) / 100.0 * np.abs(tensions), MIN_TENSION_NOISE)
    return np.full(len(tensions), float(level))


class _Model:
    """The forward model f(u, w) for one estimate: which solver, which predictions."""

    def __init__(self, robot, lengths, tensions, tip_position, tip_rotation, levels, warm,
                 reference=None, peak=None):
        self.robot = robot
        self.reference = None  # free lengths where each cable last moved beyond the noise
        self.peak = None  # ... and furthest along that motion since
        n = len(robot.cable_names)
        self.tip_position, self.tip_rotation = tip_position, tip_rotation
        self.warm = warm
        outputs, sigmas = [], []
        if lengths is not None and not robot.tendons.is_ideal:
            self.kind, self.inputs = 'lengths', lengths
            self.input_sigma = np.full(n, levels['length'])
            self.input_step = LENGTH_STEP * robot.length
            if tensions is not None:
                outputs.append(tensions)
                sigmas.append(tension_sigma(levels['tension'], tensions))
        elif tensions is not None:
            self.kind, self.inputs = 'tensions', tensions
            self.input_sigma = tension_sigma(levels['tension'], tensions)
            radius = np.hypot(robot.cable_offsets[:, 0], robot.cable_offsets[:, 1])
            self.input_step = TENSION_STEP * robot.c[0] / (robot.length * float(
                np.mean(radius)))
            if lengths is not None:
                outputs.append(lengths)
                sigmas.append(np.full(n, levels['length']))
        elif lengths is not None:
            self.kind, self.inputs = 'estimate', lengths
            self.input_sigma = np.full(n, levels['length'])
            self.input_step = LENGTH_STEP * robot.length
        else:
            self.kind, self.inputs, self.input_sigma = 'rod', np.zeros(0), np.zeros(0)
            self.input_step = 0.0
        self.turns = ()  # (cable, friction state) a reversal under the noise may have made
        if self.kind == 'lengths':
            self.warm, self.reference, moved = _noise_deadband(robot, warm, reference,
                                                               lengths, levels['length'])
            self.turns, self.peak = _possible_turns(robot, self.warm, self.reference, moved,
                                                    peak, lengths)
        self.predicts_cables = bool(outputs)
        if tip_position is not None:
            outputs.append(tip_position)
            sigmas.append(np.full(3, levels['tip_position']))
        if tip_rotation is not None:
            outputs.append(np.zeros(3))  # the angle from the measured orientation
            sigmas.append(np.full(3, levels['tip_angle']))
        self.measured = np.concatenate(outputs) if outputs else np.zeros(0)
        self.sigma = np.concatenate(sigmas) if sigmas else np.zeros(0)

    def turned(self, turns):
        """Return this model with the friction of ``turns`` ((cable, state), ...) turned."""
        other = copy.copy(self)
        motion = np.array(self.warm.motion, dtype=float)
        cables = [k for k, _ in turns]
        motion[cables] = [state for _, state in turns]
        other.warm = dataclasses.replace(self.warm, motion=motion)
        free = self.robot.tendons.free_lengths(self.inputs, self.robot.straight_cable_lengths)
        other.reference, other.peak = self.reference.copy(), self.peak.copy()
        other.reference[cables] = other.peak[cables] = free[cables]  # they moved: from here
        other.turns = tuple(turn for turn in self.turns if turn[0] not in cables)
        return other

    def solve(self, load, inputs=None, warm=None):
        """Forward solve at a wrench (6,) (and perturbed inputs); returns (result, shape)."""
        robot = self.robot
        inputs = self.inputs if inputs is None else inputs
        warm = self.warm if warm is None else warm
        force, moment = load[:3], load[3:]
        try:
            if self.kind == 'lengths':
                result = robot.solve_lengths(inputs, force, moment, warm_start=warm)
                ok, shape = result.converged, result.shape
            elif self.kind == 'tensions':
                result = shape = robot.solve_tensions(np.maximum(inputs, 0.0), force, moment,
                                                      warm_start=warm)
                ok = True
            elif self.kind == 'estimate':
                result = robot.estimate_shape(inputs, force, moment, warm_start=warm,
                                              exact=True)  # differentiated: to the end
                ok, shape = result.converged, result.shape
            else:
                result = shape = robot.solve_bvp(force, moment, None if warm is None else
                                                 getattr(warm, 'u0', None))
                ok = True
        except (ValueError, ConvergenceError) as error:
            raise _ForwardFailed(str(error)) from error
        if not ok or not np.all(np.isfinite(shape.tip_position)):
            raise _ForwardFailed(getattr(result, 'message', '') or 'no equilibrium')
        return result, shape

    def predict(self, result, shape):
        """Predictions (m,) in the order of ``measured``."""
        parts = []
        if self.predicts_cables:
            parts.append(result.tensions if self.kind == 'lengths'
                         else self.robot.cable_lengths(shape))
        rotation = shape.tip_rotation
        if self.tip_position is not None:
            parts.append(shape.tip_position + rotation @ self.robot.tip_marker)
        if self.tip_rotation is not None:
            parts.append(_angle(rotation @ self.tip_rotation.T))
        return np.concatenate(parts) if parts else np.zeros(0)

    def evaluate(self, load):
        """Predictions (m,) at a wrench (6,), the solve's result and shape."""
        result, shape = self.solve(load)
        return self.predict(result, shape), result, shape

    def load_jacobian(self, wrench, basis, steps, predicted, result):
        """J_p = J_w B (m, k): forward differences of the predictions along B's columns."""
        # perturbed solves start from the nominal one (its state and friction history)
        jacobian = np.empty((len(predicted), basis.shape[1]))
        for k in range(basis.shape[1]):
            trial = wrench + steps[k] * basis[:, k]
            jacobian[:, k] = (self.predict(*self.solve(trial, warm=result))
                              - predicted) / steps[k]
        return jacobian

    def _same_motion(self, result, lengths):
        """Warm start for perturbed lengths that keeps each cable's friction direction."""
        if self.kind != 'lengths':
            return result
        robot = self.robot
        free = robot.tendons.free_lengths(lengths, robot.straight_cable_lengths)
        return dataclasses.replace(result, free_lengths=free, motion_reference=None)

    def whitener(self, load, predicted, result):
        """W with W^T W = C^-1, C = R_y + J_u R_u J_u^T: the residual's covariance."""
        covariance = np.diag(self.sigma ** 2)
        for k in range(len(self.inputs)):
            trial = self.inputs.copy()
            trial[k] += self.input_step
            column = (self.predict(*self.solve(load, trial, self._same_motion(result, trial)))
                      - predicted) / self.input_step
            covariance += np.outer(column, column) * self.input_sigma[k] ** 2
        if not covariance.size:
            return np.zeros((0, 0))
        return np.linalg.inv(np.linalg.cholesky(covariance))


def _noise_deadband(robot, warm, reference, lengths, sigma):
    """Return (warm start, motion reference, moved (n,) bool): motion under 3 sigma is none.

    Friction acts against each cable's last direction of motion (``solve_lengths`` reads it
    from the warm start's free lengths); encoder noise is not motion, so it must not flip it.
    Motion counts from ``reference``, where each cable last moved by more than 3 sigma, so that
    slow motion (under 3 sigma between two estimates) still counts once it adds up.
    """
    previous = getattr(warm, 'free_lengths', None)
    if previous is None or len(previous) != len(lengths):
        return warm, None, None
    if reference is None or len(reference) != len(lengths):
        reference = previous
    free = robot.tendons.free_lengths(lengths, robot.straight_cable_lengths)
    still = np.abs(free - reference) < 3.0 * sigma
    return (dataclasses.replace(warm, free_lengths=np.where(still, free, reference),
                                motion_reference=None),
            np.where(still, reference, free), ~still)


def _possible_turns(robot, warm, reference, moved, peak, lengths):
    """Return (((cable, friction state), ...), peaks (n,) m): friction that may have turned unseen.

    A cable that came back from the furthest point of its motion (``peak``, free length) by
    less than the noise deadband (:func:`_noise_deadband`) keeps its friction direction in the
    model, but the real one may have turned: at once in the sliding model, by 2 x travel /
    ``stick_length`` in a stick zone
    (:func:`~continuum_statics.core.statics.length_statics.motion_since`). In a tensioned cable
    that moves the motor-side tension by newtons, which a tip force was made up to explain
    (false contacts of 8-12 N at rest after a brisk joystick reversal, issue 43). ``moved``: the
    cables that moved beyond the deadband now (their peak starts here). Returns the state each
    such cable would have turned to, and the peaks carried to the next estimate.
    """
    motion = getattr(warm, 'motion', None)
    free = robot.tendons.free_lengths(lengths, robot.straight_cable_lengths)
    if moved is None or motion is None or len(motion) != len(lengths):
        return (), free
    motion = np.asarray(motion, dtype=float)
    if peak is None or len(peak) != len(free):
        peak = reference
    # a cable that moved starts its peak here; a still one's peak follows it along its
    # motion: a pulled cable's (+1) free length shrinks
    peak = np.where(moved, free, np.where(motion > 0.0, np.minimum(peak, free),
                                          np.where(motion < 0.0, np.maximum(peak, free), free)))
    back = free - peak
    turned = turned_state(robot, motion, back)
    against = (np.abs(back) > MOTION_THRESHOLD) & (motion * np.sign(back) > 0.0)
    return tuple((int(k), float(turned[k]) + 0.0) for k in np.flatnonzero(against)), peak


def _angle(rotation):
    """Rotation vector (rad) of a rotation matrix (log map)."""
    cos = np.clip((np.trace(rotation) - 1.0) / 2.0, -1.0, 1.0)
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0],
                     rotation[1, 0] - rotation[0, 1]])
    angle = math.acos(cos)
    if angle < 1e-6:
        return axis / 2.0
    return axis * (angle / (2.0 * math.sin(angle)))


def estimate_tip_wrench(robot, lengths=None, tensions=None, tip_position=None, tip_rotation=None,
                        noise=None, moment=False, warm_start=None, load=None, load_prior=None):
    """Estimate the tip wrench (base frame) from any measurements that make it observable.

    ``lengths`` (m, motor side) and ``tensions`` (N, motor side) in ``robot.cable_names`` order;
    ``tip_position`` (m) the tracked point (the rod's tip plus ``tip_marker``) and
    ``tip_rotation`` (3x3) the tip orientation, base frame; ``noise`` standard deviations
    (:data:`DEFAULT_NOISE` keys); ``warm_start`` the previous :class:`WrenchEstimate` of a
    sequence; ``load`` the load model, 'weight' | 'force' (default) | ('direction', (dx, dy,
    dz)) | 'wrench' (``moment=True`` is 'wrench'), with ``load_prior`` its prior's standard
    deviation(s) in the model's units (:func:`load_model`). Returns :class:`WrenchEstimate`
    (``.mass`` and ``.mass_sigma`` with 'weight'); never raises for a failed solve (then
    ``converged`` is False with the last good estimate); bad arguments raise ``ValueError``.
    """
    n = len(robot.cable_names)
    model = load_model(robot, load, moment, load_prior)
    lengths = None if lengths is None else as_vector(lengths, n, 'lengths')
    tensions = None if tensions is None else as_vector(tensions, n, 'tensions')
    if tensions is not None and np.any(tensions < 0.0):
        raise ValueError('tensions must be >= 0 N, got %s' % np.round(tensions, 6).tolist())
    if tip_position is not None:
        tip_position = as_vector(tip_position, 3, 'tip_position')
    if tip_rotation is not None:
        tip_rotation = np.asarray(tip_rotation, dtype=float)
        if tip_rotation.shape != (3, 3) or not np.all(np.isfinite(tip_rotation)) or \
                not np.allclose(tip_rotation @ tip_rotation.T, np.eye(3), atol=1e-6):
            raise ValueError('tip_rotation must be a 3x3 rotation matrix')
    if lengths is None and tensions is None and tip_position is None and tip_rotation is None:
        raise ValueError('no measurement given: lengths, tensions, tip_position or '
                         'tip_rotation')
    if n == 0 and (lengths is not None or tensions is not None):
        raise ValueError('this robot has no cables: estimate from the tip pose')
    levels = noise_levels(noise)
    previous = warm_start if isinstance(warm_start, WrenchEstimate) else None
    if previous is not None and not previous.explains():
        # an estimate of measurements the model could not explain (a wrong unit, a faulty
        # sensor) sits on a branch of equilibria of its own: the next one starts afresh
        previous = None
    try:
        return _estimate(robot, lengths, tensions, tip_position, tip_rotation, levels, model,
                         previous)
    except _ForwardFailed as error:
        # a solve failed after the start (a re-linearisation, the final Jacobian): the
        # measurements have no equilibrium near the last estimate; it stays, marked so
        if previous is None:
            raise ValueError('no equilibrium for these measurements: %s' % error) from error
        return dataclasses.replace(
            previous, converged=False,
            message='no equilibrium for these measurements (%s): kept the last estimate'
            % error)


def _start(previous, load):
    """Return the parameters p a warm start gives (zeros without one)."""
    if previous is None or not np.all(np.isfinite(previous.wrench)):
        return np.zeros(len(load.prior))
    if load.same(previous.load) and previous.parameters is not None:
        # the fit's own p (a mixture's mean lies between its fits: its weights are not there)
        return np.array(previous.parameters if previous.fitted is None else previous.fitted,
                        dtype=float)
    # another model's estimate: the p whose wrench is nearest it (least squares)
    return np.linalg.lstsq(load.basis, previous.wrench, rcond=None)[0]


@dataclass(eq=False)
class _Fit:
    """One estimate's state, handed from phase to phase of :func:`_estimate`."""

    model: object  # the measurements and the forward solves (:class:`_Model`)
    load: object  # the load model (:class:`LoadModel`): w = B p, prior scales of p
    p: np.ndarray  # the load parameters
    predicted: np.ndarray = None  # the measurements the model predicts at p
    result: object = None  # the forward solve at p (a warm start of the next)
    shape: object = None
    weights: object = None  # :class:`_Weights`
    fresh: bool = False  # the load Jacobian is this estimate's own (not the previous one's)
    jacobian: np.ndarray = None  # whitened d residual / d p
    seen: np.ndarray = None  # an orthonormal basis of the directions of p the data see
    damping: float = COLD_DAMPING
    converged: bool = False
    iterations: int = 0
    failure: str = ''  # why the last trial step found no equilibrium
    notes: list = field(default_factory=list)

    def evaluate(self, p):
        """Return (predicted, forward solve, shape) at ``p``; may raise _ForwardFailed."""
        return self.model.evaluate(self.load.basis @ p)

    def residual(self, predicted):
        """Return the whitened residual of ``predicted`` measurements."""
        return self.weights.whiten @ (predicted - self.model.measured)

    def objective(self, p, residual):
        """e^T C^-1 e + p^T P^-1 p (the prior in its scales)."""
        return float(residual @ residual) + float(np.sum((p / self.load.prior) ** 2))

    def take_weights(self, weights):
        """Use ``weights`` (this estimate's own) from now on: their Jacobian and seen basis."""
        self.weights, self.fresh = weights, True
        self.jacobian = weights.whiten @ weights.load_jacobian
        self.seen = _seen_basis(self.jacobian, self.load.prior)


def _estimate(robot, lengths, tensions, tip_position, tip_rotation, levels, load, previous):
    """Estimate on checked arguments (:func:`estimate_tip_wrench`); may raise _ForwardFailed.

    Levenberg-Marquardt in the seen directions on e^T C^-1 e + p^T P^-1 p (prior-scaled), in
    phases: :func:`_started` (the start and its weights), :func:`_iteration` until one says it
    is done, :func:`_answer` (the covariance and the notes).
    """
    model = _Model(robot, lengths, tensions, tip_position, tip_rotation, levels,
                   None if previous is None else previous.solution,
                   None if previous is None else previous.friction_reference,
                   None if previous is None else previous.friction_peak)
    fit = _fitted(model, load, previous)
    if not model.turns:
        return _answer(fit)
    # reversals under the noise deadband: the flagged cables' friction kept, all turned (a
    # joystick or goal reversal turns several at once), or one of them turned (one real turn
    # among cables the noise flagged), weighed by likelihood, each by one forward solve and a
    # first-order load step; the likeliest, when likelier than none, is fitted to the end, and
    # carried on when it wins by far (or a refuted kept fit needs it)
    kept = _answer(fit)
    candidates = [model.turns] + ([(turn,) for turn in model.turns]
                                  if len(model.turns) > 1 else [])
    steps = [(turns,) + step for turns, step in (
        (turns, _turned_step(fit, model.turned(turns))) for turns in candidates)
        if step is not None]
    best = max(range(len(steps)), key=lambda k: steps[k][2], default=None)
    if best is not None and steps[best][2] > 0.0:
        # likelier than keeping the friction to first order: its own fit says by how much (a
        # first-order step from a kept estimate far off underrates it)
        turns = steps[best][0]
        try:
            turned = _fitted(model.turned(turns), load, kept)
        except _ForwardFailed as error:  # the kept estimate stands
            return dataclasses.replace(kept, message='; '.join(filter(None, (
                kept.message, 'friction turn of %s not fitted: %s' % (
                    _names(model, turns), error)))))
        gain = fit.objective(fit.p, fit.residual(fit.predicted)) - turned.objective(
            turned.p, turned.residual(turned.predicted))
        if gain > TURN_MARGIN or (gain > 0.0 and not kept.explains()):
            return _mixed(_answer(turned), [], model, turns)  # carried on
        steps[best] = (turns, turned.p, gain)
    return _mixed(kept, [(turns, gain, p - fit.p) for turns, p, gain in steps], model, ())


def _fitted(model, load, previous):
    """Return the finished :class:`_Fit` of ``model`` (Levenberg-Marquardt to the end)."""
    fit = _started(model, load, previous)
    for fit.iterations in range(1, MAX_ITERATIONS + 1):
        if _iteration(fit):
            break
    else:
        fit.notes.append('not converged in %d iterations' % MAX_ITERATIONS)
    return fit


def _turned_step(fit, turned_model):
    """Return (p, gain) of the friction turn of ``turned_model``, or None where it is moot.

    One forward solve at the fit's load with the friction turned, and the load step that best
    explains its residual to first order (the fit's whitener and Jacobian: a turn moves the
    tensions, barely their slopes); ``gain`` is the objective that step leaves below the kept
    fit's. None when the turn moves the predictions by less than their noise (a slack or barely
    loaded cable), or the tensions rule it out by more than :data:`TURN_MARGIN` (encoder noise
    flags a still cable about every other reading).
    """
    try:
        predicted, _, _ = turned_model.evaluate(fit.load.basis @ fit.p)
    except _ForwardFailed:
        return None  # no equilibrium near with the friction turned
    if float(np.sum((fit.weights.whiten @ (predicted - fit.predicted)) ** 2)) < 1.0:
        return None
    prior = fit.load.prior
    residual = fit.weights.whiten @ (predicted - turned_model.measured)
    scaled = fit.jacobian * prior @ fit.seen  # in the seen directions, as the fit steps
    z = fit.seen.T @ (fit.p / prior)
    step = -np.linalg.solve(scaled.T @ scaled + np.eye(len(z)), scaled.T @ residual + z)
    objective = float(np.sum((residual + scaled @ step) ** 2) + np.sum((z + step) ** 2))
    gain = fit.objective(fit.p, fit.residual(fit.predicted)) - objective
    return None if gain < -TURN_MARGIN else (fit.p + prior * (fit.seen @ step), gain)


def _mixed(kept, shifts, model, sure):
    """Return ``kept`` with the mean and covariance of the friction turns' mixture.

    ``shifts``: (turns, gain, dp) of each turn hypothesis weighed against keeping the friction:
    the load moves by dp if it holds, and it is exp(gain / 2) times as likely as none (the
    hypotheses exclusive, the covariance of each ``kept``'s). ``sure``: the turns carried on.
    """
    notes = ['friction of %s turned after a reversal under the noise' % _names(model, sure)
             ] if sure else []
    mean, covariance = np.array(kept.parameters, dtype=float), np.array(
        kept.parameter_covariance, dtype=float)
    if shifts:
        gains = np.array([0.0] + [0.5 * gain for _, gain, _ in shifts])
        weights = np.exp(gains - gains.max())
        weights /= weights.sum()
        moves = np.array([np.zeros_like(mean)] + [shift for _, _, shift in shifts])
        middle = weights @ moves
        mean = mean + middle
        covariance = covariance + (moves.T * weights) @ moves - np.outer(middle, middle)
        notes.append('friction kept after a reversal under the noise %.3g likely; turned: %s'
                     % (weights[0], ', '.join('%s %.3g' % (_names(model, turns), weight)
                                              for (turns, _, _), weight in zip(
                                                  shifts, weights[1:]))))
    if not notes:
        return kept
    load = kept.load
    rows = load.basis[:load.size]
    wrench = load.basis @ mean
    mass = mass_sigma = None
    if load.name == 'weight':
        mass, mass_sigma = float(mean[0]), float(np.sqrt(covariance[0, 0]))
    return dataclasses.replace(
        kept, force=wrench[:3].copy(), moment=wrench[3:].copy() if load.size == 6
        else np.zeros(3), covariance=rows @ covariance @ rows.T, parameters=mean,
        parameter_covariance=covariance, mass=mass, mass_sigma=mass_sigma,
        message='; '.join(filter(None, [kept.message] + notes)))


def _names(model, turns):
    """Return the cable names of ``turns`` ((cable, state), ...), comma-separated."""
    return ', '.join(model.robot.cable_names[k] for k, _ in turns)


def _started(model, load, previous):
    """Return the start: the warm start's parameters (unloaded if unsolvable), its weights.

    The directions the data do not see stay at the prior's mean, zero (never made up); a warm
    start is near, so its steps are Gauss-Newton's from the first.
    """
    fit = _Fit(model, load, _start(previous, load))
    try:
        fit.predicted, fit.result, fit.shape = fit.evaluate(fit.p)
    except _ForwardFailed as error:
        if not fit.p.any():
            raise ValueError('no equilibrium for these measurements even without a tip load: '
                             '%s' % error) from error
        fit.p[:] = 0.0  # the previous estimate no longer fits: start unloaded
        fit.predicted, fit.result, fit.shape = fit.evaluate(fit.p)
    prior = load.prior
    weights = _reused_weights(previous, model, fit.p, load)
    fresh = weights is None  # else the previous estimate's Jacobian, until it misleads
    if fresh:
        weights = _linearise(model, fit.p, load, fit.predicted, fit.result)
    elif _moved(fit.p, weights.jacobian_load, prior) > REJACOBIAN:
        weights, fresh = _with_jacobian(model, weights, fit.p, load, fit.predicted,
                                        fit.result), True
    fit.take_weights(weights)
    fit.fresh = fresh
    fit.p = prior * (fit.seen @ (fit.seen.T @ (fit.p / prior)))
    fit.damping = COLD_DAMPING if previous is None else WARM_DAMPING
    return fit


def _iteration(fit):
    """One Levenberg-Marquardt iteration; return True when the fit is done.

    Done: the next Gauss-Newton step is below STEP_TOLERANCE standard deviations, the objective
    no longer improves measurably (the solvers' resolution), or no step lowers it.
    """
    prior = fit.load.prior
    residual = fit.residual(fit.predicted)
    objective = fit.objective(fit.p, residual)
    scaled = fit.jacobian * prior  # d residual / d (p / prior)
    hessian = fit.seen.T @ (scaled.T @ scaled + np.eye(len(prior))) @ fit.seen
    gradient = fit.seen.T @ (scaled.T @ residual + fit.p / prior)
    if _sigmas(hessian, gradient) <= STEP_TOLERANCE:
        fit.converged = True  # already there (a warm start on an unchanged measurement)
        return True
    trial = _damped_step(fit, hessian, gradient, objective)
    if trial is None:
        if not fit.fresh:  # the previous estimate's Jacobian misled: take this one's
            fit.take_weights(_linearise(fit.model, fit.p, fit.load, fit.predicted, fit.result))
            fit.damping = COLD_DAMPING
            return False
        # no step lowers the objective: a minimum to the solvers' resolution, or no solve
        fit.converged = not fit.failure
        if fit.failure:
            fit.notes.append('no equilibrium near the step from this estimate (%s)'
                             % fit.failure)
        return True
    fit.p, fit.predicted, fit.result, fit.shape, trial_objective = trial
    fit.damping = max(fit.damping / 10.0, WARM_DAMPING)
    gradient = fit.seen.T @ (scaled.T @ fit.residual(fit.predicted) + fit.p / prior)
    if _sigmas(hessian, gradient) <= STEP_TOLERANCE \
            or (fit.fresh and objective - trial_objective < OBJECTIVE_TOLERANCE):
        fit.converged = True
        return True
    fit.take_weights(_linearise(fit.model, fit.p, fit.load, fit.predicted, fit.result)
                     if _moved(fit.p, fit.weights.load, prior) > REWEIGH else
                     _with_jacobian(fit.model, fit.weights, fit.p, fit.load, fit.predicted,
                                    fit.result))
    return False


def _damped_step(fit, hessian, gradient, objective):
    """Return (p, predicted, solve, shape, objective) of a step that lowers the objective.

    Levenberg's damping (identity in prior units: weakly seen directions move last), raised
    tenfold per refused trial, ten trials at most; None when none lowers it.
    """
    prior = fit.load.prior
    for _ in range(10):
        step = prior * (fit.seen @ -np.linalg.solve(
            hessian + fit.damping * np.max(np.diag(hessian), initial=1.0)
            * np.eye(len(hessian)), gradient))
        # at most STEP_LIMIT of the prior scale per step: the branch of equilibria nearest
        # the start, not a far one (a rod near buckling explains a tip as well)
        largest = float(np.max(np.abs(step) / prior, initial=0.0))
        if largest > STEP_LIMIT:
            step *= STEP_LIMIT / largest
        trial = fit.p + step
        try:
            predicted, result, shape = fit.evaluate(trial)
        except _ForwardFailed as error:
            fit.failure, fit.damping = str(error), fit.damping * 10.0
            continue
        trial_objective = fit.objective(trial, fit.residual(predicted))
        if trial_objective <= objective:
            return trial, predicted, result, shape, trial_objective
        fit.damping *= 10.0
    return None


def _answer(fit):
    """Return the :class:`WrenchEstimate` of a finished fit: covariance, what it saw, notes."""
    load, prior, p, notes = fit.load, fit.load.prior, fit.p, fit.notes
    weights, jacobian = fit.weights, fit.jacobian
    if _moved(p, weights.jacobian_load, prior) > REJACOBIAN:
        # the covariance is that of the estimate: its own Jacobian once the load moved
        weights = _with_jacobian(fit.model, weights, p, load, fit.predicted, fit.result)
        jacobian = weights.whiten @ weights.load_jacobian
    residual = weights.whiten @ (fit.predicted - fit.model.measured)
    data_information = jacobian.T @ jacobian
    parameter_covariance = np.linalg.inv(data_information + np.diag(1.0 / prior ** 2))
    parameter_covariance = 0.5 * (parameter_covariance + parameter_covariance.T)
    rows = load.basis[:load.size]  # the wrench rows reported: w = B p, Cov_w = B Cov_p B^T
    covariance = rows @ parameter_covariance @ rows.T
    covariance = 0.5 * (covariance + covariance.T)
    unseen = _unseen(data_information, prior, rows)
    wrench = load.basis @ p
    mass = mass_sigma = None
    if load.name == 'weight':
        mass, mass_sigma = float(p[0]), float(np.sqrt(parameter_covariance[0, 0]))
    poorly = _poorly_seen(wrench, covariance, load, mass, mass_sigma)
    if poorly:
        notes.insert(0, poorly)
    if len(unseen):
        notes.insert(0, _unseen_note(unseen))
    chi2 = float(residual @ residual) / max(len(residual), 1)
    return WrenchEstimate(force=wrench[:3].copy(),
                          moment=wrench[3:].copy() if load.size == 6 else np.zeros(3),
                          covariance=covariance, shape=fit.shape, converged=fit.converged,
                          message='; '.join(notes), unseen=unseen, iterations=fit.iterations,
                          chi2=chi2, solution=fit.result, weights=weights,
                          measurements=len(residual), friction_reference=fit.model.reference,
                          friction_peak=fit.model.peak,
                          load=load, parameters=p.copy(), fitted=p.copy(),
                          parameter_covariance=parameter_covariance, mass=mass,
                          mass_sigma=mass_sigma)


@dataclass(frozen=True, eq=False)
class _Weights:
    """The residual's whitener W, the load Jacobian J_p, and the load and inputs they are of."""

    whiten: np.ndarray
    load_jacobian: np.ndarray
    load: np.ndarray  # the parameters p where the whitener was computed
    inputs: np.ndarray
    jacobian_load: np.ndarray  # the parameters p where the load Jacobian was computed
    basis: np.ndarray  # the load model's B (p means this wrench)


def _with_jacobian(model, weights, p, load, predicted, result):
    """``weights`` with the load Jacobian computed afresh at ``p`` (k forward solves)."""
    return dataclasses.replace(weights, load_jacobian=model.load_jacobian(
        load.basis @ p, load.basis, load.steps, predicted, result), jacobian_load=p.copy())


def _linearise(model, p, load, predicted, result):
    """Fresh :class:`_Weights` at ``p`` (1 + n_inputs + k forward solves)."""
    wrench = load.basis @ p
    return _Weights(model.whitener(wrench, predicted, result),
                    model.load_jacobian(wrench, load.basis, load.steps, predicted, result),
                    p.copy(), model.inputs, p.copy(), load.basis)


def _reused_weights(previous, model, p, load):
    """Return the previous estimate's weights while load and inputs stay close, else None.

    The sensitivities change with the robot's bend: they are refreshed once the load moved by
    :data:`REWEIGH` of its prior scale or an input by :data:`REWEIGH_INPUT` steps. Another
    load model's weights are never reused.
    """
    weights = getattr(previous, 'weights', None)
    if weights is None or weights.whiten.shape != (len(model.measured),) * 2 or \
            weights.inputs.shape != model.inputs.shape or \
            weights.basis.shape != load.basis.shape or \
            not np.array_equal(weights.basis, load.basis):
        return None
    if _moved(p, weights.load, load.prior) > REWEIGH:
        return None
    if np.max(np.abs(model.inputs - weights.inputs), initial=0.0) > \
            REWEIGH_INPUT * model.input_step:
        return None
    return weights


def _sigmas(hessian, gradient):
    """Size of the Gauss-Newton step -H^-1 g in standard deviations (sqrt of g^T H^-1 g)."""
    if not gradient.size:
        return 0.0
    return float(np.sqrt(max(float(gradient @ np.linalg.solve(hessian, gradient)), 0.0)))


def _moved(p, since, prior):
    """How far the parameters are from where something was computed, in prior scales (max)."""
    return float(np.max(np.abs(p - since) / prior, initial=0.0))


def _seen_basis(jacobian, prior):
    """Orthonormal basis (k, j) of the prior-scaled parameter directions the data see."""
    scaled = jacobian * prior
    values, vectors = np.linalg.eigh(scaled.T @ scaled)
    return vectors[:, values >= 1.0]


def _unseen(information, prior, rows):
    """Return the unit directions of w (rows B p) whose data-only sigma exceeds the prior's.

    In units of the prior (force / largest plausible force, moment likewise) so that force and
    moment compare; a direction the measurements pin down less well than "some plausible load"
    is one they do not see.
    """
    scaled = information * np.outer(prior, prior)
    values, vectors = np.linalg.eigh(scaled)
    directions = []
    for value, vector in zip(values, vectors.T):
        if value < 1.0:  # data sigma > the prior's
            direction = rows @ (vector * prior)  # back to load units, then normalised
            directions.append(direction / np.linalg.norm(direction))
    return np.array(directions).reshape(-1, len(rows))


def _unseen_note(unseen):
    parts = []
    for direction in unseen:
        label = 'force' if len(direction) == 3 or not np.any(np.abs(direction[3:]) > 1e-3) \
            else ('moment' if not np.any(np.abs(direction[:3]) > 1e-3) else 'force/moment')
        parts.append('%s along (%s)' % (label, ', '.join('%.2f' % v for v in direction)))
    return ('the measurements do not determine the tip %s: held at zero with the prior '
            'variance' % '; '.join(parts))


def _poorly_seen(wrench, covariance, load, mass, mass_sigma):
    """Name the seen directions whose sigma exceeds :data:`POORLY_SEEN` of the estimate, or ''.

    Force and moment apart (their own magnitudes and units); only while the estimate stands
    clear of zero (its chi-square distance from zero beyond the 3-sigma quantile). A direction
    where the data weigh less than the prior (the posterior variance above half the prior's)
    is an unseen one, named as such.
    """
    if mass is not None:
        if POORLY_SEEN * abs(mass) < mass_sigma < abs(mass) / 3.0:
            return ('the payload mass is poorly seen: sigma %.3g g against %.3g g estimated'
                    % (1e3 * mass_sigma, 1e3 * mass))
        return ''
    rows = load.basis[:load.size]
    prior_covariance = rows @ np.diag(load.prior ** 2) @ rows.T
    parts = []
    for block, label, unit in ((slice(0, 3), 'force', 'N'), (slice(3, 6), 'moment', 'N m')):
        if block.start >= load.size:
            break
        value, spread = wrench[block], covariance[block, block]
        magnitude = float(np.linalg.norm(value))
        if magnitude == 0.0:
            continue
        values, vectors = np.linalg.eigh(spread)
        kept = values > 1e-12 * max(float(values[-1]), 1e-300)
        projected = vectors[:, kept].T @ value
        distance = float(np.sum(projected ** 2 / values[kept]))  # chi-square from zero
        if distance <= gates.chi2_quantile(gates.THREE_SIGMA, int(np.sum(kept))):
            continue  # not a load at all: noise about none
        for variance, vector in zip(values[::-1], vectors.T[::-1]):
            sigma = math.sqrt(max(float(variance), 0.0))
            if sigma <= POORLY_SEEN * magnitude:
                break
            if variance > 0.5 * float(vector @ prior_covariance[block, block] @ vector):
                continue  # unseen: named as such
            vector = vector * (1.0 if vector[np.argmax(np.abs(vector))] > 0 else -1.0)
            parts.append('the tip %s along (%s) is poorly seen: sigma %.3g %s against %.3g %s '
                         'estimated' % (label, ', '.join('%.2f' % v for v in vector), sigma,
                                        unit, magnitude, unit))
    return '; '.join(parts)
