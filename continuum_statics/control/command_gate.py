"""The cable_driver's command gate: which ``cable_commands`` reach the actuators, and as what.

- A length outside the robot's limits by at most ``margin`` is clamped (encoder quantisation,
  rounding); further out the whole command is refused with the reason: a clamped set of lengths
  is a shape nobody asked for.
- Commands are refused while the driver is not active (lifecycle), the actuators are not
  connected, the backend failed or an actuator reports a fault.
- A command may name a subset of the cables. After a hold (start, watchdog, reconnection, set
  home) the cables it does not name stay where they were last read; otherwise where they were
  last commanded.
- The watchdog: no command for ``timeout`` s and the gate says hold.

No ROS and no backend calls: the node asks the gate, calls the backend, and tells the gate what
the backend took. Not thread-safe: the node calls it under its own lock.
"""
import numpy as np

from continuum_statics.control.health import ERROR

#: First reconnection delay after a lost port or bus, s (doubles up to reconnect_max_interval).
FIRST_RETRY = 0.1


class CommandRefused(ValueError):
    """A command the gate does not pass on; the message says why."""


class CommandGate:
    """Lifecycle, connection and fault state of a cable driver, and its command rules.

    :param cable_names: the robot's cable names (robot order)
    :param limits: (n, 2) length limits, m
    :param straight: (n,) straight-rod lengths, m: the targets before any command
    """

    def __init__(self, cable_names, limits, straight):
        self.cable_names = tuple(cable_names)
        self.limits = np.asarray(limits, dtype=float).reshape(-1, 2)
        self.straight = np.array(straight, dtype=float)
        self.targets = self.straight.copy()
        self.last_reading = None  # the last lengths read (m), None after a (re)connection
        self.last_command_time = None
        self.holding = True
        self.active = False  # lifecycle: commands accepted
        self.finalized = False  # lifecycle: shut down
        self.configured = False  # a backend exists
        self.connected = False
        self.connection_error = ''
        self.backend_error = ''
        self.status = None  # the backend's last BackendStatus
        self.retry_delay = FIRST_RETRY  # s until the next connection attempt after a loss
        self.next_attempt = 0.0  # monotonic s
        self.accepted = 0
        self.clamped = 0
        self.refused = 0

    # -- state ----------------------------------------------------------------------------------
    def lifecycle_state(self) -> str:
        """'unconfigured', 'inactive' (configured), 'active' or 'finalized'."""
        if self.finalized:
            return 'finalized'
        if self.active:
            return 'active'
        return 'inactive' if self.configured else 'unconfigured'

    def refusal(self) -> str:
        """Why commands cannot be carried out now, or ''."""
        if self.finalized:
            return 'cable_driver is shut down (lifecycle finalized): restart it'
        if not self.active:
            return 'cable_driver is %s (lifecycle): activate it to accept commands' % (
                self.lifecycle_state())
        if not self.connected:
            return 'actuators not connected (%s)' % self.connection_error
        if self.backend_error:
            return 'backend failed (%s)' % self.backend_error
        status = self.status
        if status is not None and status.level >= ERROR:
            return 'actuator fault: %s' % status.message
        return ''

    def connect(self) -> bool:
        """Record a (re)connection; return True when it ends a loss (a reconnection).

        After a (re)connection the cables stay where they are until a new command.
        """
        reconnected = bool(self.connection_error)
        self.connected, self.connection_error = True, ''
        self.retry_delay = FIRST_RETRY
        self.hold(forget_reading=True)
        return reconnected

    def lose(self, error, now, max_interval) -> 'float | None':
        """Record a lost connection and schedule the next attempt.

        The delay doubles up to ``max_interval`` s. Return None for a new loss, else the delay
        of this retry, s.
        """
        first = self.connected or not self.connection_error
        self.connected, self.connection_error = False, str(error)
        delay = self.retry_delay
        self.next_attempt = now + delay
        self.retry_delay = min(2.0 * delay, max_interval)
        return None if first else delay

    def hold(self, forget_reading=False, home=False) -> None:
        """Record a hold of the actuators: the next command starts from the last reading.

        :param forget_reading: the last reading no longer holds (a reconnection, a new home)
        :param home: the straight pose was redefined: the targets are the straight lengths
        """
        self.holding = True
        if forget_reading:
            self.last_reading = None
        if home:
            self.targets = self.straight.copy()

    def read(self, lengths) -> None:
        """Record the lengths (m) just read from the actuators."""
        self.last_reading = np.asarray(lengths, dtype=float)

    # -- commands -------------------------------------------------------------------------------
    def admit(self, index, lengths, margin) -> np.ndarray:
        """Return the full target lengths (m, robot order) of a command, or refuse it.

        :param index: robot index of each commanded cable (``cable_index(..., require_all=False)``)
        :param lengths: the commanded lengths, m, finite
        :param margin: how far outside a length limit is still clamped, m
        :raises CommandRefused: outside the limits by more than ``margin``, or the driver
            refuses commands now (counted in ``refused``)
        """
        lengths = np.asarray(lengths, dtype=float)
        low, high = self.limits[index, 0], self.limits[index, 1]
        outside = np.flatnonzero((lengths < low - margin) | (lengths > high + margin))
        if outside.size:
            raise CommandRefused('outside the length limits by more than length_margin %g m: %s'
                                 % (margin, ', '.join(
                                     '%s %.4f m not in [%.4f, %.4f]' % (
                                         self.cable_names[index[i]], lengths[i], low[i],
                                         high[i]) for i in outside)))
        clamped = np.clip(lengths, low, high)
        if np.any(clamped != lengths):
            self.clamped += 1
        refusal = self.refusal()
        if refusal:
            self.refused += 1
            raise CommandRefused('refused: ' + refusal)
        targets = self.targets.copy()  # stored only once the backend took it (taken())
        if self.holding and self.last_reading is not None:
            # After a hold, cables not named in this command stay where they are.
            targets = np.clip(self.last_reading, self.limits[:, 0], self.limits[:, 1])
        targets[index] = clamped
        return targets

    def taken(self, targets, now) -> None:
        """Record that the backend took ``targets`` (from :meth:`admit`) at monotonic ``now``."""
        self.targets = targets
        self.accepted += 1
        self.last_command_time = now
        self.holding = False

    def timed_out(self, now, timeout) -> bool:
        """Return True once no command came for ``timeout`` s (0: never): hold (the watchdog)."""
        if (not self.holding and timeout > 0.0 and self.last_command_time is not None
                and now - self.last_command_time > timeout):
            self.holding = True
            return True
        return False

    def home_refusal(self, tolerance, force=False) -> str:
        """Why the last reading is no straight pose to home at (``tolerance`` m), or ''."""
        if force:
            return ''
        if self.last_reading is None:
            return 'no reading yet (home_force:=true to home anyway)'
        offset = self.last_reading - self.straight
        worst = int(np.argmax(np.abs(offset)))
        if abs(offset[worst]) <= tolerance:
            return ''
        return ('the robot is not straight: %s reads %+.2f mm from its straight length '
                '(home_tolerance %.2f mm); straighten it, or set home_force:=true if the '
                'previous home is wrong' % (self.cable_names[worst], offset[worst] * 1e3,
                                             tolerance * 1e3))
