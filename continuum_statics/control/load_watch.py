"""What the tip_load_estimator decides (no ROS): inputs, when to solve, what is published, contact.

One entry point per timer tick, :meth:`LoadWatch.step`, given the newest inputs and a solver:

1. inputs: the fresh cable lengths, tensions and tracked tip; none that sees a load -> a reason;
2. gates before the solve: a tension above its cable's ``tension_limits`` (plus 3 sigma of
   noise) is not a reading of this robot (a bridge reporting mN, a faulty load cell): set aside;
   while the cables move (and ``contact_min_time`` after), the last estimate at rest is held
   (still solved, every ``HELD_SOLVE_PERIOD``: the warm start follows each cable's friction
   direction): the model is a
   statics model, and friction turning in a reversed cable is no load;
3. an input within ``UNCHANGED_SIGMAS`` of the one last solved, once a re-solve no longer moves
   the estimate -> the last estimate unchanged (an unchanged measurement gives an unchanged
   estimate, and costs nothing);
4. the solve, warm-started from the last estimate that passed the gates (a set-aside one would
   keep the next on its branch);
5. gates after it: not finite, not converged (a capped or failed solve), or the chi-square gate
   (:meth:`~continuum_statics.core.estimation.load_estimation.WrenchEstimate.explains`:
   measurements the
   model cannot explain at their stated noise, e.g. a tracker the tensions contradict) -> set
   aside with the reason, never published as a load (the last published one holds); an
   estimate within its own 3 sigma of the published load is that load (``SAME_LOAD``);
6. contact (:class:`~continuum_statics.control.contact.ContactDetector`): a consistent force
   over ``contact_min_time``, never begun while the cables move.
"""
from dataclasses import dataclass
import enum

import numpy as np

from continuum_statics.control.contact import ContactDetector
from continuum_statics.core.estimation import gates
from continuum_statics.core.estimation.load_estimation import tension_sigma

#: An input closer than this many of its noise standard deviations to the one last solved is
#: unchanged: re-solving it could only move the estimate by noise of noise.
UNCHANGED_SIGMAS = 1.0
#: A re-solve of an unchanged measurement that moves the estimate by less than this many of its
#: standard deviations has reached the fixed point: later ones are not solved.
SETTLED_SIGMAS = 0.1
#: A new estimate within this chi-square quantile (3 sigma) of the published one, by its own
#: covariance, is the same load: the published one holds. A load changes only when the
#: measurements say so beyond their noise: a configuration that barely sees the load (sigma
#: 0.9 N) gave (0.69, 0.13, -1.10) N for a hidden (0.12, -0.08, 0), published as the load:
#: statics found no shape under it and goals after it failed 46-165 mm away.
SAME_LOAD = gates.THREE_SIGMA
#: A cable length that moves by more than this many noise standard deviations is motion: the
#: cables are moving, the last estimate at rest holds and contact may not begin.
#: Five: noise alone exceeds it between two readings once in ~10^5 (the difference of two
#: readings has sigma sqrt(2)).
MOVING_SIGMAS = 5.0
#: Tension readings above their cable's upper limit by more than this many noise standard
#: deviations are not readings of this robot.
LIMIT_SIGMAS = 3.0
#: While the cables move, the held estimate's warm start is solved at most once in this many
#: seconds (it only follows each cable's friction direction; the estimate is not published).
#: Solved at every tick (up to 100 Hz) it took 4.1-4.5 s of a core over the README set-up's
#: ten goals, 245-416 solves; at this period 2.1-2.8 s, 121-138 (statics shares the 2 cores).
HELD_SOLVE_PERIOD = 0.05


class Verdict(enum.Enum):
    """What one tick decided."""

    NO_INPUT = 'no input'          # nothing fresh that sees a load (reason says what)
    UNCHANGED = 'unchanged'        # the input equals the one last solved: the same estimate
    HELD = 'held'                  # the cables move: the last estimate at rest, unchanged
    PUBLISH = 'publish'            # a new estimate to publish
    SET_ASIDE = 'set aside'        # the input or its estimate was rejected (reason says why):
    #                                the last published estimate holds (published again)


@dataclass(frozen=True)
class Outcome:
    """Result of :meth:`LoadWatch.step`."""

    verdict: Verdict
    estimate: object = None  # the estimate to publish (PUBLISH, UNCHANGED, HELD; SET_ASIDE:
    #                          the last published one, None before the first)
    reason: str = ''
    contact_changed: bool = False


