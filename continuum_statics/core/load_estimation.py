"""Tip-load estimation: the wrench on the tip that best explains what the robot measures (no ROS).

Intrinsic force sensing (Xu & Simaan: the wrench from actuation forces and the statics model)
and deflection-based sensing (Rucker & Webster 2011: the wrench whose deflection matches a
measured tip, with a probabilistic estimator) are one weighted least-squares problem here.
Unknowns w: the tip force (N) and, with ``moment=True``, the tip moment (N m), base frame.
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
Gaussian prior P on w (standard deviation: the largest plausible tip load, see
:func:`plausible_tip_load`) the estimate minimises e^T C^-1 e + w^T P^-1 w by Gauss-Newton, and
its covariance is (J_w^T C^-1 J_w + P^-1)^-1 (the maximum a posteriori estimate and its
Laplace covariance, as in Rucker & Webster's deflection-based estimator). The prior is what keeps
a direction the measurements cannot see at zero with a large variance instead of a made-up
value; those directions are named in the message. J_w and J_u are forward differences of the
solvers, each warm-started from the nominal solve.
"""
import dataclasses
from dataclasses import dataclass
import math

import numpy as np
from scipy.stats import chi2 as chi2_distribution

from continuum_statics.core.bvp import ConvergenceError
from continuum_statics.core.inputs import as_vector
from continuum_statics.core.shape import Shape

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
#: A direction of the load is named as poorly seen when its standard deviation is more than this
#: fraction of the estimate there (not only when the measurements do not see it at all).
POORLY_SEEN = 0.5
#: The chi-square gate: a measurement set whose weighted squared residual exceeds the (1 - p)
#: quantile of the chi-square distribution with (measurements - seen load directions) degrees
#: of freedom is one the model cannot explain at the stated noise (a faulty sensor, a wrong
#: unit, a tracker the tensions contradict). p = 1e-3: measurements whose noise is as stated
#: are set aside once in a thousand; a faulty one is off by orders of magnitude more.
CHI2_GATE_PROBABILITY = 1e-3


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
    mass: float = None  # kg, a payload (load='weight')
    mass_sigma: float = None  # kg

    @property
    def dof(self):
        """Degrees of freedom of the residual: measurements less the seen load directions."""
        return self.measurements - (len(self.covariance) - len(self.unseen))

    def explains(self, probability=CHI2_GATE_PROBABILITY):
        """Return True if the measurements pass the chi-square gate (see CHI2_GATE_PROBABILITY)."""
        if not np.isfinite(self.chi2):
            return False
        if self.dof <= 0:
            return True
        total = self.chi2 * self.measurements
        return bool(total <= chi2_distribution.ppf(1.0 - probability, self.dof))

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


def tension_sigma(level, tensions):
    """Per-cable tension standard deviations (N) of a noise level (N or 'P%')."""
    if isinstance(level, str):
        return np.maximum(float(level[:-1]) / 100.0 * np.abs(tensions), MIN_TENSION_NOISE)
    return np.full(len(tensions), float(level))


