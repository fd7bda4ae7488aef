"""State estimation: the shape from every measurement the robot has, with its uncertainty (no ROS).

The model's estimate (:mod:`estimation`: cable lengths, tensions and the tip load in, the
equilibrium out) misses what the model does not know. That error is carried as *unmodelled
loads* d = [tip force (3, N); tip moment (3, N m); a length error per cable (n, m)], base
frame, with the robot file's ``model_uncertainty`` as their prior N(0, P0). Between two stamps
they follow an Ornstein-Uhlenbeck process with the calibrated correlation time tau:

    mean <- a mean,  P <- a^2 P + (1 - a^2) P0,  a = exp(-dt / tau)

so a correction a sensor made fades, and its variance grows back to P0, while the sensor is
gone. A fourth group, ``base_position``, is an offset of the whole backbone (the base's
registration drifting, and what the loads leave unexplained that is the same everywhere). A
fifth, ``drift``, is an offset of the whole backbone that changes smoothly from one measurement
to the next as the robot moves (friction history, hysteresis: on the real v6 robot the error's
structure function grows with the square of the lag over the first rows, a smooth process, not
an OU's linear growth): a Matern 3/2 process of standard deviation sigma_w and length scale l
(Rasmussen & Williams 2006, eq. 4.17), carried as the offset and its rate (``drift_rate``) with
the exact transition of its state-space form
(Hartikainen & Saerkkae 2010), lambda = sqrt(3) / l:

    T(dt) = exp(-lambda dt) [[1 + lambda dt, dt], [-lambda^2 dt, 1 - lambda dt]],
    P_inf = diag(sigma_w^2, lambda^2 sigma_w^2),  P <- T P T^T + P_inf - T P_inf T^T

A tracker's last residual is then carried at first (the last-residual baseline's strength
between nearby rows) and handed over to the slowly varying loads as it fades.

What none of these makes, a shape error new with each configuration, is ``point_noise``: white,
of standard deviation point_noise s / L at arc length s, added to each point's covariance and
to a sensor's noise at its point (R_k + F(s_k)), never carried from one stamp to the next (the
nugget of kriging, a Gaussian process's white-noise term). A reading at the tip of this very
stamp has seen the tip's own white error: the tip is then estimated with the state augmented by
it (:func:`_tip_white`).

A rod in motion lags its equilibrium, which is all the model computes. A lightly damped first
bending mode (omega_1, zeta: the robot file's ``rod.damping``) driven by an equilibrium whose tip
starts moving at speed v swings about it with amplitude v / omega_1 (the ramp response of a
second-order system; a steady ramp leaves 2 zeta v / omega_1), and the swing decays as
exp(-zeta omega_1 t) once the equilibrium stops. The estimate carries that amplitude
(``Unmodelled.swing``: the larger of the model tip's speed while the cables move over omega_1
and the last amplitude decayed, :func:`_swung`) and adds it to the white error at the tip as
the smallest sphere whose 95 % ellipsoid holds a swing of that amplitude at every phase and in
every direction: variance swing^2 / chi2_3(0.95) on each axis, s / L of it along the rod (its
direction and phase are not tracked: the stamps of a 30 Hz estimate are a third of a 10 Hz
swing's period apart). An upper bound: the rod's tendons stiffen it above the bare rod's
omega_1, and motors that speed up smoothly excite less than a step in speed. A file without the
rod's damping has none.

With the robot file's ``load_model`` the tip load is part of the state too, ahead of the
unmodelled loads: the parameters p of its :class:`~continuum_statics.core.estimation.
load_estimation.LoadModel` (a payload's mass, a force along a direction, a force, a wrench; w =
B p), with the model's prior N(0, diag(load_prior^2)). A load does not fade like the model's
error: it is held, mean and variance, while the readings agree with it (a payload or a contact
stays while the model's error follows the motion, and only that persistence tells the two apart
to a tip tracker: both move its point the same way; a load that changes as fast as the model's
error left a 20 g payload's sigma at 46 of its 50 g prior after 60 s of readings). A reading
the gate sets aside is held (at rest, one beyond the hold gate too,
:data:`~continuum_statics.core.estimation.gates.HOLD_PROBABILITY`); when the same sensor's
next reading, as far off, agrees with it (a new load
moves every reading from then on, an outlier one) and a new load explains it (the load's
variance back at its prior: a payload taken, a contact made), the load starts again from
there, and the reading is used. The model is solved at
the load estimated so far (the tip load the caller gives plus B p), and the load's columns are
derivatives there (:data:`LOAD_COLUMN_STEP`): the first-order correction below is about that
point, ``Unmodelled.origin``, so a load far from zero is not a linearisation far from the
estimate. Each reading is judged once and counted once, for the shape, the model's error and
the load together.

The shape under d is, to first order about the model's estimate (d = 0),

    r(s; d) = r(s) + G_r(s) d,  theta(s; d) = G_theta(s) d   (a small rotation of R(s))

with G's columns the central differences of the estimator itself over each load's prior (its inputs
moved: lengths - d_L, tip load + d_f, d_m; :data:`COLUMN_STEP`). A sensor at arc length s_k with
offset o_k in the rod's frame reads y_k = r(s_k) + R(s_k) o_k (and R(s_k) for a pose sensor) plus
noise R_k = diag(sigma^2). The maximum a posteriori d of the linearised problem, and its
covariance, are the Kalman update (the Gauss-Newton step of Rucker & Webster's probabilistic
estimator, IEEE T-RO 2011, on these unknowns):

    S = H P H^T + R,  K = P H^T S^-1,  mean+ = mean + K nu,  P+ = (I - K H) P

with nu = y - h(mean) the innovation. Each reading is first judged on its own: its normalised
innovation squared nu^T S^-1 nu against the chi-square gate of its degrees of freedom
(:data:`~continuum_statics.core.estimation.gates.SENSOR_GATE_PROBABILITY`); a reading that fails it
is set aside with the reason (:class:`~continuum_statics.core.description.sensors.SensorVerdict`).
The
published covariance of each backbone point is G_r P+ G_r^T.

Cost: the model's estimate plus, per call, at most one column of G (a warm-started estimate,
once the tip moved :data:`COLUMN_DISTANCE` of the rod's length from where that column was
made); every column when nothing is cached or, for an estimate solved to the end, once the tip
moved more than :data:`REFRESH_DISTANCE`. The covariances are computed when read.

A reading stamped before the estimate (an EM tracker's 30 ms latency, an optical tracker's
frames arriving after the encoders') is compared with the model of its own stamp: the estimate
keeps the model's shapes and load columns of the last :data:`HISTORY_SECONDS` (and the newest
before them), and the prediction and H of a late reading are interpolated between the two that
bracket its stamp. A reading stamped before every kept estimate (the first estimate's, or one
older than that span) has no model of its time and is set aside.
The unmodelled loads themselves change slowly (their correlation time), so the update applies
to them now.
"""
import bisect
from dataclasses import dataclass
import functools
import math

import numba
import numpy as np

from continuum_statics.core.description.layout import POSITION_AT, ROTATION_AT
from continuum_statics.core.description.sensors import SensorVerdict, as_reading
from continuum_statics.core.estimation import gates, shape_estimation
from continuum_statics.core.estimation.load_estimation import tension_sigma
from continuum_statics.core.rod.rotations import rotation_vector_into

