"""Simulated cable actuators: a first-order lag with a speed limit, length limits and noise.

Given the robot, the simulated cables are its real tendons too: each reading solves the robot's
displacement-driven statics (:meth:`Robot.solve_lengths`: slack, stretch, pretension, friction by
direction of motion) at the motors' lengths and reports the motor-side tensions, as a driver
with current sensing or load cells would. Robots with ideal cables (no tendons block) report
no tensions, as before. A hidden tip load (:meth:`SimulatedCableBackend.set_tip_wrench`, the
node's ``sim_tip_wrench``) acts on that simulated robot: the motors hold their lengths and the
tensions change, which is what a tip-load estimator has to find without being told. The
robot file's obstacles act on it too (:meth:`Robot.solve_lengths` rests the rod on them), and the
equilibrium's tip is :attr:`~SimulatedCableBackend.true_tip_pose`: give the driver a robot file
with an obstacle and statics one without to see what a model that does not know it misses.
"""
import math

import numpy as np

from continuum_statics.core.estimation.load_estimation import plausible_tip_load
from continuum_statics.drivers.base import (
    OK,
    WARN,
    BackendOption,
    BackendStatus,
    CableBackend,
    CableReading,
)
from continuum_statics.drivers.sim_dynamics import TIP_TOLERANCE, SimulatedRod