@dataclass(frozen=True)
class Inputs:
    """The newest measurements and when they arrived (monotonic s); None where absent."""

    lengths: np.ndarray = None
    tensions: np.ndarray = None
    cables_received: float = -np.inf
    tip_position: np.ndarray = None
    tip_rotation: np.ndarray = None
    tip_received: float = -np.inf


class LoadWatch:
    """The estimator node's decisions, with the last published estimate and the contact state.

    :param robot: the robot (cable names, tendon model, tension limits)
    :param contact_threshold: N
    :param contact_min_time: s a contact decision must hold
    """

    def __init__(self, robot, contact_threshold, contact_min_time):
        self.robot = robot
        self.contact = ContactDetector(contact_threshold, contact_min_time)
        self.estimate = None  # the last estimate that passed the gates (the warm start)
        self.published = None  # the last estimate at rest (what is published)
        self._solved = None  # the measurement vector the last estimate was solved from
        self._settled = False  # re-solving that measurement no longer moves the estimate
        self._rejected = None  # (measurement vector, reason) of the last one set aside
        self._still = None  # (lengths, monotonic s): where the cables last stopped moving
        self._held_solved = None  # monotonic s of the last solve while the cables moved

    def measurements(self, inputs, now, timeout, use_tip_pose):
        """Return (keyword arguments of estimate_tip_wrench, '') or (None, reason)."""
        kwargs = {}
        if inputs.lengths is not None and now - inputs.cables_received <= timeout:
            kwargs['lengths'] = inputs.lengths
            if inputs.tensions is not None:
                kwargs['tensions'] = inputs.tensions
        if inputs.tip_position is not None and use_tip_pose and \
                now - inputs.tip_received <= timeout:
            kwargs['tip_position'] = inputs.tip_position
            if inputs.tip_rotation is not None:
                kwargs['tip_rotation'] = inputs.tip_rotation
        if 'tensions' in kwargs or 'tip_position' in kwargs:
            return kwargs, ''
        if not len(self.robot.cable_names):
            return None, 'no tip_pose_measured: a rod without cables is sensed at its tip'
        return None, ('no measurement that sees a tip load: cable_states carries no tensions '
                      '(effort) and no tip_pose_measured arrives')

    def step(self, kwargs, noise, now, solve):
        """Decide one tick on the measurements ``kwargs`` (see the module docstring).

        :param noise: the noise levels (``estimate_tip_wrench``'s ``noise``)
        :param now: monotonic s
        :param solve: ``solve(warm_start, **kwargs)`` -> WrenchEstimate; may raise ValueError
        """
        reason = self._beyond_limits(kwargs.get('tensions'), noise)
        if reason:
            return self._set_aside(reason)
        moving = self._moving(kwargs.get('lengths'), noise, now) and self.published is not None
        if moving:
            return self._held(kwargs, now, solve)
        self._held_solved = None
        vector, sigma = _measurement_vector(kwargs, noise)
        unchanged = _within(vector, self._solved, UNCHANGED_SIGMAS * sigma)
        if self._rejected is not None and _within(vector, self._rejected[0],
                                                  UNCHANGED_SIGMAS * sigma):
            return self._set_aside(self._rejected[1])  # the same verdict, not solved again
        if unchanged and self._settled:
            return Outcome(Verdict.UNCHANGED, self.published,
                           contact_changed=self._contact(self.published, now, False))
        try:
            estimate = solve(self.estimate, **kwargs)
        except ValueError as error:
            return self._set_aside('no estimate: %s' % error, vector)
        reason = _flagged(estimate)
        if reason:
            return self._set_aside(reason, vector)
        self._rejected = None
        # settled: a second solve of the same measurement moved it by noise of noise (one warm
        # solve after a jump may stop short of the fixed point: its Jacobian was the old one's)
        self._settled = unchanged and bool(np.all(
            np.abs(estimate.wrench - self.estimate.wrench)[:len(estimate.sigma)]
            <= SETTLED_SIGMAS * estimate.sigma))
        self.estimate = estimate
        self._solved = vector
        if not _same_load(estimate, self.published):
            self.published = estimate
        return Outcome(Verdict.PUBLISH, self.published,
                       contact_changed=self._contact(self.published, now, False))

    def _held(self, kwargs, now, solve):
        """Hold the last estimate at rest while the cables move (a moving rod is no statics).

        Still solved, at most every :data:`HELD_SOLVE_PERIOD`: the warm start follows each
        cable's friction direction.
        """
        if self._held_solved is None or now - self._held_solved >= HELD_SOLVE_PERIOD:
            self._held_solved = now
            try:
                estimate = solve(self.estimate, **kwargs)
            except ValueError:
                estimate = None
            if estimate is not None and not _flagged(estimate):
                self.estimate = estimate
        self._solved, self._settled, self._rejected = None, False, None
        return Outcome(Verdict.HELD, self.published,
                       contact_changed=self._contact(self.published, now, True))

    def _set_aside(self, reason, vector=None):
        self.contact.hold()
        if vector is not None:
            self._rejected = (vector, reason)
        # the last load at rest holds: a consumer that heard nothing would time out to zero
        # load, which moved the model tip ~10 mm under a 0.14 N load and let goals be judged
        # there (2 of 4 fresh-clone runs on a 2-GHz machine)
        return Outcome(Verdict.SET_ASIDE, self.published, reason=reason)

    def _contact(self, estimate, now, moving):
        return self.contact.update(estimate.force, estimate.covariance, now, not moving)

    def _beyond_limits(self, tensions, noise):
        """Return why a tension exceeds its cable's upper limit beyond noise, else ''."""
        if tensions is None:
            return ''
        upper = self.robot.tendons.tension_limits[:, 1]
        over = tensions > upper + LIMIT_SIGMAS * tension_sigma(noise['tension'], tensions)
        if not over.any():
            return ''
        names = [name for name, bad in zip(self.robot.cable_names, over) if bad]
        return ('tension of %s above its limit (%s N > %s N): not a reading of this robot '
                '(units? a faulty load cell?)' % (
                    ', '.join(names), np.round(tensions[over], 3).tolist(),
                    np.round(upper[over], 3).tolist()))

    def _moving(self, lengths, noise, now):
        """Return True while the cables move or stopped less than the contact time ago."""
        if lengths is None:
            return False
        if self._still is None or self._still[0].shape != lengths.shape:
            self._still = (lengths.copy(), -np.inf)  # no motion seen yet
        elif np.any(np.abs(lengths - self._still[0]) > MOVING_SIGMAS * noise['length']):
            self._still = (lengths.copy(), now)
        return now - self._still[1] < self.contact.min_time