#: The tip may move this fraction of the rod's length from where the load columns were made
#: before an estimate solved to the end makes them all again (a tracking call refreshes one
#: column per call instead: bounded work).
REFRESH_DISTANCE = 0.02
#: A tracking call refreshes the next load column once the tip moved this fraction of the rod's
#: length from where that column was made (a robot at rest keeps its columns: no solves).
COLUMN_DISTANCE = 0.01
#: ... at most one column every this many calls (a node at 1 kHz: ~7 columns a second; a
#: column is two bounded solves, which must stay out of the 99th percentile).
COLUMN_EVERY = 150
#: How far (in sigmas of the model uncertainty, along its direction) the correction at a
#: sensor may go before its readings are set aside (a slow drift): 3, a 0.3 % chance that an
#: honest model error lies beyond.
CORRECTION_SIGMAS = 3.0
#: Central-difference step of an ideal cable's length column, as a fraction of its prior sigma:
#: small enough that the moved lengths still fit a shape (one sigma of one cable does not: a
#: slack solve), large against the solver's tolerance; ideal cables act through geometry,
#: smooth at the estimate. Every other column steps one sigma each way, the slope over the
#: prior's range: a real tendon's length acts through stretch, slack and friction's stick zone,
#: which a derivative at the estimate misses (simulated truth: 95 % ellipsoids held 98.8 % of
#: the cases with derivatives, 94.8 % with these steps).
COLUMN_STEP = 1e-3
#: Central-difference step of a tip-load column, as a fraction of the load's prior sigma: a
#: derivative at the load estimated so far (the model is solved there).
LOAD_COLUMN_STEP = 1e-3
#: A tip-load update that moves the load further than this many of its posterior sigmas from
#: where the model was solved is done again there (the columns' linear range), at most
#: LOAD_ITERATIONS times in a call (a payload hung, a contact made: 2-4 iterations).
LOAD_LINEAR = 0.5
LOAD_ITERATIONS = 8
#: ... and this many in a call with a per-call bound (a node at 1 kHz: the next call, solved at
#: the load this one reached, goes on).
BOUNDED_LOAD_ITERATIONS = 2
#: A cable length that moved this far (m) from where the cables last moved is motion, and no
#: new tip load is taken until LOAD_SETTLE s after the last motion (a moving or swinging rod is
#: no statics).
LOAD_MOTION = 5e-5
LOAD_SETTLE = 1.0
#: A reading held as a possible new tip load expires after this many s.
PENDING_SECONDS = 1.0
#: s of the model's estimates kept for late readings (an EM tracker's latency is 10-50 ms, a
#: camera's up to a few hundred); a reading older than every kept estimate is set aside.
HISTORY_SECONDS = 0.5
#: ... one every this many s at most (the newest always): a 1 kHz node keeps ~100, not 500.
HISTORY_SPACING = 0.005
#: ... and at most this many of them.
HISTORY_LENGTH = 128
#: chi2_3(0.95): a swing of amplitude A lies on the 95 % ellipsoid of variance A^2 / it
SWING_SPREAD = gates.chi2_quantile(0.95, 3)
#: Unmodelled-load groups, in the order of d: name, size (None: one per cable), unit.
#: The tip load's parameters (the file's load_model) come first, before these.
GROUPS = (('tip_force', 3, 'N'), ('section_moment', 3, 'N m'), ('cable_length', None, 'm'),
          ('base_position', 3, 'm'), ('drift', 3, 'm'), ('drift_rate', 3, 'm/s'))
#: Groups whose columns are known without a solve: an offset of the whole backbone ...
_RIGID = ('base_position', 'drift')
#: ... and the drift's rate, which moves no point now.
_IDLE = ('drift_rate',)


@dataclass(frozen=True, eq=False)
class Unmodelled:
    """The unmodelled loads explained so far: their mean and covariance at a stamp.

    :ivar names: (k,) what each entry is, e.g. 'tip_force.x', 'cable_length.servo_1'
    :ivar mean: (k,) N, N m or m
    :ivar covariance: (k, k)
    :ivar stamp: s, or None
    :ivar origin: (k,) the state the model was solved at (a tip load estimated earlier, kept
        while the load stays within LOAD_LINEAR sigma of it; zero elsewhere), or None: zero
    :ivar load_basis: (6, j) B of the file's load model (its parameters are the first j
        entries), or None
    :ivar pending: ((sensor name, (position (3,) m, stamp s)), ...) of readings the gate set
        aside that a new tip load may explain: the next reading of that sensor that agrees
        renews the load (:func:`_update`)
    :ivar still: (cable lengths (n,) m, stamp s[, the model's tip (3,) m]) where the cables
        last moved: while they move and LOAD_SETTLE s after, no new tip load is taken and
        contact does not begin (:func:`_moving`); the tip times the swing (:func:`_swung`)
    :ivar point_noise: m, the model's error at the tip that no load explains (white), the robot
        file's ``model_uncertainty.point_noise`` (:meth:`point_variance`)
    :ivar load_reference: (j,) the tip load taken when its variance was last at its prior (the
        first reading fused, a renewal), or None: the drift guard judges its change since then
        with the model's error (:func:`_update`)
    :ivar swing: m, the amplitude of the rod's swing about the model's equilibrium at the tip
        (module doc, :func:`_swung`)
    :ivar tip_white: (mean (3,) m, covariance (6, 6)) of the tip's white error's share after a
        reading at the tip at this stamp (:func:`_tip_white`), or None: N(0, tip_variance)
    :ivar suspects: names of the sensors the drift guard set aside (:func:`_beyond_the_prior`)
        and not taken back since (a reading of theirs used): they do not renew the tip load
    """

    names: tuple
    mean: np.ndarray
    covariance: np.ndarray
    stamp: float = None
    origin: np.ndarray = None
    load_basis: np.ndarray = None
    pending: tuple = ()
    still: tuple = None
    point_noise: float = 0.0
    load_reference: np.ndarray = None
    swing: float = 0.0
    tip_white: tuple = None
    suspects: tuple = ()

    @property
    def correction(self):
        """(k,) the state less the point the model was solved at: what moves the shape."""
        return self.mean if self.origin is None else self.mean - self.origin

    @property
    def tip_wrench(self):
        """(6,) [force N; moment N m] of the tip load, base frame; None without a load model."""
        if self.load_basis is None:
            return None
        return self.load_basis @ self.mean[:self.load_basis.shape[1]]

    @property
    def tip_wrench_covariance(self):
        """(6, 6) of :attr:`tip_wrench`; None without a load model."""
        if self.load_basis is None:
            return None
        j = self.load_basis.shape[1]
        return self.load_basis @ self.covariance[:j, :j] @ self.load_basis.T

    @property
    def sigma(self):
        """(k,) standard deviations."""
        return np.sqrt(np.diag(self.covariance))

    @property
    def tip_variance(self):
        """The variance (m^2, each axis) of the model's white error at the tip.

        :attr:`point_noise` squared plus the swing's, swing^2 / chi2_3(0.95) (module doc).
        """
        return self.point_noise ** 2 + self.swing ** 2 / SWING_SPREAD

    def point_variance(self, shape, s):
        """Return the variance (m^2, each axis) of the model's white error at arc lengths ``s``.

        :attr:`tip_variance` at the tip, growing as (s / L)^2 from the clamped base (zero
        there): the error of a rod bent by what the model misses grows along it.
        """
        tip = self.tip_variance
        if not tip:  # most files at rest: no array work per reading
            return 0.0 if np.ndim(s) == 0 else np.zeros(len(s))
        return white_sigma(math.sqrt(tip), s, shape.s[-1]) ** 2

    def as_dict(self):
        """{name: (mean, sigma)} for reports."""
        return {name: (float(m), float(s)) for name, m, s in zip(self.names, self.mean,
                                                                 self.sigma)}