class SimulatedCableBackend(CableBackend):
    """Each cable follows its target as a first-order lag whose speed is limited.

    ``d length / dt = clip((target - length) / time_constant, -max_speed, max_speed)``, integrated
    exactly between two calls, so the result does not depend on the call rate. Lengths stay inside
    the limits; a reading adds zero-mean Gaussian noise of ``noise_std`` (m). The cables start at
    ``initial_lengths`` (the straight-rod lengths in the node).

    Options: ``time_constant`` (s, >= 0; 0 = no lag), ``max_speed`` (m/s, > 0),
    ``noise_std`` (m, >= 0), ``seed`` (int; negative = not reproducible), ``dynamics`` (the rod
    in motion behind the motors, :mod:`~continuum_statics.drivers.sim_dynamics`),
    ``motor_bandwidth`` (Hz; > 0 sets the time constant 1 / (2 pi bandwidth)), ``tip_mass``
    (kg of payload, with ``dynamics``).
    """

    name = 'sim'
    options_spec = (
        BackendOption('time_constant', 0.02, 'time constant of the first-order lag, s (0: none)',
                      0.0, 10.0),
        BackendOption('max_speed', 0.05, 'maximum cable speed, m/s', 1e-6, 10.0),
        BackendOption('noise_std', 0.0, 'standard deviation of the measurement noise, m',
                      0.0, 0.01),
        BackendOption('seed', -1, 'noise random seed (negative: not reproducible)',
                      -1, 2 ** 31 - 1, read_only=True),
        BackendOption('dynamics', False, 'simulate the rod in motion: the motors drive its '
                      "real tendons at the robot file's dynamics.dt, in real time",
                      read_only=True),
        BackendOption('motor_bandwidth', 0.0, 'motor bandwidth, Hz (> 0: the time constant '
                      'is 1 / (2 pi bandwidth); 0: time_constant)', 0.0, 1000.0),
        BackendOption('tip_mass', 0.0, 'payload at the tip with dynamics, kg', 0.0, 1.0,
                      read_only=True),
    )

    #: the node passes ``robot=`` (its :class:`Robot`) to backends that set this
    wants_robot = True
    takes_tip_wrench = True

    def __init__(self, cable_names, length_limits, initial_lengths, robot=None, **options):
        super().__init__(cable_names, length_limits, initial_lengths, **options)
        # the tendon model, when the robot file has one (ideal cables report no tension)
        self._robot = robot if robot is not None and not robot.tendons.is_ideal else None
        self._statics = None  # the last solve_lengths result: friction history, warm start
        self._true_tip = None  # its tip while the last reading's solve converged, else None
        self._tip_wrench = np.zeros(6)  # hidden tip load (N, N m), base frame
        merged = self.options
        # the payload acts only on the rod in motion; there, it is held to the hidden load's bound
        self._tip_mass = float(merged['tip_mass']) if merged['dynamics'] else 0.0
        for key in ('time_constant', 'max_speed', 'noise_std', 'motor_bandwidth'):
            self.set_option(key, merged[key])
        seed = int(merged['seed'])
        self._rng = np.random.default_rng(None if seed < 0 else seed)
        self._lengths = np.clip(self.initial_lengths, self.length_limits[:, 0],
                                self.length_limits[:, 1])
        self._targets = self._lengths.copy()
        self._velocities = np.zeros_like(self._lengths)
        self._time = None
        self._rod = None  # the rod in motion (option dynamics)
        self._reported = (0.0, 0)  # its dropped time and failed steps at the last status()
        if merged['dynamics']:
            if robot is None:
                raise ValueError('sim.dynamics needs the robot (the node passes it)')
            problem = implausible_load(robot, self._tip_wrench, self._tip_mass)
            if problem:
                raise ValueError('sim.tip_mass: ' + problem)
            self._rod = SimulatedRod(robot, self._lengths, float(merged['tip_mass']))

    def set_option(self, key, value):
        """Change ``time_constant``, ``max_speed`` or ``noise_std`` at run time."""
        value = float(value)
        if key == 'time_constant':
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError('time_constant must be finite and >= 0 s, got %r' % value)
            self.time_constant = value
        elif key == 'max_speed':
            if not (value > 0.0):  # also rejects NaN; inf means no speed limit
                raise ValueError('max_speed must be > 0 m/s, got %r' % value)
            self.max_speed = value
        elif key == 'noise_std':
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError('noise_std must be finite and >= 0 m, got %r' % value)
            self.noise_std = value
        elif key == 'motor_bandwidth':
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError('motor_bandwidth must be finite and >= 0 Hz, got %r' % value)
            if value > 0.0:
                self.time_constant = 1.0 / (2.0 * math.pi * value)
        else:
            super().set_option(key, value)
        self.options[key] = value

    def set_tip_wrench(self, wrench):
        """Apply a tip load [fx, fy, fz, mx, my, mz] (N, N m, base frame) to the robot."""
        wrench = np.asarray(wrench, dtype=float).reshape(-1)
        if wrench.shape != (6,) or not np.all(np.isfinite(wrench)):
            raise ValueError('tip wrench must be 6 finite numbers [fx, fy, fz, mx, my, mz], '
                             'got %s' % wrench.tolist())
        if self._robot is not None:
            problem = implausible_load(self._robot, wrench, self._tip_mass)
            if problem:
                raise ValueError(problem + '; kept the last one')
        self._tip_wrench = wrench

    @property
    def tip_wrench(self):
        """The hidden tip load (6,) (a copy)."""
        return self._tip_wrench.copy()

    def start(self, now):
        """Start the simulation clock at ``now`` (monotonic s)."""
        self._time = float(now)
        if self._rod is not None:
            self._rod.time = float(now)

    def command(self, target_lengths, now):
        """Advance to ``now`` and follow the new targets from there."""
        self._advance(now)
        targets = np.asarray(target_lengths, dtype=float).reshape(self._lengths.shape)
        self._targets = np.clip(targets, self.length_limits[:, 0], self.length_limits[:, 1])

    def hold(self, now):
        """Advance to ``now`` and stop there."""
        self._advance(now)
        self._targets = self._lengths.copy()

    def read(self, now):
        """Advance to ``now``; return the (noisy) lengths, the speeds and the model tensions."""
        self._advance(now)
        lengths = self._lengths
        tensions = self._tensions(lengths)
        if self.noise_std > 0.0:
            lengths = lengths + self._rng.normal(0.0, self.noise_std, lengths.shape)
        return CableReading(lengths=lengths.copy(), velocities=self._velocities.copy(),
                            tensions=tensions)

    @classmethod
    def knows_truth(cls, robot, options):
        """Say whether a true tip exists: the rod in motion or the real tendons' equilibrium."""
        return bool(options.get('dynamics')) or not robot.tendons.is_ideal

    @property
    def true_tip_pose(self):
        """The true tip (position (3,) m, rotation (3, 3)), or None (ideal cables, no solve yet).

        With ``dynamics`` the rod in motion's; else the equilibrium of the motors' lengths under
        the hidden load and the robot file's obstacles (the last reading's solve; None when it
        did not converge: no stale truth).
        """
        if self._rod is not None:
            return self._rod.tip_pose()
        return self._true_tip  # one tuple, replaced whole by the reading thread

    def _tensions(self, lengths):
        """Motor-side tensions (N) of the tendon model at the true lengths, or None."""
        if self._rod is not None:  # a slack cable's tension is zero, never -1e-12 or -0.0
            return np.maximum(self._rod.tensions, 0.0)
        if self._robot is None:
            return None
        solution = self._robot.solve_lengths(lengths, self._tip_wrench[:3], self._tip_wrench[3:],
                                             warm_start=self._statics)
        if not solution.converged:  # keep the last good history; report nothing made up
            self._true_tip = None
            return None
        self._statics = solution
        self._true_tip = solution.shape.tip_position.copy(), solution.shape.tip_rotation.copy()
        return np.maximum(solution.tensions, 0.0)

    def status(self):
        """Report the largest distance between a cable and its target (and the rod's pace)."""
        tracking = float(np.max(np.abs(self._targets - self._lengths), initial=0.0))
        values = {
            'max_tracking_error_m': '%.6f' % tracking,
            'time_constant_s': '%g' % self.time_constant,
            'max_speed_m_per_s': '%g' % self.max_speed,
            'noise_std_m': '%g' % self.noise_std,
        }
        if self._rod is None:
            return BackendStatus(OK, 'simulated cables', values)
        rod = self._rod
        values.update({'real_time_factor': '%.2f' % rod.real_time_factor,
                       'step_time_ms': '%.3f' % (1e3 * rod.step_time),
                       'dt_s': '%g' % rod.dt, 'steps': str(rod.steps),
                       'failed_steps': str(rod.failed_steps),
                       'dropped_time_s': '%.3f' % rod.dropped_time})
        gap = rod.tip_gap(self._tip_wrench)
        values['true_tip_from_model_m'] = 'n/a' if gap is None else '%.6f' % gap
        # what happened since the last report: a start-up hiccup does not warn for ever
        dropped = rod.dropped_time - self._reported[0]
        failed = rod.failed_steps - self._reported[1]
        self._reported = (rod.dropped_time, rod.failed_steps)
        if dropped > 0.0 or failed:
            return BackendStatus(WARN, 'simulated rod in motion slower than real time or '
                                 'stalled (%.3f s dropped, %d failed steps since the last '
                                 'report)' % (dropped, failed), values)
        if gap is not None and gap > TIP_TOLERANCE:
            return BackendStatus(WARN, "true tip %.1f mm from the model's (the statics of the "
                                 "motors' lengths; tolerance %g mm): a payload or a swing the "
                                 'model does not know, goals are off by as much'
                                 % (1e3 * gap, 1e3 * TIP_TOLERANCE), values)
        return BackendStatus(OK, 'simulated cables and rod in motion', values)

    @property
    def targets(self):
        """Current targets, m (a copy)."""
        return self._targets.copy()

    def _advance(self, now):
        now = float(now)
        if self._rod is not None:  # motors and rod together, at the rod's fixed step
            for _ in range(self._rod.steps_until(now)):
                self._rod.step(self._motor_step(self._rod.dt), self._tip_wrench)
            return
        if self._time is None:
            self._time = now
        dt = now - self._time
        if dt <= 0.0:
            return
        self._time = now
        self._motor_step(dt)

    def _motor_step(self, dt):
        """Move the motors over ``dt`` s; return their lengths (m)."""
        before = self._lengths
        self._lengths = np.clip(self.step(before, self._targets, dt, self.time_constant,
                                          self.max_speed),
                                self.length_limits[:, 0], self.length_limits[:, 1])
        self._velocities = (self._lengths - before) / dt
        return self._lengths

    @staticmethod
    def step(lengths, targets, dt, time_constant, max_speed):
        """Exact solution of the speed-limited first-order lag over ``dt`` s.

        While ``|target - length| > max_speed * time_constant`` the cable moves at ``max_speed``;
        closer in, the gap decays as ``exp(-t / time_constant)``.
        """
        gap = targets - lengths
        distance = np.abs(gap)
        knee = max_speed * time_constant if time_constant > 0.0 else 0.0
        # Time spent at full speed before the gap shrinks to the knee (0 if already inside it).
        fast_time = np.where(distance > knee, (distance - knee) / max_speed, 0.0)
        fast_time = np.nan_to_num(fast_time, nan=0.0)  # max_speed = inf
        in_fast = dt <= fast_time
        remaining = np.where(in_fast, 0.0, dt - fast_time)
        start = np.minimum(distance, knee)
        if time_constant > 0.0:
            decayed = start * np.exp(-remaining / time_constant)
        else:
            decayed = np.zeros_like(start)
        new_distance = np.where(in_fast, distance - max_speed * dt, decayed)
        return targets - np.sign(gap) * new_distance


