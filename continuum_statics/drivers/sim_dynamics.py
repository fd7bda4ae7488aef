"""The simulated robot in motion: the rod's dynamics behind the simulated motors (issue 36).

With ``sim.dynamics: true`` the simulated driver's cables are the motors' lengths driving
:class:`~continuum_statics.core.dynamics.rod_dynamics.RodDynamics` (real tendons: stretch, slack,
friction)
at the robot file's fixed time step, in real time: each reading first integrates the motors and
the rod up to the clock. What the driver reports is what a real one reads (the motors' lengths
and the tensions at the motors); the true tip pose is there for tests and the view.
"""
import time

import numpy as np

from continuum_statics.core.warmup import warm_up_dynamics

#: most simulated time (s) one reading integrates; beyond it the simulation drops the backlog
#: (slower than real time: counted, and the real-time factor on /diagnostics says so)
MAX_CATCH_UP = 0.05
#: m: a true tip farther than this from the model's (the statics of the motors' lengths under
#: the hidden tip load) is a WARN. Above what dynamics and statics differ by at rest (1.4e-7 m)
#: and the 2 mm the nodes' goals come to rest within; a hidden payload past it is not a rounding
#: error: the controller's "goal reached" is that far off.
TIP_TOLERANCE = 0.005
#: s: the time constant of the low-pass filter both tips are compared through. A swing
#: (13.7 Hz: 1/43; a 20 g payload's 4.1 Hz: 1/13) and a fast goal's 0.1 s dynamic lag (16.6 mm:
#: about 3 mm) average out; a steady offset does not.
TIP_FILTER = 0.5


class SimulatedRod:
    """The rod of a simulated driver, stepped at a fixed dt up to the clock.

    :param robot: the robot (its ``tendons`` block: lengths drive real tendons)
    :param lengths: (n,) m, the motors' lengths at the start (the rod starts at rest there)
    :param tip_mass: kg of payload at the tip (weight and inertia)
    """

    def __init__(self, robot, lengths, tip_mass=0.0):
        if robot.tendons.is_ideal:
            raise ValueError('sim.dynamics needs real tendons (a tendons block in the robot '
                             'file: stiffness, pretension): the motors drive the rod through '
                             'their stretch; robot %r has ideal cables' % robot.name)
        # the rod-in-motion kernels are not in the nodes' warm-up: compiled (or loaded from the
        # cache) here, at configure, rather than at the first step of the real-time loop
        warm_up_dynamics()
        self.robot = robot
        self.dynamics = robot.dynamics(tip_mass=tip_mass)
        self.dt = self.dynamics.dt
        self.state = self.dynamics.start(lengths=lengths)
        self.time = None  # the clock (s) the simulation has reached
        self.steps = 0
        self.failed_steps = 0
        self.dropped_time = 0.0  # s of backlog dropped (slower than real time)
        self._compute = 0.0  # s of CPU spent stepping
        self._simulated = 0.0
        # low-passed true tip and motor lengths (TIP_FILTER): what tip_gap compares
        self._smooth = 1.0 - np.exp(-self.dt / TIP_FILTER)
        self._tip_filtered = self.state.tip_position.copy()
        self._lengths_filtered = np.array(lengths, dtype=float)
        self._model = None  # the last statics of the filtered lengths (friction, warm start)

    def steps_until(self, now):
        """Return how many fixed steps bring the rod up to the clock ``now`` (s).

        The first call starts the clock. A backlog beyond :data:`MAX_CATCH_UP` is dropped
        (slower than real time: counted in :attr:`dropped_time`).
        """
        if self.time is None:
            self.time = now
            return 0
        behind = now - self.time
        if behind > MAX_CATCH_UP:  # slower than real time: keep up with the clock
            dropped = behind - MAX_CATCH_UP
            self.dropped_time += dropped
            self.time += dropped
        return max(int((now - self.time) / self.dt + 1e-9), 0)

    def step(self, lengths, wrench):
        """Advance the rod one ``dt`` with the motors at ``lengths`` (n,) m.

        ``wrench`` (6,) is the hidden tip load (N, N m, base frame). A step that does not
        converge keeps the last state (counted in :attr:`failed_steps`).
        """
        began = time.perf_counter()
        state = self.dynamics.step(lengths=lengths, tip_force=wrench[:3], tip_moment=wrench[3:])
        if state.converged:
            self.state = state
        else:
            self.failed_steps += 1
        self._tip_filtered += self._smooth * (self.state.tip_position
                                              - self._tip_filtered)
        self._lengths_filtered += self._smooth * (lengths - self._lengths_filtered)
        self.time += self.dt
        self.steps += 1
        self._simulated += self.dt
        self._compute += time.perf_counter() - began

    @property
    def real_time_factor(self):
        """Simulated seconds per second of computing, over the run (inf before any step)."""
        return self._simulated / self._compute if self._compute > 0.0 else float('inf')

    @property
    def step_time(self):
        """Mean compute time of one step (s)."""
        return self._compute / self.steps if self.steps else 0.0

    @property
    def tensions(self):
        """(n,) N at the motors (what a load cell or the motor current reads)."""
        return self.state.tensions.copy()

    def tip_gap(self, wrench):
        """Distance (m) of the true tip from the model's, both low-passed (:data:`TIP_FILTER`).

        The model's tip is the statics of the motors' lengths under the hidden tip load
        ``wrench`` (6,), which is what the statics node finds when it is told that load; a
        payload nobody is told about (``tip_mass``) is the gap. One statics solve (~0.1 ms):
        call it at the diagnostics rate, not per step. None if the statics does not converge.
        """
        model = self.robot.solve_lengths(self._lengths_filtered, wrench[:3], wrench[3:],
                                         warm_start=self._model)
        if not model.converged:
            return None
        self._model = model
        return float(np.linalg.norm(self._tip_filtered - model.shape.tip_position))

    def tip_pose(self):
        """Return the true tip: position (3,) m and rotation (3, 3), base frame."""
        shape = self.state.shape
        return shape.tip_position.copy(), np.array(shape.rotations[-1])