@dataclass(frozen=True, eq=False)
class Sensitivity:
    """The estimate's first-order response to the unmodelled loads (kept between calls).

    :ivar positions: (N, 3, k) d r(s_i) / d d at every node
    :ivar angles: (N, 3, k) d theta(s_i) / d d (small rotations, base frame)
    :ivar tips: (k, 3) the tip position each column was made at (m)
    :ivar rest: calls since a column was last made
    :ivar tensions: (n, k) d T / d d of the model's tensions at the motors, or None (a model
        without tendons)
    """

    positions: np.ndarray
    angles: np.ndarray
    tips: np.ndarray
    rest: int = 0
    tensions: np.ndarray = None


def group_sigma(uncertainty, group):
    """Return one group's stationary standard deviation (the drift's rate: lambda sigma_w)."""
    if group == 'drift_rate':
        return (math.sqrt(3.0) / uncertainty.drift_time * uncertainty.drift
                if uncertainty.drift > 0.0 else 0.0)
    return getattr(uncertainty, group)


@functools.lru_cache(maxsize=64)
def prior_scales(robot):
    """Return (names, sigma (k,)) of the state: the tip load's, then unmodelled loads'.

    The unmodelled loads with a nonzero prior only.
    """
    uncertainty = robot.model_uncertainty
    names, sigmas = list(_load_names(robot.load_model)), list(_load_prior(robot))
    for group, size, _ in GROUPS:
        sigma = group_sigma(uncertainty, group)
        if sigma <= 0.0:
            continue
        labels = robot.cable_names if size is None else ('x', 'y', 'z')
        names.extend('%s.%s' % (group, label) for label in labels)
        sigmas.extend([sigma] * len(labels))
    sigmas = np.array(sigmas)
    sigmas.setflags(write=False)
    return tuple(names), sigmas


def _load_names(model):
    """Return the names of a load model's parameters in the state ('tip_load.mass', ...)."""
    if model is None:
        return ()
    if model.name in ('weight', 'direction'):
        return ('tip_load.mass' if model.name == 'weight' else 'tip_load.force',)
    axes = [('force', axis) for axis in 'xyz'] + (
        [('moment', axis) for axis in 'xyz'] if model.name == 'wrench' else [])
    return tuple('tip_load.%s_%s' % pair for pair in axes)


def _load_prior(robot):
    """Return (j,) the load model's prior standard deviations (none without one)."""
    return () if robot.load_model is None else tuple(robot.load_model.prior)


def load_size(robot):
    """Return how many of the state's first entries are the tip load's parameters."""
    return 0 if robot.load_model is None else robot.load_model.basis.shape[1]


def propagate(robot, carried, stamp):
    """Return the state at ``stamp`` from the last estimate's (:func:`decayed`)."""
    names, prior = _prior(robot)
    basis = None if robot.load_model is None else robot.load_model.basis
    floor = robot.model_uncertainty.point_noise
    if carried is None or carried.names != names:
        return Unmodelled(names, np.zeros(len(names)), prior, stamp, load_basis=basis,
                          point_noise=floor)
    if stamp is None or carried.stamp is None:
        return _evolved(carried, stamp=carried.stamp if stamp is None else stamp,
                        load_basis=basis, point_noise=floor, tip_white=None)
    # an older stamp is not a step back in time
    mean, covariance = decayed(carried.mean, carried.covariance, prior,
                               max(stamp - carried.stamp, 0.0),
                               robot.model_uncertainty.correlation_time, _drift_time(robot),
                               load_size(robot))
    return _evolved(carried, mean=mean, covariance=covariance, stamp=stamp,
                    load_basis=basis, point_noise=floor, tip_white=None)


def _moved_variance(robot, elapsed):
    """Return (k, k) the variance the state's process adds over ``elapsed`` s."""
    names, prior = _prior(robot)
    zero = np.zeros(len(names))
    return decayed(zero, np.zeros_like(prior), prior, elapsed,
                   robot.model_uncertainty.correlation_time, _drift_time(robot),
                   load_size(robot))[1]


def _drift_time(robot):
    """Return the drift's length scale (s), or None when the robot has no drift."""
    uncertainty = robot.model_uncertainty
    return uncertainty.drift_time if uncertainty.drift > 0.0 else None


@functools.lru_cache(maxsize=64)
def _prior(robot):
    """Return (names, P0 (k, k)) of the robot's unmodelled loads."""
    names, sigma = prior_scales(robot)
    prior = np.diag(sigma ** 2)
    prior.setflags(write=False)
    return names, prior


def decayed(mean, covariance, prior, elapsed, correlation_time, drift_time=None, held=0):
    """Return (mean, covariance) ``elapsed`` s later, towards their stationary N(0, prior).

    Ornstein-Uhlenbeck with ``correlation_time``; with ``drift_time`` the last six entries are
    the drift and its rate (x, y, z each), moved by the Matern 3/2 transition (module doc).
    The first ``held`` entries (the tip load) are held: mean and variance.
    """
    if drift_time is None:  # a diagonal transition T = diag(t): P <- t t^T (P - P0) + P0
        if not held:
            a = math.exp(-elapsed / correlation_time)
            return a * mean, a * a * covariance + (1.0 - a * a) * prior
        t, outer = _held_transition(len(mean), held, round(float(elapsed), 9),
                                    correlation_time)
        return t * mean, outer * (covariance - prior) + prior
    # a node's steps repeat (1 ms at 1 kHz) up to the clock's rounding: one cached transition
    transition = _transition(len(mean), round(float(elapsed), 9), correlation_time, drift_time,
                             held)
    # T (P - P0) T^T + P0 keeps a held block as it is
    return transition @ mean, transition @ (covariance - prior) @ transition.T + prior


@functools.lru_cache(maxsize=256)
def _held_transition(size, held, elapsed, correlation_time):
    """Return (t (size,), t t^T) of a diagonal transition: 1 on the held entries, else a."""
    t = np.full(size, math.exp(-elapsed / correlation_time))
    t[:held] = 1.0
    outer = np.outer(t, t)
    t.setflags(write=False)
    outer.setflags(write=False)
    return t, outer


@functools.lru_cache(maxsize=256)
def _transition(size, elapsed, correlation_time, drift_time, held=0):
    """Return the (size, size) transition of :func:`decayed`."""
    transition = np.eye(size) * math.exp(-elapsed / correlation_time)
    transition[:held, :held] = np.eye(held)
    lam = math.sqrt(3.0) / drift_time
    e = math.exp(-lam * elapsed)
    offset = np.arange(size - 6, size - 3)  # each axis's offset; its rate three further on
    transition[offset, offset] = e * (1.0 + lam * elapsed)
    transition[offset, offset + 3] = e * elapsed
    transition[offset + 3, offset] = -e * lam * lam * elapsed
    transition[offset + 3, offset + 3] = e * (1.0 - lam * elapsed)
    transition.setflags(write=False)
    return transition