class _Model:
    """The forward model f(u, w) for one estimate: which solver, which predictions."""

    def __init__(self, robot, lengths, tensions, tip_position, tip_rotation, levels, warm,
                 reference=None):
        self.robot = robot
        self.reference = None  # free lengths where each cable last moved beyond the noise
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
        if self.kind == 'lengths':
            self.warm, self.reference = _noise_deadband(robot, warm, reference, lengths,
                                                        levels['length'])
        self.predicts_cables = bool(outputs)
        if tip_position is not None:
            outputs.append(tip_position)
            sigmas.append(np.full(3, levels['tip_position']))
        if tip_rotation is not None:
            outputs.append(np.zeros(3))  # the angle from the measured orientation
            sigmas.append(np.full(3, levels['tip_angle']))
        self.measured = np.concatenate(outputs) if outputs else np.zeros(0)
        self.sigma = np.concatenate(sigmas) if sigmas else np.zeros(0)

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

    def load_jacobian(self, load, size, steps, predicted, result):
        """J_w (m, size): forward differences of the predictions in the wrench."""
        # perturbed solves start from the nominal one (its state and friction history)
        jacobian = np.empty((len(predicted), size))
        for k in range(size):
            trial = load.copy()
            trial[k] += steps[k]
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
    """Return (warm start, motion reference): cables that moved under 3 sigma have not moved.

    Friction acts against each cable's last direction of motion (``solve_lengths`` reads it
    from the warm start's free lengths); encoder noise is not motion, so it must not flip it.
    Motion counts from ``reference``, where each cable last moved by more than 3 sigma, so that
    slow motion (under 3 sigma between two estimates) still counts once it adds up.
    """
    previous = getattr(warm, 'free_lengths', None)
    if previous is None or len(previous) != len(lengths):
        return warm, None
    if reference is None or len(reference) != len(lengths):
        reference = previous
    free = robot.tendons.free_lengths(lengths, robot.straight_cable_lengths)
    still = np.abs(free - reference) < 3.0 * sigma
    return (dataclasses.replace(warm, free_lengths=np.where(still, free, reference),
                                motion_reference=None),
            np.where(still, reference, free))


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
                        noise=None, moment=False, warm_start=None, load='force'):
    """Estimate the tip wrench (base frame) from any measurements that make it observable.

    ``load``: what the lab knows of the load (:func:`load_model`): ``'force'`` (3 unknowns),
    ``'wrench'`` (6: the force and moment, as ``moment=True``), ``('direction', d)`` (its size
    along a known unit direction d, N) or ``'weight'`` (a payload hung on the tip: its mass,
    along gravity; ``mass`` and ``mass_sigma`` in kg).

    ``lengths`` (m, motor side) and ``tensions`` (N, motor side) in ``robot.cable_names`` order;
    ``tip_position`` (m) the tracked point (the rod's tip plus ``tip_marker``) and
    ``tip_rotation`` (3x3) the tip orientation, base frame; ``noise`` standard deviations
    (:data:`DEFAULT_NOISE` keys); ``warm_start`` the previous :class:`WrenchEstimate` of a
    sequence. Returns :class:`WrenchEstimate`; never raises for a failed solve (then
    ``converged`` is False with the last good estimate); bad arguments raise ``ValueError``.
    """
    n = len(robot.cable_names)
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
    direction, scale = load_model(robot, load, moment)
    moment = moment or load == 'wrench'
    previous = warm_start if isinstance(warm_start, WrenchEstimate) else None
    if previous is not None and not previous.explains():
        # an estimate of measurements the model could not explain (a wrong unit, a faulty
        # sensor) sits on a branch of equilibria of its own: the next one starts afresh
        previous = None
    try:
        if direction is not None:
            return _estimate_along(robot, lengths, tensions, tip_position, tip_rotation, levels,
                                   direction, scale, load == 'weight', previous)
        return _estimate(robot, lengths, tensions, tip_position, tip_rotation, levels, moment,
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


#: Load models of :func:`estimate_tip_wrench` (besides ``('direction', d)``).
LOAD_MODELS = ('force', 'wrench', 'weight')


def load_model(robot, load, moment=False):
    """Return (unit direction (3,) or None, N per unit of the unknown) of a load model.

    None: the general models (force, wrench). ``'weight'``: gravity's direction, |g| N per kg;
    ``('direction', d)``: d normalised, 1 N per N. ``ValueError`` names what was expected.
    """
    if isinstance(load, str):
        if load not in LOAD_MODELS:
            raise ValueError("load must be one of %s or ('direction', (dx, dy, dz)), got %r"
                             % (', '.join(LOAD_MODELS), load))
        if load == 'weight':
            g = float(np.linalg.norm(robot.gravity))
            if not g > 0.0:
                raise ValueError("load='weight' needs gravity: the robot file's gravity is zero")
            if moment:
                raise ValueError("load='weight' is a force along gravity: not with moment=True")
            return np.asarray(robot.gravity, dtype=float) / g, g
        return None, None
    if not (isinstance(load, (tuple, list)) and len(load) == 2 and load[0] == 'direction'):
        raise ValueError("load must be one of %s or ('direction', (dx, dy, dz)), got %r"
                         % (', '.join(LOAD_MODELS), load))
    direction = as_vector(load[1], 3, 'load direction')
    norm = float(np.linalg.norm(direction))
    if not norm > 0.0:
        raise ValueError('load direction must not be zero, got %s' % direction.tolist())
    if moment:
        raise ValueError("load=('direction', d) is a force: not with moment=True")
    return direction / norm, 1.0


def _estimate_along(robot, lengths, tensions, tip_position, tip_rotation, levels, direction,
                    scale, weight, previous):
    """Estimate one unknown: the tip force's size along ``direction`` (x scale N per unit).

    The same maximum a posteriori estimate as :func:`_estimate` (Rucker & Webster 2011's
    deflection-based estimator) on one unknown p, w = scale p direction: Gauss-Newton on
    e^T C^-1 e + (p / prior)^2 with a step limit, the covariance 1 / (J^T C^-1 J + prior^-2).
    A hanging mass is one number: a tip position that barely sees a force along the rod cannot
    trade it against the vertical one.
    """
    force_scale, _ = plausible_tip_load(robot)
    prior = force_scale / scale
    steps = LOAD_STEP * np.full(6, force_scale)
    model = _Model(robot, lengths, tensions, tip_position, tip_rotation, levels,
                   None if previous is None else previous.solution,
                   None if previous is None else previous.friction_reference)
    value = 0.0
    if previous is not None and np.all(np.isfinite(previous.force)):
        value = float(previous.force @ direction) / scale
    wrench = np.zeros(6)

    def at(p):
        wrench[:3] = scale * p * direction
        return model.evaluate(wrench.copy())

    def slope(p, predicted, result):
        wrench[:3] = scale * p * direction
        return model.load_jacobian(wrench.copy(), 3, steps, predicted, result) @ direction * scale

    predicted, result, shape = at(value)
    whiten = model.whitener(wrench.copy(), predicted, result)
    jac = whiten @ slope(value, predicted, result)
    converged, notes, iterations = False, [], 0
    for iterations in range(1, MAX_ITERATIONS + 1):
        residual = whiten @ (predicted - model.measured)
        information = float(jac @ jac) + prior ** -2
        step = -(float(jac @ residual) + value / prior ** 2) / information
        step = float(np.clip(step, -STEP_LIMIT * prior, STEP_LIMIT * prior))
        if abs(step) * math.sqrt(information) <= STEP_TOLERANCE:
            converged = True
            break
        objective = float(residual @ residual) + (value / prior) ** 2
        for _ in range(10):
            trial = value + step
            trial_predicted, trial_result, trial_shape = at(trial)
            trial_residual = whiten @ (trial_predicted - model.measured)
            if float(trial_residual @ trial_residual) + (trial / prior) ** 2 <= objective:
                break
            step *= 0.5
        else:
            notes.append('no step lowers the misfit')
            break
        value, predicted, result, shape = trial, trial_predicted, trial_result, trial_shape
        jac = whiten @ slope(value, predicted, result)
    else:
        notes.append('not converged in %d iterations' % MAX_ITERATIONS)
    residual = whiten @ (predicted - model.measured)
    sigma = 1.0 / math.sqrt(float(jac @ jac) + prior ** -2)
    force = scale * value * direction
    covariance = (scale * sigma) ** 2 * np.outer(direction, direction)
    unseen = np.zeros((0, 3))
    if float(jac @ jac) < prior ** -2:
        unseen = direction[None, :]
        notes.insert(0, 'the measurements do not determine the tip force along (%.3g, %.3g, '
                        '%.3g): held near zero with the prior' % tuple(direction))
    elif sigma > POORLY_SEEN * abs(value):
        notes.insert(0, 'the %s is poorly seen: sigma %.3g %s against %.3g estimated' % (
            'mass' if weight else 'force along (%.3g, %.3g, %.3g)' % tuple(direction),
            sigma * (1e3 if weight else 1.0), 'g' if weight else 'N',
            value * (1e3 if weight else 1.0)))
    return WrenchEstimate(force=force, moment=np.zeros(3), covariance=covariance, shape=shape,
                          converged=converged, message='; '.join(notes), unseen=unseen,
                          iterations=iterations,
                          chi2=float(residual @ residual) / max(len(residual), 1),
                          solution=result, measurements=len(residual),
                          friction_reference=model.reference,
                          mass=value if weight else None, mass_sigma=sigma if weight else None)


def _estimate(robot, lengths, tensions, tip_position, tip_rotation, levels, moment, previous):
    """Estimate on checked arguments (:func:`estimate_tip_wrench`); may raise _ForwardFailed."""
    size = 6 if moment else 3
    force_scale, moment_scale = plausible_tip_load(robot)
    prior = np.concatenate([np.full(3, force_scale), np.full(3, moment_scale)])[:size]
    steps = LOAD_STEP * np.concatenate([np.full(3, force_scale), np.full(3, moment_scale)])
    model = _Model(robot, lengths, tensions, tip_position, tip_rotation, levels,
                   None if previous is None else previous.solution,
                   None if previous is None else previous.friction_reference)
    load = np.zeros(6)
    if previous is not None and np.all(np.isfinite(previous.wrench)):
        load[:size] = previous.wrench[:size]
    notes, converged, iterations, failure = [], False, 0, ''
    try:
        predicted, result, shape = model.evaluate(load)
    except _ForwardFailed as error:
        if not load.any():
            raise ValueError('no equilibrium for these measurements even without a tip load: '
                             '%s' % error) from error
        load[:] = 0.0  # the previous estimate no longer fits: start unloaded
        predicted, result, shape = model.evaluate(load)
    weights = _reused_weights(previous, model, load, prior)
    fresh = weights is None  # the load Jacobian is this estimate's own
    if fresh:
        weights = _linearise(model, load, size, steps, predicted, result)
    elif _moved(load, weights.jacobian_load, prior) > REJACOBIAN:
        weights, fresh = _with_jacobian(model, weights, load, size, steps, predicted, result), True
    jacobian = weights.whiten @ weights.load_jacobian
    seen = _seen_basis(jacobian, prior)
    # the directions the data do not see stay at the prior's mean, zero (never made up)
    load[:size] = prior * (seen @ (seen.T @ (load[:size] / prior)))
    # Levenberg-Marquardt in the seen directions on e^T C^-1 e + w^T P^-1 w (prior-scaled);
    # a warm start is near: Gauss-Newton steps from the first
    damping = COLD_DAMPING if previous is None else WARM_DAMPING
    for iterations in range(1, MAX_ITERATIONS + 1):
        residual = weights.whiten @ (predicted - model.measured)
        objective = float(residual @ residual) + float(np.sum((load[:size] / prior) ** 2))
        scaled = jacobian * prior  # d residual / d (w / prior)
        hessian = seen.T @ (scaled.T @ scaled + np.eye(size)) @ seen
        gradient = seen.T @ (scaled.T @ residual + load[:size] / prior)
        if _sigmas(hessian, gradient) <= STEP_TOLERANCE:
            converged = True  # already there (a warm start on an unchanged measurement)
            break
        accepted = False
        for _ in range(10):
            # Levenberg's damping (identity in prior units): weakly seen directions move last
            step = prior * (seen @ -np.linalg.solve(
                hessian + damping * np.max(np.diag(hessian), initial=1.0)
                * np.eye(len(hessian)), gradient))
            # at most STEP_LIMIT of the prior scale per step: the branch of equilibria nearest
            # the start, not a far one (a rod near buckling explains a tip as well)
            largest = float(np.max(np.abs(step) / prior))
            if largest > STEP_LIMIT:
                step *= STEP_LIMIT / largest
            trial = load.copy()
            trial[:size] += step
            try:
                trial_predicted, trial_result, trial_shape = model.evaluate(trial)
            except _ForwardFailed as error:
                failure, damping = str(error), damping * 10.0
                continue
            trial_residual = weights.whiten @ (trial_predicted - model.measured)
            trial_objective = (float(trial_residual @ trial_residual)
                               + float(np.sum((trial[:size] / prior) ** 2)))
            if trial_objective <= objective:
                accepted = True
                break
            damping *= 10.0
        if not accepted:
            if not fresh:  # the previous estimate's Jacobian misled: take this one's
                weights, fresh = _linearise(model, load, size, steps, predicted, result), True
                jacobian = weights.whiten @ weights.load_jacobian
                seen, damping = _seen_basis(jacobian, prior), COLD_DAMPING
                continue
            # no step lowers the objective: a minimum to the solvers' resolution, or no solve
            converged = not failure
            if failure:
                notes.append('no equilibrium near the step from this estimate (%s)' % failure)
            break
        load, predicted, result, shape = trial, trial_predicted, trial_result, trial_shape
        damping = max(damping / 10.0, WARM_DAMPING)
        # converged when the next Gauss-Newton step (this Jacobian) is below the tolerance, or
        # the fit no longer improves by a measurable amount (the solvers' resolution)
        residual = weights.whiten @ (predicted - model.measured)
        gradient = seen.T @ (scaled.T @ residual + load[:size] / prior)
        if _sigmas(hessian, gradient) <= STEP_TOLERANCE \
                or (fresh and objective - trial_objective < OBJECTIVE_TOLERANCE):
            converged = True
            break
        weights = (_linearise(model, load, size, steps, predicted, result)
                   if _moved(load, weights.load, prior) > REWEIGH else
                   _with_jacobian(model, weights, load, size, steps, predicted, result))
        fresh = True
        jacobian = weights.whiten @ weights.load_jacobian
        seen = _seen_basis(jacobian, prior)
    else:
        notes.append('not converged in %d iterations' % MAX_ITERATIONS)
    if _moved(load, weights.jacobian_load, prior) > REJACOBIAN:
        # the covariance is that of the estimate: its own Jacobian once the load moved
        weights = _with_jacobian(model, weights, load, size, steps, predicted, result)
        jacobian = weights.whiten @ weights.load_jacobian
    residual = weights.whiten @ (predicted - model.measured)
    data_information = jacobian.T @ jacobian
    covariance = np.linalg.inv(data_information + np.diag(1.0 / prior ** 2))
    covariance = 0.5 * (covariance + covariance.T)
    unseen = _unseen(data_information, prior)
    poorly = _poorly_seen(covariance[:3, :3], load[:3], unseen)
    if poorly:
        notes.insert(0, poorly)
    if len(unseen):
        notes.insert(0, _unseen_note(unseen, size))
    chi2 = float(residual @ residual) / max(len(residual), 1)
    return WrenchEstimate(force=load[:3].copy(),
                          moment=load[3:].copy() if moment else np.zeros(3),
                          covariance=covariance, shape=shape, converged=converged,
                          message='; '.join(notes), unseen=unseen, iterations=iterations,
                          chi2=chi2, solution=result, weights=weights,
                          measurements=len(residual), friction_reference=model.reference)


@dataclass(frozen=True, eq=False)
class _Weights:
    """The residual's whitener W, the load Jacobian J_w, and the load and inputs they are of."""

    whiten: np.ndarray
    load_jacobian: np.ndarray
    load: np.ndarray  # where the whitener was computed
    inputs: np.ndarray
    jacobian_load: np.ndarray  # where the load Jacobian was computed


def _with_jacobian(model, weights, load, size, steps, predicted, result):
    """``weights`` with the load Jacobian computed afresh at ``load`` (size forward solves)."""
    return dataclasses.replace(weights, load_jacobian=model.load_jacobian(
        load, size, steps, predicted, result), jacobian_load=load.copy())


def _linearise(model, load, size, steps, predicted, result):
    """Fresh :class:`_Weights` at ``load`` (1 + n_inputs + size forward solves)."""
    return _Weights(model.whitener(load, predicted, result),
                    model.load_jacobian(load, size, steps, predicted, result), load.copy(),
                    model.inputs, load.copy())


def _reused_weights(previous, model, load, prior):
    """Return the previous estimate's weights while load and inputs stay close, else None.

    The sensitivities change with the robot's bend: they are refreshed once the load moved by
    :data:`REWEIGH` of its prior scale or an input by :data:`REWEIGH_INPUT` steps.
    """
    weights = getattr(previous, 'weights', None)
    if weights is None or weights.whiten.shape != (len(model.measured),) * 2 or \
            weights.inputs.shape != model.inputs.shape or \
            weights.load_jacobian.shape[1] != len(prior):
        return None
    if _moved(load, weights.load, prior) > REWEIGH:
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


def _moved(load, since, prior):
    """How far the load is from where something was computed, in prior scales (max norm)."""
    return float(np.max(np.abs(load - since)[:len(prior)] / prior))


def _seen_basis(jacobian, prior):
    """Orthonormal basis (size, k) of the prior-scaled load directions the data see."""
    scaled = jacobian * prior
    values, vectors = np.linalg.eigh(scaled.T @ scaled)
    return vectors[:, values >= 1.0]


def _unseen(information, prior):
    """Return the unit directions of w whose data-only sigma exceeds the prior's.

    In units of the prior (force / largest plausible force, moment likewise) so that force and
    moment compare; a direction the measurements pin down less well than "some plausible load"
    is one they do not see.
    """
    scaled = information * np.outer(prior, prior)
    values, vectors = np.linalg.eigh(scaled)
    directions = []
    for value, vector in zip(values, vectors.T):
        if value < 1.0:  # data sigma > the prior's
            direction = vector * prior  # back to load units, then normalised
            directions.append(direction / np.linalg.norm(direction))
    return np.array(directions).reshape(-1, len(prior))


def _poorly_seen(covariance, force, unseen):
    """Name the force's principal directions whose sigma exceeds POORLY_SEEN of its size."""
    size = float(np.linalg.norm(force))
    values, vectors = np.linalg.eigh(covariance)
    notes = []
    for value, vector in zip(values[::-1], vectors.T[::-1]):
        sigma = math.sqrt(max(value, 0.0))
        if sigma <= POORLY_SEEN * size or any(abs(float(vector @ u[:3])) > 0.9 for u in unseen):
            continue
        notes.append('(%.2f, %.2f, %.2f): sigma %.3g N' % (*(vector * np.sign(
            vector[np.argmax(np.abs(vector))])), sigma))
    if not notes:
        return ''
    return ('the tip force is poorly seen along %s, against %.3g N estimated'
            % (', '.join(notes), size))


def _unseen_note(unseen, size):
    parts = []
    for direction in unseen:
        label = 'force' if size == 3 or not np.any(np.abs(direction[3:]) > 1e-3) else (
            'moment' if not np.any(np.abs(direction[:3]) > 1e-3) else 'force/moment')
        parts.append('%s along (%s)' % (label, ', '.join('%.2f' % v for v in direction)))
    return ('the measurements do not determine the tip %s: held at zero with the prior '
            'variance' % '; '.join(parts))