def implausible_load(robot, wrench, tip_mass=0.0, load='hidden tip load'):
    """Return why a hidden tip load (6,) with a payload (kg) is beyond the rod, or ''.

    The payload's weight (``tip_mass`` times the robot's gravity) adds to the force; ``load``
    names the wrench in the message. Beyond
    10 E I / L^2 of force (2 pi E I / L of moment) the simulated rod has no equilibrium near:
    every reading then runs the tendon solve's slow last resort (200 Hz fell to 4 Hz), and a rod
    in motion collapses (1 kg on the 30 cm Nitinol rod: its tip half a metre from the model's).
    Used by the driver and by ``simulate``.
    """
    force_limit, moment_limit = plausible_tip_load(robot)
    wrench = np.asarray(wrench, dtype=float)
    weight = float(tip_mass) * np.asarray(robot.gravity, dtype=float)
    force, moment = np.linalg.norm(wrench[:3] + weight), np.linalg.norm(wrench[3:])
    if force <= force_limit and moment <= moment_limit:
        return ''
    what = load if not tip_mass else 'payload %g kg (weight %.3g N)%s' % (
        tip_mass, np.linalg.norm(weight), ' with the %s' % load if wrench.any() else '')
    return ('%s: |F| %.3g N, |M| %.3g N m is beyond what the rod can carry (%.3g N, %.3g N m: '
            '10 E I / L^2, 2 pi E I / L)' % (what, force, moment, force_limit, moment_limit))