def _evolved(record, **changes):
    """Return a copy of a frozen dataclass ``record`` with ``changes`` (``dataclasses.replace``).

    Without its per-field work: three records a call at 1 kHz took ~35 us of ~300 (these
    records have no ``__post_init__``). The fields alone are copied: a cached property (a
    :class:`ShapeEstimate`'s covariances) is computed again for the copy.
    """
    fields = record.__dataclass_fields__
    unknown = changes.keys() - fields.keys()
    if unknown:
        raise TypeError('%s has no field %s' % (type(record).__name__, ', '.join(unknown)))
    copy = object.__new__(type(record))
    if len(record.__dict__) == len(fields):  # nothing cached: one C-level dict copy
        copy.__dict__.update(record.__dict__)
    else:
        copy.__dict__.update((name, value) for name, value in record.__dict__.items()
                             if name in fields)
    copy.__dict__.update(changes)
    return copy


def _solve(spread, vector):
    """Return spread^-1 vector of a small symmetric positive definite matrix.

    One LU solve: a Cholesky factor and its two triangular solves took 37 us against 13 (3 x 3).
    """
    return np.linalg.solve(spread, vector)


def fused(mean, covariance, jac, innovation, noise):
    """Return (mean, covariance) after the Kalman update with rows ``jac`` (the module's)."""
    spread = jac @ covariance @ jac.T + noise
    gain = np.linalg.solve(spread, jac @ covariance).T
    # Joseph form: stays symmetric positive semi-definite in floating point
    keep = np.eye(len(mean)) - gain @ jac
    covariance = keep @ covariance @ keep.T + gain @ noise @ gain.T
    return mean + gain @ innovation, 0.5 * (covariance + covariance.T)


def estimate_state(robot, lengths, tip_force, tip_moment, tensions, sensors, stamp, start,
                   jacobians, previous, tracking):
    """Return the fused estimate (an :class:`shape_estimation.ShapeEstimate` with covariances).

    Arguments as :func:`shape_estimation.estimate_shape`, plus ``sensors`` ({name: reading}) and
    ``stamp`` (s). ``previous`` carries the unmodelled loads and the load columns.
    """
    readings = _readings(robot, sensors)
    prior = propagate(robot, getattr(previous, 'unmodelled', None), stamp)
    j = load_size(robot)
    anchor = prior.still  # where the cables last moved before this call
    if j or robot.description.rod.first_mode_damping:  # a load to hold, a swing to time
        prior = _moving(prior, lengths, stamp, tracking)
    carried = getattr(previous, 'sensitivity', None)
    if j and (prior.origin is None or not _within_linear_range(prior, j)):
        # the model solved at the tip load estimated so far (module doc); kept while the load
        # stays within its columns' linear range (the same tip load: a warm solve's work)
        prior = _solved_at(prior, prior.mean, j)
    bounded = tracking is not None and bool(tracking.max_model_runs)
    swing, since = prior.swing, getattr(getattr(previous, 'unmodelled', None), 'stamp', None)
    for _ in range((BOUNDED_LOAD_ITERATIONS if bounded else LOAD_ITERATIONS) if j else 1):
        if j:
            wrench = robot.load_model.basis @ prior.origin[:j]
            force, moment = tip_force + wrench[:3], tip_moment + wrench[3:]
        else:
            force, moment = tip_force, tip_moment
        model = shape_estimation.estimate_shape(robot, lengths, force, moment, tensions, start,
                                                jacobians, previous, tracking)
        if not len(prior.mean):
            verdicts = {name: SensorVerdict(False, math.nan, 'the robot file gives no '
                                            'model_uncertainty to correct')
                        for name in (sensor.name for sensor in readings)}
            return _evolved(model, unmodelled=prior, sensors=verdicts)
        sensitivity = _sensitivity(robot, model, lengths, force, moment, tensions, carried,
                                   prior, tracking)
        prior = _swung(robot, prior, swing, since, anchor, model.shape.tip_position)
        history = _history(getattr(previous, 'history', ()), stamp, model.shape, sensitivity,
                           prior.origin)
        posterior, verdicts = _update(
            robot, model.shape, sensitivity, prior, readings, stamp, history,
            _tension_measurement(robot, model, sensitivity, prior, tensions))
        if not j or _within_linear_range(posterior, j):
            break
        # the load moved beyond the linear range of its columns: solve the model there and
        # update again from the same prior (an iterated Kalman update: Gauss-Newton on the
        # maximum a posteriori load; Bell & Cathey 1993)
        prior = _solved_at(prior, posterior.mean, j)
        # the columns are made again where the tip moved far (REFRESH_DISTANCE) when solved to
        # the end; a bounded call keeps them (a chord iteration: the model itself is solved at
        # the new load each time), so a node's call stays bounded
        carried = sensitivity
    shape = _corrected(model.shape, sensitivity, posterior.correction, posterior.tip_white)
    tensions_verdict = verdicts.pop(TENSIONS, None)
    return _evolved(model, shape=shape, unmodelled=posterior, sensors=verdicts,
                    tensions_verdict=tensions_verdict, sensitivity=sensitivity,
                    history=history)


def _moving(prior, lengths, stamp, tracking):
    """Return ``prior`` with ``still`` updated: where and when the cables last moved.

    A cable that moved more than LOAD_MOTION (or 5 sigma of the encoders) from where the
    cables last moved is motion; the statics model has no dynamics, so a moving rod (and one
    still swinging, LOAD_SETTLE s after) looks loaded: no new load is taken then (the readings
    of a moving robot never agree anyway), and contact does not begin. The held load is still
    updated: holding it through motion (its uncertainty considered in the gain) let its wide
    prior explain every tracker reading of the v6 run, whose rows all follow a motion: the
    fused tip fell back to the model's, 10.5 mm against 3.0 mm on the 1/1 rows; holding it
    without its uncertainty in the gain gave 15.7 mm against 11.9 on 40/40.
    """
    if stamp is None or lengths is None or not len(lengths):
        return prior
    lengths = np.asarray(lengths, dtype=float)
    threshold = max(LOAD_MOTION, 5.0 * getattr(tracking, 'length_noise', 0.0))
    if prior.still is None or prior.still[0].shape != lengths.shape:
        return _evolved(prior, still=(lengths.copy(), -math.inf))
    if np.max(np.abs(lengths - prior.still[0])) > threshold:
        return _evolved(prior, still=(lengths.copy(), stamp))
    return prior


def _swung(robot, prior, swing, since, anchor, tip):
    """Return ``prior`` with its swing (module doc) at its stamp and the model's ``tip`` (3,) m.

    ``swing`` (m) was the amplitude at ``since`` (s, the last call); it decays by
    exp(-zeta omega_1 dt). When the cables moved this call (:func:`_moving`: beyond their
    noise since they last moved, at ``anchor``) the model tip's speed since then over omega_1
    may raise it; the tip is kept with the anchor for the next. Between two such calls the
    speed is not judged: the model tip of a still robot moves with the encoders' noise alone
    (0.3 mm in a 1 ms step is 0.3 m/s). A motion's first call after a rest is judged over the
    time since the call before plus 1 / omega_1 (a motion the rod cannot follow is a step,
    whose swing is the step itself), the next ones over their own time. 0 without the rod's
    damping in the robot file.
    """
    rod = robot.description.rod
    zeta = rod.first_mode_damping
    if not zeta:
        return prior
    omega = rod.first_mode
    stamp, still = prior.stamp, prior.still
    later = stamp is not None and since is not None and stamp > since
    if later:
        swing *= math.exp(-zeta * omega * (stamp - since))
    if still is not None and (still[1] == stamp or len(still) == 2):
        if later and anchor is not None and len(anchor) > 2 and stamp > anchor[1]:
            elapsed = min(stamp - anchor[1], stamp - since + 1.0 / omega)
            speed = float(np.linalg.norm(tip - anchor[2])) / elapsed
            swing = max(swing, speed / omega)
        still = still[:2] + (np.array(tip, dtype=float),)
    return _evolved(prior, swing=swing, still=still)


