"""The cable_driver's actuators: one backend run through its :class:`~.command_gate.CommandGate`.

What the driver decides around a :class:`~continuum_statics.drivers.base.CableBackend`, without
ROS: connection and reconnection with a doubling backoff, lifecycle power switching, the command
watchdog, resetting faults and setting home. Every backend call happens here, under one lock (the
node's executor and its publish loop both call in); a backend failure never escapes: it becomes
the gate's ``backend_error`` or a lost connection, which the node's status reports.
"""
import threading
import time

from continuum_statics.control.command_gate import FIRST_RETRY
from continuum_statics.control.health import ERROR, THROTTLE_S, WARN
from continuum_statics.drivers.base import BackendStatus, ConnectionLost

#: Longest the diagnostics wait for the lock (a reconnection may hold it for seconds), s.
STATUS_WAIT = 0.05


class Actuators:
    """A cable backend, its gate and the rules of calling it.

    :param gate: the :class:`~.command_gate.CommandGate` holding the driver's state
    :param name: the backend's name, for the messages
    :param log: logger with ``info``, ``warning`` and ``error``
    """

    def __init__(self, gate, name, log, clock=time.monotonic):
        self.gate, self.name, self.log, self.clock = gate, name, log, clock
        self.backend = None  # created by configure, released by release
        self.lock = threading.Lock()
        self.reconnects = 0
        self.failure = ''  # why the last switch_power failed
        self.max_interval = 10.0  # reconnect_max_interval, s
        self._logged = {}  # what -> monotonic s of its last throttled log line

    def _throttled(self, level, what, text):
        now = self.clock()
        last = self._logged.get(what)
        if last is None or now - last >= THROTTLE_S:
            self._logged[what] = now
            getattr(self.log, level)(text)

    # -- connection -----------------------------------------------------------------------------
    def configure(self, backend, before_connect=None) -> None:
        """Take a new backend (power off) and connect; a failure is retried by :meth:`step`."""
        backend.power = False
        with self.lock:
            self.backend, self.gate.configured = backend, True
            if before_connect is not None:
                before_connect(backend)
            self.gate.retry_delay = FIRST_RETRY
            self._connect(self.clock())

    def _connect(self, now):
        """Try ``backend.start``; on ConnectionLost schedule the next try (under the lock)."""
        try:
            self.backend.start(now)
        except ConnectionLost as error:
            self._lost(error, now)
            return False
        if self.gate.connect():
            self.reconnects += 1
            self.log.info('reconnected: %s is back' % self.name)
        return True

    def _lost(self, error, now):
        delay = self.gate.lose(error, now, self.max_interval)
        if delay is None:
            self.log.error('%s: %s; reconnecting' % (self.name, error))
        else:
            self._throttled('warning', 'connection', 'still no connection: %s (next try in '
                            '%.2g s)' % (error, delay))

    def _failure(self, what, error):
        self.gate.backend_error = '%s failed: %s' % (what, error)
        self._throttled('error', what, 'backend %s' % self.gate.backend_error)

    def switch_power(self, on) -> bool:
        """Lifecycle (de)activation: power on/off, holding; False when the backend failed.

        Why it failed is then in :attr:`failure` ('' after a success).
        """
        gate = self.gate
        if self.backend is None:
            gate.active = on
            return True
        with self.lock:
            gate.active = on
            gate.hold()
            now = self.clock()
            try:
                if gate.connected:
                    (self.backend.enable if on else self.backend.disable)(now)
                else:
                    self.backend.power = on  # the reconnection does it
            except ConnectionLost as error:
                self._lost(error, now)  # the reconnection does it
            except Exception as error:
                # the transition fails: the lifecycle stays where it was, and so does the gate
                gate.active = not on
                self.failure = '%s failed: %s' % ('activate' if on else 'deactivate', error)
                return False  # the node logs it and puts it on /diagnostics
        self.failure = ''
        return True

    def release(self) -> None:
        """Hold, then release the actuators and the port or bus (cleanup, shutdown)."""
        with self.lock:
            backend, self.backend = self.backend, None
            gate = self.gate
            gate.active = gate.connected = gate.configured = False
            if backend is None:
                return
            try:
                if not gate.connection_error:
                    backend.hold(self.clock())
            except Exception as error:
                self.log.warning('hold at release failed: %s' % error)
            try:
                backend.close()
            except Exception as error:
                self.log.error('backend shutdown failed: %s' % error)

    # -- commands and the loop ------------------------------------------------------------------
    def command(self, index, lengths, margin) -> None:
        """Carry out a command (cables ``index``, lengths m); CommandRefused says why not."""
        with self.lock:
            targets = self.gate.admit(index, lengths, margin)
            now = self.clock()
            try:
                self.backend.command(targets, now)
            except ConnectionLost as error:
                self._lost(error, now)
                return
            except Exception as error:  # a real backend may fail; the node stays up
                self._failure('command', error)
                return
            self.gate.taken(targets, now)

    def step(self, timeout, accept=None) -> object:
        """One loop period: reconnect when due, the watchdog, then read; the reading or None.

        :param timeout: command_timeout, s (0: no watchdog)
        :param accept: called with the reading under the lock; a ValueError from it (a NaN
            reading) is a failed read
        """
        now = self.clock()
        gate = self.gate
        with self.lock:
            if self.backend is None:  # unconfigured
                return None
            if not gate.connected and (now < gate.next_attempt or not self._connect(now)):
                return None
            try:
                if gate.timed_out(now, timeout):
                    self.backend.hold(now)
                    self.log.info('no cable command for %.3g s: holding position' % timeout)
                reading = self.backend.read(now)
                gate.status = self.backend.status()
                if accept is not None:
                    accept(reading)
            except ConnectionLost as error:
                self._lost(error, now)
                return None
            except Exception as error:  # ValueError on NaN from a backend, or a hardware error
                self._failure('read', error)
                return None
            gate.backend_error = ''
            gate.read(reading.lengths)
        return reading

    def status(self) -> object:
        """Return the backend's status now (the last one while the lock is busy), or None."""
        if self.backend is None or self.gate.finalized:
            return None
        # a reconnection can hold the lock for seconds (drive timeouts): never stall on it
        if not self.lock.acquire(timeout=STATUS_WAIT):
            return self.gate.status or BackendStatus(WARN, 'actuators busy')
        try:
            if self.backend is not None:
                self.gate.status = self.backend.status()
                return self.gate.status
            return None
        finally:
            self.lock.release()

    # -- services -------------------------------------------------------------------------------
    def reset(self) -> tuple:
        """Clear faults (or reconnect when lost): return (success, message)."""
        gate = self.gate
        with self.lock:
            try:
                if not gate.connected:
                    gate.retry_delay = FIRST_RETRY
                    ok = self._connect(self.clock())
                    return ok, 'reconnected' if ok else 'still not connected: %s' % (
                        gate.connection_error)
                message = self.backend.reset()
                gate.status, gate.backend_error = self.backend.status(), ''
                gate.hold()
                if gate.status.level < ERROR:
                    return True, message
                return False, '%s; still: %s' % (message, gate.status.message)
            except ConnectionLost as error:
                self._lost(error, self.clock())
                return False, str(error)
            except Exception as error:
                return False, 'reset failed: %s' % error

    def set_home(self, tolerance, force=False) -> list:
        """Make the present positions the straight pose; return the zeros (ValueError: why not)."""
        gate = self.gate
        with self.lock:
            if not gate.connected:
                raise ValueError('actuators not connected (%s)' % gate.connection_error)
            refusal = gate.home_refusal(tolerance, force)
            if refusal:
                raise ValueError(refusal)
            zeros = self.backend.set_home()
            gate.hold(forget_reading=True, home=True)
            self.backend.hold(self.clock())
        return zeros

    def call(self, function, *args) -> None:
        """Call ``function(backend, *args)`` under the lock when there is a backend."""
        with self.lock:
            if self.backend is not None:
                function(self.backend, *args)