def _flagged(estimate):
    """Return why an estimate may not be published as a load, or ''."""
    if not (np.isfinite(estimate.wrench).all() and np.isfinite(estimate.covariance).all()):
        return 'non-finite estimate'
    if not estimate.converged:
        return 'not converged: %s' % (estimate.message or 'capped solve')
    if not estimate.explains():
        return ('the model cannot explain these measurements (chi-square %.3g per measurement '
                'over %d degrees of freedom: a faulty sensor, wrong units or a wrong noise '
                'figure)' % (estimate.chi2, estimate.dof))
    return ''


def _same_load(estimate, published):
    """Return True if ``estimate`` is ``published``'s load within its own noise (SAME_LOAD)."""
    if published is None or published.parameters.shape != estimate.parameters.shape:
        return False
    difference = estimate.parameters - published.parameters
    try:
        chi2 = float(difference @ np.linalg.solve(estimate.parameter_covariance, difference))
    except np.linalg.LinAlgError:
        return False
    return chi2 <= gates.chi2_quantile(SAME_LOAD, len(difference))


def _within(vector, reference, tolerance):
    """Return True if ``vector`` is within ``tolerance`` (elementwise) of ``reference``."""
    return reference is not None and reference.shape == vector.shape and \
        bool(np.all(np.abs(vector - reference) <= tolerance))


def _measurement_vector(kwargs, noise):
    """Return all measurements in one vector, and their noise standard deviations."""
    parts, sigmas = [], []
    for key, level in (('lengths', 'length'), ('tensions', 'tension'),
                       ('tip_position', 'tip_position'), ('tip_rotation', 'tip_angle')):
        value = kwargs.get(key)
        if value is None:
            continue
        value = np.asarray(value, dtype=float).ravel()
        parts.append(value)
        sigmas.append(tension_sigma(noise[level], value) if key == 'tensions'
                      else np.full(len(value), float(noise[level])))
    return np.concatenate(parts), np.concatenate(sigmas)