def cables_settling(state):
    """Return True while the cables moved under LOAD_SETTLE s ago: no new load, no contact."""
    return (state.still is not None and state.stamp is not None
            and state.stamp - state.still[1] < LOAD_SETTLE)


def _solved_at(prior, mean, j):
    """Return ``prior`` with its origin at the tip load of ``mean`` (zero elsewhere)."""
    origin = np.zeros(len(mean))
    origin[:j] = mean[:j]
    return _evolved(prior, origin=origin)


def _within_linear_range(state, j):
    """Return True when the state's load is within LOAD_LINEAR sigma of where it was solved."""
    moved = state.mean[:j] - state.origin[:j]
    return bool((moved * moved <= LOAD_LINEAR ** 2 * state.covariance.diagonal()[:j]).all())


def _history(carried, stamp, shape, sensitivity, origin=None):
    """Return the model's estimates of the last HISTORY_SECONDS up to this one (oldest first).

    The oldest kept is the newest at least HISTORY_SECONDS old, so the two kept around any
    stamp of that span bracket it (a client at 1 Hz keeps the one before); the newest before
    this one goes when it is within HISTORY_SPACING of the one before it, and one of this very
    stamp (estimated again) gives way. Each entry: (stamp, shape, sensitivity, the state it was
    solved at). Without a stamp there is no history; a stamp before the newest kept (a replay
    started again, a clock reset) starts it again.
    """
    if stamp is None:
        return ()
    if carried and carried[-1][0] > stamp:
        carried = ()
    if carried and carried[-1][0] == stamp:
        carried = carried[:-1]  # this stamp estimated again (refined): the new one stands
    if len(carried) > 1 and carried[-1][0] - carried[-2][0] < HISTORY_SPACING - 1e-9:
        carried = carried[:-1]
    first = 0
    while first + 1 < len(carried) and carried[first + 1][0] <= stamp - HISTORY_SECONDS:
        first += 1  # usually one a call: the history moves on with the stamps
    first = max(first, len(carried) - HISTORY_LENGTH + 1)
    return carried[first:] + ((stamp, shape, sensitivity, origin),)


def _rows_at(history, stamp, sensor, shape, sensitivity, origin=None):
    """Return ``sensor``'s (prediction, H, rotation, shift) of the model at ``stamp`` (d = 0).

    Interpolated between the kept estimates that bracket ``stamp``; the current estimate when
    ``stamp`` (or the estimate's) is None or not before it. None for a stamp before every kept
    estimate: no model of its time (a tracker's reading 30 ms older than the first estimate,
    taken while the rod moved, was once compared with the model 17 mm away from it, fused, and
    then every honest reading was set aside for the 17 mm it had put in the estimate).
    ``shift`` (rows of H) brings a kept estimate solved at another state (a tip load since
    relinearised) to the current ``origin``: H_k (origin - origin_k), zero without a load;
    None when the rows are the current estimate's.
    """
    if stamp is None or not history or stamp >= history[-1][0]:
        return (*sensor_rows(shape, sensitivity, sensor), None)
    if stamp < history[0][0]:
        return None
    after = max(bisect.bisect_left(history, stamp, key=lambda moment: moment[0]), 1)
    (t0, shape0, sens0, origin0), (t1, shape1, sens1, origin1) = (history[after - 1],
                                                                  history[after])
    k = sensitivity.positions.shape[2]
    if sens0.positions.shape[2] != k or sens1.positions.shape[2] != k:
        return (*sensor_rows(shape, sensitivity, sensor), None)  # other unmodelled loads then
    w = min(max((stamp - t0) / (t1 - t0), 0.0), 1.0) if t1 > t0 else 1.0
    point0, jac0, rotation0 = sensor_rows(shape0, sens0, sensor)
    point1, jac1, rotation1 = sensor_rows(shape1, sens1, sensor)
    shift = np.zeros(len(jac0))
    if origin is not None:
        shift = ((1.0 - w) * jac0 @ (origin - origin0) + w * jac1 @ (origin - origin1))
    return ((1.0 - w) * point0 + w * point1, (1.0 - w) * jac0 + w * jac1,
            rotation1 if w >= 0.5 else rotation0, shift)


def stale_columns(robot, estimate):
    """Return True when ``estimate``'s load columns were made further than REFRESH_DISTANCE.

    The distance is from the model tip (the estimate's tip without its correction). A bounded
    call keeps such columns (it refreshes one every COLUMN_EVERY calls); a call solved to the
    end makes them again.
    """
    sensitivity = getattr(estimate, 'sensitivity', None)
    if sensitivity is None or not len(sensitivity.tips):
        return False
    tip = estimate.shape.tip_position - sensitivity.positions[-1] @ estimate.unmodelled.correction
    if estimate.unmodelled.tip_white is not None:  # the tip's white error moved it too
        tip = tip - estimate.unmodelled.tip_white[0]
    moved = _moved_since(robot, sensitivity.tips, tip)
    return bool(np.max(moved) > REFRESH_DISTANCE * robot.length)


def _moved_since(robot, tips, tip):
    """Return (k,) how far the tip moved since each column was made, m.

    0 for the columns known without a solve (the offset's, the drift's): no motion changes them.
    """
    return np.linalg.norm(tips - tip, axis=1) * _solved_columns(robot)


@functools.lru_cache(maxsize=64)
def _solved_columns(robot):
    """Return (k,) 1.0 for the columns made by solves, 0.0 for the offset's and the drift's."""
    names, _ = prior_scales(robot)
    solved = np.array([name.split('.')[0] not in _RIGID + _IDLE for name in names], float)
    solved.setflags(write=False)
    return solved


def _readings(robot, sensors):
    """Check ``sensors`` ({name: reading}) against the robot file's; return {Sensor: reading}."""
    if not sensors:
        return {}
    known = {sensor.name: sensor for sensor in robot.sensors}
    readings = {}
    for name, reading in dict(sensors).items():
        if name not in known:
            raise ValueError('sensor %r is not in the robot file (its sensors: %s)'
                             % (name, ', '.join(known) or 'none'))
        if reading is not None:
            readings[known[name]] = as_reading(known[name], reading)
    return readings


def _sensitivity(robot, model, lengths, tip_force, tip_moment, tensions, carried, prior,
                 tracking):
    """Return the load columns at this estimate: all of them, or the stalest one (tracking)."""
    tip = model.shape.tip_position
    size = len(prior.mean)
    fresh = (carried is None or carried.positions.shape[2] != size
             or carried.positions.shape[0] != len(model.shape.s)
             or (carried.tensions is None) != (model.tensions is None))
    bounded = tracking is not None and bool(tracking.max_model_runs)
    if not fresh and not bounded:
        moved = _moved_since(robot, carried.tips, tip)
        fresh = np.max(moved) > REFRESH_DISTANCE * robot.length
    elif not fresh and carried.rest >= COLUMN_EVERY:
        moved = _moved_since(robot, carried.tips, tip)
    if fresh:
        n = len(model.shape.s)
        carried = Sensitivity(np.zeros((n, 3, size)), np.zeros((n, 3, size)),
                              np.zeros((size, 3)), tensions=None if model.tensions is None
                              else np.zeros((len(model.tensions), size)))
        columns = range(size)
    elif (bounded and carried.rest >= COLUMN_EVERY
          and np.max(moved) > COLUMN_DISTANCE * robot.length):
        columns = [int(np.argmax(moved))]
    else:
        return _evolved(carried, rest=carried.rest + 1)
    positions, angles, tips = (carried.positions.copy(), carried.angles.copy(),
                               carried.tips.copy())
    tensions_of = None if carried.tensions is None else carried.tensions.copy()
    names, sigma = prior_scales(robot)
    for j in columns:
        tips[j] = tip
        group = names[j].split('.')[0]
        if group in _RIGID or group in _IDLE:
            positions[:, :, j] = angles[:, :, j] = 0.0
            if tensions_of is not None:  # an offset of the backbone pulls no cable
                tensions_of[:, j] = 0.0
            if group in _RIGID:
                positions[:, 'xyz'.index(names[j][-1]), j] = 1.0
            continue
        step = np.zeros(size)
        ideal = names[j].startswith('cable_length') and robot.tendons.is_ideal
        step[j] = sigma[j] * (LOAD_COLUMN_STEP if group == 'tip_load'
                              else COLUMN_STEP if ideal else 1.0)
        # central differences from the estimate's state: an unfinished estimate's error cancels
        # (every column at once, the first time: solved to the end). A step of a thousandth of
        # a sigma (the tip load's, an ideal cable's) to the end too: a node's bound stops at a
        # tenth of the encoders' noise or 1 % of the misfit, about such a step's effect (the
        # payload's mass column came out 170 % off; an ideal cable's of sigma 0.3 mm, a 0.3 um
        # step, zero: both sides stopped where they started)
        small = group == 'tip_load' or ideal
        bound = None if fresh or not bounded or small else tracking
        up, down = (_moved(robot, model, lengths, tip_force, tip_moment, tensions, sign * step,
                           bound) for sign in (1.0, -1.0))
        if up.capped or down.capped:  # a bounded solve left unfinished: keep the old column
            tips[j] = carried.tips[j]
            continue
        if tensions_of is not None:
            if up.tensions is None or down.tensions is None:
                tips[j] = carried.tips[j]  # a fall-back fit without tendons: keep the column
                continue
            tensions_of[:, j] = (up.tensions - down.tensions) / (2.0 * step[j])
        up, down = up.shape, down.shape
        positions[:, :, j] = (up.positions - down.positions) / (2.0 * step[j])
        angles[:, :, j] = _small_rotations(up.rotations, down.rotations) / (2.0 * step[j])
    return Sensitivity(positions, angles, tips, 0, tensions_of)


def _moved(robot, model, lengths, tip_force, tip_moment, tensions, load, tracking):
    """Return the estimate with the unmodelled loads ``load`` in its inputs.

    Warm-started from the estimate itself (its state, Jacobians and friction history), with the
    node's per-call bound when ``tracking``: the two sides of a central difference start from
    the same state with the same bound, so what one leaves unfinished the other does too.
    """
    force, moment, cable = split_loads(robot, load)
    return shape_estimation.estimate_shape(
        robot, np.asarray(lengths, dtype=float) - cable, np.asarray(tip_force) + force,
        np.asarray(tip_moment) + moment, tensions, model.shape.state, model.jacobians, model,
        tracking)


def split_loads(robot, load):
    """Return (tip force (3,), tip moment (3,), cable length errors (n,)) of a state vector.

    The tip load's parameters (B p) and the unmodelled tip force and moment add up.
    """
    at = load_size(robot)
    wrench = robot.load_model.basis @ load[:at] if at else np.zeros(6)
    parts = []
    for group, size, _ in GROUPS[:3]:
        size = len(robot.cable_names) if size is None else size
        if getattr(robot.model_uncertainty, group) > 0.0:
            parts.append(load[at:at + size])
            at += size
        else:
            parts.append(np.zeros(size))
    return parts[0] + wrench[:3], parts[1] + wrench[3:], parts[2]


def _small_rotations(rotations, reference):
    """Return (N, 3) base-frame rotation vectors taking ``reference`` to ``rotations``."""
    delta = np.einsum('nij,nkj->nik', rotations, reference)
    return 0.5 * np.stack([delta[:, 2, 1] - delta[:, 1, 2], delta[:, 0, 2] - delta[:, 2, 0],
                           delta[:, 1, 0] - delta[:, 0, 1]], axis=1)


def sensor_rows(shape, sensitivity, sensor):
    """Return (prediction (3,), H (3 or 6, k), rotation) of ``sensor`` at ``shape`` (d = 0)."""
    lower, upper, w, near = _placement(shape.s, sensor)
    rotation = shape.rotations[near]
    arm = rotation @ sensor.offset
    point = (1.0 - w) * shape.positions[lower] + w * shape.positions[upper] + arm
    angles = sensitivity.angles[near]
    jac = ((1.0 - w) * sensitivity.positions[lower] + w * sensitivity.positions[upper]
           + _lever(arm) @ angles)
    if sensor.kind != 'pose':
        return point, jac, rotation
    return point, np.vstack([jac, angles]), rotation


def _lever(arm):
    """Return -[arm]x (3, 3): d(R o) = theta x (R o) = -[R o]x theta for arm = R o.

    Written out: np.cross costs ~50 us here.
    """
    return np.array([[0.0, arm[2], -arm[1]], [-arm[2], 0.0, arm[0]], [arm[1], -arm[0], 0.0]])


def _placement(s, sensor):
    """Return (lower node, upper node, weight of upper, nearest node) of a sensor on grid s."""
    key = (len(s), float(s[-1]))
    cached = _PLACEMENTS.get((sensor, key))
    if cached is None:
        upper = int(np.clip(np.searchsorted(s, sensor.s, side='right'), 1, len(s) - 1))
        lower = upper - 1
        span = s[upper] - s[lower]
        w = min(max((sensor.s - s[lower]) / span if span > 0.0 else 0.0, 0.0), 1.0)
        cached = _PLACEMENTS[(sensor, key)] = (lower, upper, w, upper if w >= 0.5 else lower)
    return cached


#: Where each sensor sits on a grid (sensor objects live as long as their robot).
_PLACEMENTS = {}


def _sensor_measurement(robot, shape, sensitivity, prior, sensor, reading, stamp, history):
    """Return (value, innovation, H, noise, judged) of a sensor's reading against the state.

    The reading is predicted by the model of its own stamp (``history``, :func:`_rows_at`;
    None when no model of its time is kept);
    ``value`` is its position, which a later reading must agree with (:func:`_agrees`);
    ``judged`` the position rows at its point on the current shape (:func:`_beyond_the_prior`).
    """
    rows = _rows_at(history, reading.stamp, sensor, shape, sensitivity, prior.origin)
    if rows is None:
        return None
    predicted, jac, rotation, shift = rows
    judged = jac[:3] if shift is None else sensor_rows(shape, sensitivity, sensor)[1][:3]
    shift = np.zeros(len(jac)) if shift is None else shift
    moved = prior.correction  # what the model's shape does not have yet
    innovation = reading.position - predicted - shift[:3] - jac[:3] @ moved
    # the device's own noise wins; the model's error no load explains adds to it
    sigmas = [math.sqrt((reading.sigma or sensor.position_sigma) ** 2
                        + prior.point_variance(shape, sensor.s))] * 3
    if sensor.kind == 'pose' and reading.rotation is not None:
        angle = _small_rotations(reading.rotation[None], rotation[None])[0]
        innovation = np.concatenate([innovation, angle - shift[3:] - jac[3:] @ moved])
        sigmas += [sensor.angle_sigma] * 3
    else:
        jac = jac[:3]
    noise = np.diag(np.square(sigmas))
    if reading.stamp is not None and stamp is not None and stamp > reading.stamp:
        # an older reading: the unmodelled loads may have moved since it was taken
        noise = noise + jac @ _moved_variance(robot, stamp - reading.stamp) @ jac.T
    return reading.position, innovation, jac, noise, judged


def _tension_measurement(robot, model, sensitivity, prior, tensions):
    """Return (value, innovation, H, noise, H) of measured tensions, or None when not fused.

    Fused when the robot file gives ``tension_noise`` and its cables are real tendons: the
    lengths set the shape and the model predicts each motor's tension (a tip load shows in
    them: 10 g at the tip of a 0.3 m rod with holes 10 mm out moves them by about 3 N), so
    T = T_model + H_T d with H_T the same central differences as the shape's columns. With
    ideal cables the measured tensions make the shape instead (no prediction to compare).
    """
    if (tensions is None or robot.tension_noise is None or robot.tendons.is_ideal
            or model.tensions is None or sensitivity.tensions is None):
        return None
    tensions = np.asarray(tensions, dtype=float)
    innovation = tensions - model.tensions - sensitivity.tensions @ prior.correction
    noise = np.diag(np.square(tension_sigma(robot.tension_noise, tensions)))
    return tensions, innovation, sensitivity.tensions, noise, sensitivity.tensions


#: The verdicts' key of the measured tensions (a space: no sensor's name).
TENSIONS = 'cable tensions'


def _update(robot, shape, sensitivity, prior, readings, stamp, history=(), tensions=None):
    """Judge each reading against the prior, fuse those that pass; return (posterior, verdicts).

    ``readings``: {sensor: reading}; ``tensions``: the measured tensions'
    :func:`_tension_measurement`, or None (their verdict under :data:`TENSIONS`).
    """
    mean, covariance = prior.mean, prior.covariance
    j = load_size(robot)
    renewed, pending, changed = False, dict(prior.pending), False
    moving = bool(j) and cables_settling(prior)
    verdicts, rows, residuals, noises, used, at_tip = {}, [], [], [], {}, []
    measurements = [(sensor.name, sensor, _sensor_measurement(
        robot, shape, sensitivity, prior, sensor, reading, stamp, history),
        sensor.at_tip and (reading.stamp is None or stamp is None or reading.stamp == stamp))
        for sensor, reading in readings.items()]
    if tensions is not None:
        measurements.append((TENSIONS, None, tensions, False))
    for name, sensor, measurement, here in measurements:
        if measurement is None:
            age = stamp - readings[sensor].stamp
            verdicts[name] = SensorVerdict(False, math.inf, (
                'stamped %.3g s before this estimate, before the oldest model it keeps: no '
                'shape of its time to compare it with%s' % (age, '; is its clock synchronised?'
                                                             if age > HISTORY_SECONDS else '')))
            continue
        value, innovation, jac, noise, judged = measurement
        spread = jac @ covariance @ jac.T + noise
        chi2 = float(innovation @ _solve(spread, innovation))
        gate = gates.gate(len(innovation), gates.SENSOR_GATE_PROBABILITY)
        renewing, held = False, ''
        if (not chi2 <= gates.gate(len(innovation), gates.HOLD_PROBABILITY) and j
                and not renewed and not moving and name not in prior.suspects):
            # a new tip load (a payload hung or taken, a contact made) moves every reading
            # from then on, a noisy one alone: a reading at rest this far off is held, and the
            # next of that sensor, as far off and agreeing with it, decides if a new load
            # explains it (the load's variance back at its prior, around the load so far).
            # Held back even when the gate would pass it: used, it put a 30 g payload into
            # the model's error, and the next reading agreed with the estimate. Not a sensor
            # the drift guard set aside (with the model solved under the estimated tip force,
            # doc/state_estimation.md, a drifting tracker's jump once took a 140 g payload)
            agrees = _agrees(pending.get(name), value, noise[:len(value), :len(value)], stamp)
            if agrees:
                candidate = covariance.copy()
                candidate[:j, :] = candidate[:, :j] = 0.0
                candidate[:j, :j] = _prior(robot)[1][:j, :j]
                again = float(innovation @ _solve(jac @ candidate @ jac.T + noise, innovation))
                if again <= gate:
                    covariance, chi2, renewed = candidate, again, True
                    renewing = True
            if not renewing and not (agrees and chi2 <= gate):  # else the gate's to judge
                pending[name], changed = (value, stamp), True
                held = '; held: a new tip load if the next reading agrees'
                if chi2 <= gate:
                    verdicts[name] = SensorVerdict(False, chi2, (
                        'held back one reading at rest: innovation chi2 %.1f (%s from the '
                        'estimate)%s' % (chi2, _offset(innovation, sensor), held)))
                    continue
        if not chi2 <= gate:
            verdicts[name] = SensorVerdict(False, chi2, (
                'innovation chi2 %.1f above the gate %.1f (%s from the estimate)%s'
                % (chi2, gate, _offset(innovation, sensor), held)))
            continue
        changed = pending.pop(name, None) is not None or changed
        verdicts[name] = SensorVerdict(
            True, chi2, 'the tip load changed: its variance back at its prior' if renewing
            else '')
        rows.append(jac)
        residuals.append(innovation)
        noises.append(noise)
        used[name] = judged
        # the first tip reading of this stamp: a second one's white error is another draw
        # in the noise it was judged with (the same w in both would need their cross term)
        at_tip.append(here and not any(at_tip))
    if changed:
        prior = _evolved(prior, pending=tuple(pending.items()))
    if not rows:
        return prior, verdicts
    innovation, noise = np.concatenate(residuals), _block_diagonal(noises)
    white = _tip_white(prior, sensitivity, covariance, rows, innovation, noise, at_tip)
    mean, covariance = fused(mean, covariance, np.vstack(rows), innovation, noise)
    # the tip load a reading took while its variance was at its prior (a first reading, a new
    # load) is the load's reference; its change since then is judged with the model's error
    reference = prior.load_reference
    if j and (renewed or reference is None):
        reference = mean[:j].copy()
    # a fault slower than the gate: the correction readings add up to over calls is judged too
    # (a first correction, from nothing carried, is the gate's alone)
    correction = mean if prior.origin is None else mean - prior.origin
    if j:  # a load held is no licence: a drifting tracker walked it 15 mm at 0.5 mm/s, unnamed
        correction = np.concatenate([mean[:j] - reference, correction[j:]])
    beyond = np.any(prior.mean[j:]) and _beyond_the_prior(robot, used, correction)
    if beyond:
        for name in beyond:
            verdicts[name] = SensorVerdict(False, verdicts[name].chi2, beyond[name])
        return _evolved(prior, suspects=tuple(sorted(set(prior.suspects)
                                                     | set(beyond)))), verdicts
    return _evolved(prior, mean=mean, covariance=covariance,
                    load_reference=reference, tip_white=white, suspects=tuple(
                        name for name in prior.suspects if name not in used)), verdicts


def _tip_white(prior, sensitivity, covariance, rows, innovation, noise, at_tip):
    """Return (mean (3,) m, covariance (6, 6)) of the tip's white error's share after the update.

    A reading at the tip of this very configuration (``at_tip``: per used reading, the first
    such) carries the tip's own white error w (variance W on each axis,
    :attr:`Unmodelled.tip_variance`), which its noise already counts; the tip's pose,
    T d + [w; 0] with T = [G_r; G_theta] at the tip, is then estimated with the state augmented
    by w (Kalman's update on [d; w], H = [H_d, E]): its position moves by W E^T S^-1 nu, and its
    covariance is T P+ T^T plus the returned one, diag(W I, 0) - (a + b) S^-1 (a + b)^T
    + a S^-1 a^T with a = T P H^T, b = [W E^T; 0]. Before (W whole) a tracked row's ellipsoid
    held 100 %. None without such a reading or white error. ``covariance``: P before the
    update; ``rows``: the used H blocks; ``noise``: their R, W in it.
    """
    variance = prior.tip_variance
    if not variance or not any(at_tip):
        return None
    select = np.vstack([np.eye(len(block), 3) if here else np.zeros((len(block), 3))
                        for block, here in zip(rows, at_tip)])
    jac = np.vstack(rows)
    spread = jac @ covariance @ jac.T + noise
    tip = np.vstack([sensitivity.positions[-1], sensitivity.angles[-1]])
    seen = tip @ covariance @ jac.T  # a: the loads' share
    white = np.zeros_like(seen)
    white[:3] = variance * select.T  # b: the white error's share (it moves no angle)
    both = seen + white
    solved = np.linalg.solve(spread, np.column_stack([both.T, seen.T, innovation]))
    change = -both @ solved[:, :6] + seen @ solved[:, 6:12]
    change[:3, :3] += variance * np.eye(3)
    return white[:3] @ solved[:, 12], 0.5 * (change + change.T)


def _agrees(pending, value, noise, stamp):
    """Return True when a reading's ``value`` agrees with a ``pending`` (value, stamp) one.

    The robot at rest (the load is only renewed then), two readings of one new load differ by
    two readings' noise (``noise``: one reading's), within the gate; a held reading older than
    PENDING_SECONDS has expired.
    """
    if pending is None:
        return False
    then_value, then = pending
    if stamp is not None and then is not None and stamp - then > PENDING_SECONDS:
        return False
    difference = value - then_value
    return float(difference @ _solve(2.0 * noise, difference)) <= gates.gate(
        len(difference), gates.SENSOR_GATE_PROBABILITY)


def _rms(values):
    return float(np.sqrt(np.mean(np.square(values))))


def _offset(innovation, sensor):
    """Return how far a reading is from the estimate, in words (a sensor's mm, tensions' N)."""
    if sensor is None:
        return '%.3g N RMS' % _rms(innovation)
    return '%.1f mm' % (1e3 * float(np.linalg.norm(innovation[:3])))


def _beyond_the_prior(robot, used, correction):
    """Return {name: reason} of the used readings whose correction lies beyond the prior.

    The gate judges a reading against an estimate the same sensor already moved, so a sensor
    drifting slower than one gate walks the correction anywhere (1 mm/s: 45 mm in 45 s, every
    reading used). The correction the estimate now applies at each sensor, G m, is judged
    against what the model's uncertainty allows there (G P0 G^T, the load's rows left out):
    beyond CORRECTION_SIGMAS along its direction, the readings are set aside and the
    correction kept where it was.
    ``correction``: (k,) the model's error and the tip load's change since its reference
    (a new load is the gate's and the renewal's to judge; a load that keeps moving after it is
    judged here, against the model's error alone: a tip tracker cannot tell a slowly growing
    load from a drifting tracker). ``used``: {name: H} of the used readings, the rows each is
    judged on: a sensor's position at its point on the current shape, the tensions' (N).
    """
    p0 = _prior(robot)[1].copy()
    j = load_size(robot)
    p0[:j, :] = p0[:, :j] = 0.0
    beyond = {}
    for name, jac in used.items():
        at = jac @ correction
        size = float(np.linalg.norm(at))
        if size == 0.0:
            continue
        direction = at / size
        allowed = math.sqrt(max(float(direction @ jac @ p0 @ jac.T @ direction), 0.0))
        if size > CORRECTION_SIGMAS * allowed:
            tensions = name == TENSIONS
            scale, unit = (1.0, 'N') if tensions else (1e3, 'mm')
            beyond[name] = (
                'its readings would correct the model by %.3g %s at the %s, more than %g '
                'sigma of the model uncertainty there (%.3g %s): a drifting or biased %s?'
                % (scale * size, unit, 'cables' if tensions else 'sensor', CORRECTION_SIGMAS,
                   scale * CORRECTION_SIGMAS * allowed, unit,
                   'load cell' if tensions else 'sensor'))
    return beyond


def _block_diagonal(blocks):
    size = sum(len(block) for block in blocks)
    out, at = np.zeros((size, size)), 0
    for block in blocks:
        out[at:at + len(block), at:at + len(block)] = block
        at += len(block)
    return out


def _corrected(shape, sensitivity, mean, tip_white=None):
    """Return ``shape`` moved by the unmodelled loads ``mean`` (first order; same solver state).

    ``tip_white``: :attr:`Unmodelled.tip_white`, whose mean moves the tip's point alone.
    """
    states = shape.states.copy()
    move_states(states, sensitivity.positions, sensitivity.angles, mean)
    if tip_white is not None:
        states[-1, POSITION_AT:POSITION_AT + 3] += tip_white[0]
    return type(shape)(shape.s, states, shape.u0, shape.tip_force, shape.c, shape.d,
                       shape.state, shape.fixed_tensions)


@numba.njit(cache=True, nogil=True)
def move_states(states, positions, angles, mean):
    """Add G_r mean to each node's position and turn its rotation by G_theta mean (in place)."""
    for n in range(states.shape[0]):
        v = np.zeros(3)
        for i in range(3):
            for j in range(mean.shape[0]):
                states[n, POSITION_AT + i] += positions[n, i, j] * mean[j]
                v[i] += angles[n, i, j] * mean[j]
        turn = rotation_vector_into(v)
        rotation = states[n, ROTATION_AT:ROTATION_AT + 9].reshape(3, 3).copy()
        for i in range(3):
            for j in range(3):
                states[n, ROTATION_AT + 3 * i + j] = (turn[i, 0] * rotation[0, j]
                                                      + turn[i, 1] * rotation[1, j]
                                                      + turn[i, 2] * rotation[2, j])


def point_covariance(estimate, sensor):
    """Return the (3, 3) covariance (m^2) of ``sensor``'s point in a fused ``estimate``.

    The model's part only: add ``sensor.position_sigma ** 2`` to compare with a reading.
    """
    _, jac, rotation = sensor_rows(estimate.shape, estimate.sensitivity, sensor)
    jac = jac[:3]
    unmodelled = estimate.unmodelled
    if sensor.at_tip and unmodelled.tip_white is not None:
        rows = np.hstack([np.eye(3), _lever(rotation @ sensor.offset)])
        return jac @ unmodelled.covariance @ jac.T + rows @ unmodelled.tip_white[1] @ rows.T
    floor = unmodelled.point_variance(estimate.shape, sensor.s)
    return jac @ unmodelled.covariance @ jac.T + floor * np.eye(3)


def white_sigma(point_noise, s, length):
    """Return the sigma (m, each axis) of the model's white error at arc lengths ``s`` (m).

    ``point_noise`` at the tip, growing as s / L (``length``) from the clamped base (zero there).
    """
    return point_noise * np.clip(np.asarray(s, dtype=float) / length, 0.0, 1.0)
