"""ROBOTIS Dynamixel X-series servos on spools, Protocol 2.0 through the official dynamixel-sdk.

One servo per cable (``ids`` in robot-file order). At start every id is pinged (missing ones are
named); the operating mode (extended position 4 or current-based position 5) is written with the
torque off, Goal Position is set to Present Position and the torque is switched on. Each cycle
writes Goal Position by one sync write and reads Present Current, Velocity and Position (126..135)
by one sync read; the status packets' alert bit (which the SDK's GroupSyncRead drops, so the
sync read is done here with the SDK's own ``syncReadTx``/``readRx``) triggers a sync read of
Hardware Error Status (70). A servo in shutdown is ERROR on diagnostics naming it and the fault
bits until :meth:`reset` reboots it.

Multi-turn count: an X servo restarts within one turn after a power loss or reboot. When a
servo reports a position inside its first turn, the backend adds the whole turns that bring it
nearest to the last position it saw (or, at the first start, to ``zero_ticks``, the straight
pose): a spool must not turn more than half a turn while unpowered.
"""
import struct
import time

import numpy as np

from continuum_statics.drivers.base import (
    ERROR,
    OK,
    WARN,
    BackendOption,
    BackendStatus,
    CableBackend,
    CableReading,
    ConnectionLost,
)
from continuum_statics.drivers.spool import Spool, per_cable

try:
    import dynamixel_sdk as sdk
except ImportError as _error:  # reported when the backend is constructed
    sdk = None
    _IMPORT_ERROR = _error

TICKS_PER_REV = 4096
ADDR_OPERATING_MODE, ADDR_HOMING_OFFSET = 11, 20
ADDR_TORQUE_ENABLE, ADDR_HARDWARE_ERROR, ADDR_GOAL_POSITION = 64, 70, 116
ADDR_PRESENT_CURRENT, PRESENT_LENGTH = 126, 10  # current (2), velocity (4), position (4)
OPERATING_MODES = {'extended_position': 4, 'current_based_position': 5}
VELOCITY_UNIT_RPM = 0.229
ALERT = 0x80
#: Longest blocking serial read inside the SDK's receive loop, s (see ``start``).
READ_BLOCK_S = 0.001
#: Hardware Error Status bits (e-Manual, X series).
HARDWARE_ERRORS = {0x01: 'input voltage', 0x04: 'overheating', 0x08: 'motor encoder',
                   0x10: 'electrical shock', 0x20: 'overload'}
#: What the port raises when the adapter vanishes (termios.error is not an OSError).
PORT_ERRORS = (OSError, AttributeError)


def hardware_error_text(bits):
    """Names of the Hardware Error Status ``bits``, e.g. 'overload, overheating (0x24)'."""
    names = [text for bit, text in HARDWARE_ERRORS.items() if bits & bit]
    return '%s (0x%02x)' % (', '.join(names) or 'unknown', bits)


def _port_errors():
    import termios
    try:
        import serial
        return PORT_ERRORS + (termios.error, serial.SerialException)
    except ImportError:
        return PORT_ERRORS + (termios.error,)


class DynamixelCableBackend(CableBackend):
    """Dynamixel X-series servos (Protocol 2.0) driving cable spools."""

    name = 'dynamixel'
    zero_option = 'zero_ticks'
    options_spec = (
        BackendOption('port', '/dev/ttyUSB0', 'serial port of the U2D2 / USB adapter',
                      read_only=True),
        BackendOption('baudrate', 57600, "bus speed, bit/s (the servos' Baud Rate setting)",
                      9600, 4500000, read_only=True),
        BackendOption('ids', [1, 2, 3, 4], 'servo id per cable, robot-file order',
                      read_only=True),
        BackendOption('spool_radius', 0.01, 'spool radius, m', 1e-4, 1.0, read_only=True),
        BackendOption('directions', [1], '+1/-1 per cable (one value: all); +1 = rising '
                      'position lengthens the cable', read_only=True),
        BackendOption('zero_ticks', [0], 'Present Position at the straight pose per cable, '
                      'ticks (one value: all; home_file overrides)', read_only=True),
        BackendOption('operating_mode', 'extended_position',
                      'extended_position (4) or current_based_position (5)', read_only=True),
        BackendOption('torque_constant', 0.0, 'N m/A, tension from Present Current (0: no '
                      'tension reading)', 0.0, 100.0),
        BackendOption('current_unit', 2.69e-3, 'A per Present Current unit (XM430: 2.69 mA)',
                      1e-6, 1.0, read_only=True),
        BackendOption('disable_torque_on_exit', True, 'torque off when the driver exits'),
        BackendOption('timeout_margin', 0.0, 'added to the SDK status-packet timeout (wire time '
                      '+ 34 ms), s: slow adapters, loaded computers', 0.0, 5.0, read_only=True),
    )

    def __init__(self, cable_names, length_limits, initial_lengths, **options):
        if sdk is None:
            raise ValueError('the dynamixel backend needs dynamixel-sdk 4.x (pip install '
                             '"dynamixel-sdk>=4,<5"): %s' % _IMPORT_ERROR)
        super().__init__(cable_names, length_limits, initial_lengths, **options)
        merged = self.options
        n = len(self.cable_names)
        self.ids = [int(i) for i in per_cable('ids', merged['ids'], n, integer=True)]
        if len(set(self.ids)) != n or not all(0 <= i <= 252 for i in self.ids):
            raise ValueError('ids must be %d distinct servo ids in 0..252, got %s'
                             % (n, self.ids))
        if merged['operating_mode'] not in OPERATING_MODES:
            raise ValueError('operating_mode must be one of %s, got %r'
                             % (', '.join(OPERATING_MODES), merged['operating_mode']))
        self.mode = OPERATING_MODES[merged['operating_mode']]
        self.spool = Spool.from_options(self.initial_lengths, merged['directions'],
                                        per_cable('zero_ticks', merged['zero_ticks'], n, True),
                                        merged['spool_radius'], TICKS_PER_REV)
        self.port_name = str(merged['port'])
        self.baudrate = int(merged['baudrate'])
        self.torque_constant = float(merged['torque_constant'])
        self.current_unit = float(merged['current_unit'])
        self._port_errors = _port_errors()
        self._packet = sdk.PacketHandler(2.0)
        self._port = None
        self._writer = None
        self._turns = np.zeros(n, dtype=np.int64)  # whole turns added after a count loss
        self._last_ticks = [None] * n  # multi-turn positions last seen
        self._hardware_errors = np.zeros(n, dtype=np.int64)
        self._torque_refused = set()
        self._models = {}
        self._warning = ''
        self.cycles = 0
        self.retries = 0  # sync reads repeated after one missing status packet

    # -- connection ---------------------------------------------------------------------------
    def _label(self, j):
        return 'servo %d (%s)' % (self.ids[j], self.cable_names[j])

    def _lost(self, what, error=None):
        self._drop_port()
        detail = ': %s' % error if error is not None else ''
        return ConnectionLost('port %s %s%s' % (self.port_name, what, detail))

    def _drop_port(self):
        port, self._port, self._writer = self._port, None, None
        if port is not None:
            try:
                port.closePort()
            except Exception:  # the port is gone already
                pass

    def start(self, now):
        """Open the port, ping every servo, set the operating mode, Goal = Present, torque on.

        :raises ConnectionLost: the port does not open or a servo does not answer (named)
        """
        self._drop_port()
        # A new handler each time: a vanished one stays 'in use'.
        port = _PortHandler(self.port_name, float(self.options['timeout_margin']))
        try:
            if not port.openPort() or not port.setBaudRate(self.baudrate):
                raise ConnectionLost('port %s: cannot open at %d bit/s'
                                     % (self.port_name, self.baudrate))
        except self._port_errors as error:
            raise ConnectionLost('port %s cannot be opened: %s' % (self.port_name, error)) \
                from None
        # The SDK polls a non-blocking port while it waits for a status packet (a busy loop that
        # takes a whole core); a short blocking read returns as soon as the bytes are there.
        if getattr(port, 'ser', None) is not None:
            port.ser.timeout = READ_BLOCK_S
        self._port = port
        try:
            missing = []
            for j, servo_id in enumerate(self.ids):
                model, result, _ = self._packet.ping(port, servo_id)
                if result != sdk.COMM_SUCCESS:
                    missing.append(self._label(j))
                else:
                    self._models[servo_id] = model
            if missing:
                self._drop_port()
                raise ConnectionLost('port %s: %s not answering' % (
                    self.port_name, ', '.join(missing)))
            for j in range(len(self.ids)):
                self._prepare(j)
            self._writer = sdk.GroupSyncWrite(port, self._packet, ADDR_GOAL_POSITION, 4)
        except ConnectionLost:
            raise
        except self._port_errors as error:
            raise self._lost('lost during start', error) from None

    def _txrx(self, j, what, call, *args):
        """Run one SDK transaction on servo j; return (value, error byte)."""
        out = call(self._port, self.ids[j], *args)
        value, result, error = (None,) + tuple(out) if len(out) == 2 else out
        if result != sdk.COMM_SUCCESS:
            raise self._lost('%s: %s did not answer (%s)' % (
                what, self._label(j), self._packet.getTxRxResult(result)))
        return value, error

    def _prepare(self, j):
        """Mode with torque off, restore the turn count, Goal = Present, torque on."""
        packet = self._packet
        torque, _ = self._txrx(j, 'read Torque Enable', packet.read1ByteTxRx, ADDR_TORQUE_ENABLE)
        mode, _ = self._txrx(j, 'read Operating Mode', packet.read1ByteTxRx, ADDR_OPERATING_MODE)
        errors, _ = self._txrx(j, 'read Hardware Error Status', packet.read1ByteTxRx,
                               ADDR_HARDWARE_ERROR)
        self._hardware_errors[j] = errors
        if mode != self.mode:
            if torque:
                self._txrx(j, 'torque off', packet.write1ByteTxRx, ADDR_TORQUE_ENABLE, 0)
                torque = 0
            _, error = self._txrx(j, 'write Operating Mode', packet.write1ByteTxRx,
                                  ADDR_OPERATING_MODE, self.mode)
            if error & 0x7F:
                raise ValueError('%s refused Operating Mode %d: %s' % (
                    self._label(j), self.mode, packet.getRxPacketError(error)))
        raw, _ = self._txrx(j, 'read Present Position', packet.read4ByteTxRx, 132)
        raw = _signed32(raw)
        offset, _ = self._txrx(j, 'read Homing Offset', packet.read4ByteTxRx, ADDR_HOMING_OFFSET)
        offset = _signed32(offset)
        self._turns[j] = 0
        if 0 <= raw - offset < TICKS_PER_REV:  # a fresh count: restart within one turn
            reference = self._last_ticks[j]
            if reference is None:
                reference = int(self.spool.zeros[j])
            self._turns[j] = int(round((reference - raw) / TICKS_PER_REV))
        self._last_ticks[j] = raw + int(self._turns[j]) * TICKS_PER_REV
        if not torque and self.power:
            self._torque_on(j, raw)
        elif torque and not self.power:
            self._txrx(j, 'torque off', packet.write1ByteTxRx, ADDR_TORQUE_ENABLE, 0)

    def _torque_on(self, j, raw):
        """Goal Position = Present Position ``raw`` (no jump), then torque on."""
        packet = self._packet
        self._txrx(j, 'write Goal Position', packet.write4ByteTxRx, ADDR_GOAL_POSITION,
                   raw & 0xFFFFFFFF)
        _, error = self._txrx(j, 'torque on', packet.write1ByteTxRx, ADDR_TORQUE_ENABLE, 1)
        if error & 0x7F:
            self._torque_refused.add(j)
        else:
            self._torque_refused.discard(j)

    def enable(self, now):
        """Torque on at the present positions (lifecycle activate)."""
        self.power = True
        if self._port is None:
            return  # the next (re)connection switches it on
        try:
            for j in range(len(self.ids)):
                torque, _ = self._txrx(j, 'read Torque Enable', self._packet.read1ByteTxRx,
                                       ADDR_TORQUE_ENABLE)
                if not torque:
                    raw, _ = self._txrx(j, 'read Present Position', self._packet.read4ByteTxRx,
                                        132)
                    self._torque_on(j, _signed32(raw))
        except self._port_errors as error:
            raise self._lost('lost while enabling', error) from None

    def disable(self, now):
        """Hold, then torque off (lifecycle deactivate): the spools can be turned by hand."""
        self.power = False
        if self._port is None:
            return
        try:
            self.hold(now)
            for j in range(len(self.ids)):
                self._txrx(j, 'torque off', self._packet.write1ByteTxRx, ADDR_TORQUE_ENABLE, 0)
        except self._port_errors as error:
            raise self._lost('lost while disabling', error) from None

    # -- cycle ----------------------------------------------------------------------------
    def _sync_read(self, address, length):
        """Sync read ``length`` bytes at ``address`` from every servo; (data list, alert list).

        One missing status packet is retried once (a lost byte, a late USB frame); a servo that
        misses twice in a row stopped answering.
        """
        try:
            return self._sync_read_once(address, length)
        except _Missing as missing:
            self.retries += 1
            try:
                self._port.clearPort()
                return self._sync_read_once(address, length)
            except _Missing:
                raise ConnectionLost(str(missing)) from None
            except ConnectionLost:
                raise
            except self._port_errors as error:
                raise self._lost('lost', error) from None

    def _sync_read_once(self, address, length):
        port, packet = self._port, self._packet
        if port is None:
            raise ConnectionLost('port %s is not open' % self.port_name)
        try:
            result = packet.syncReadTx(port, address, length, self.ids, len(self.ids), False)
            if result != sdk.COMM_SUCCESS:
                raise self._lost('sync read failed (%s)' % packet.getTxRxResult(result))
            data, alerts = [], []
            for j, servo_id in enumerate(self.ids):
                values, result, error = packet.readRx(port, servo_id, length)
                if result != sdk.COMM_SUCCESS:
                    port.is_using = False
                    raise _Missing('port %s: %s stopped answering (%s)' % (
                        self.port_name, self._label(j), packet.getTxRxResult(result)))
                data.append(bytes(values))
                alerts.append(bool(error & ALERT))
            return data, alerts
        except (ConnectionLost, _Missing):
            raise
        except self._port_errors as error:
            raise self._lost('lost', error) from None

    def command(self, target_lengths, now):
        """Sync write Goal Position for ``target_lengths`` (m)."""
        ticks = np.round(self.spool.positions(target_lengths)).astype(np.int64) - \
            self._turns * TICKS_PER_REV
        self._write_goals(ticks)

    def _write_goals(self, ticks):
        writer = self._writer
        if writer is None:
            raise ConnectionLost('port %s is not open' % self.port_name)
        writer.clearParam()
        for servo_id, tick in zip(self.ids, ticks):
            writer.addParam(servo_id, list(struct.pack('<i', int(tick))))
        try:
            result = writer.txPacket()
        except self._port_errors as error:
            raise self._lost('lost', error) from None
        if result != sdk.COMM_SUCCESS:
            raise self._lost('sync write failed (%s)' % self._packet.getTxRxResult(result))

    def hold(self, now):
        """Goal Position = the positions last read."""
        if any(t is None for t in self._last_ticks) or self._writer is None:
            return
        self._write_goals(np.array(self._last_ticks, dtype=np.int64) -
                          self._turns * TICKS_PER_REV)

    def read(self, now):
        """Sync read current, velocity, position; Hardware Error Status when a servo alerts."""
        data, alerts = self._sync_read(ADDR_PRESENT_CURRENT, PRESENT_LENGTH)
        current = np.array([struct.unpack_from('<h', d, 0)[0] for d in data], dtype=float)
        velocity = np.array([struct.unpack_from('<i', d, 2)[0] for d in data], dtype=float)
        raw = np.array([struct.unpack_from('<i', d, 6)[0] for d in data], dtype=np.int64)
        if any(alerts) or self._hardware_errors.any():
            errors, _ = self._sync_read(ADDR_HARDWARE_ERROR, 1)
            self._hardware_errors = np.array([e[0] for e in errors], dtype=np.int64)
        ticks = raw + self._turns * TICKS_PER_REV
        self._last_ticks = [int(t) for t in ticks]
        self.cycles += 1
        ticks_per_s = velocity * VELOCITY_UNIT_RPM / 60.0 * TICKS_PER_REV
        tensions = None
        if self.torque_constant > 0.0:
            tensions = self.spool.tensions(self.torque_constant * self.current_unit * current)
        return CableReading(lengths=self.spool.lengths(ticks),
                            velocities=self.spool.speeds(ticks_per_s), tensions=tensions)

    # -- health, faults, homing -----------------------------------------------------------
    def status(self):
        """ERROR naming each servo in hardware error (and its bits) or refusing torque."""
        values = {'port': self.port_name, 'connected': self._port is not None,
                  'ids': ','.join(str(i) for i in self.ids), 'read_retries': self.retries}
        problems = []
        for j in range(len(self.ids)):
            if self._hardware_errors[j]:
                problems.append('%s hardware error: %s' % (
                    self._label(j), hardware_error_text(int(self._hardware_errors[j]))))
            elif j in self._torque_refused:
                problems.append('%s refused torque on' % self._label(j))
            if self._turns[j]:
                values['turns_restored_%d' % self.ids[j]] = int(self._turns[j])
        for j, tick in enumerate(self._last_ticks):
            if tick is not None:
                values['ticks_%d' % self.ids[j]] = tick
        if problems:
            return BackendStatus(ERROR, '; '.join(problems) + ' (call cable_driver/reset)',
                                 values)
        if self._warning:
            return BackendStatus(WARN, self._warning, values)
        return BackendStatus(OK, 'dynamixel: %d servos on %s' % (len(self.ids), self.port_name),
                             values)

    def reset(self):
        """Reboot every servo in hardware error or refusing torque, then re-enable it."""
        faulted = [j for j in range(len(self.ids))
                   if self._hardware_errors[j] or j in self._torque_refused]
        if not faulted:
            return 'no servo in fault'
        if self._port is None:
            raise ConnectionLost('port %s is not open' % self.port_name)
        done = []
        try:
            for j in faulted:
                what = hardware_error_text(int(self._hardware_errors[j])) \
                    if self._hardware_errors[j] else 'torque refused'
                self._txrx(j, 'reboot', self._packet.reboot)
                deadline = time.monotonic() + 3.0  # a real X servo answers ~0.5 s after REBOOT
                while self._packet.ping(self._port, self.ids[j])[1] != sdk.COMM_SUCCESS:
                    if time.monotonic() > deadline:
                        raise self._lost('%s did not come back after REBOOT' % self._label(j))
                    time.sleep(0.05)
                self._prepare(j)
                done.append('rebooted %s (%s)' % (self._label(j), what))
        except ConnectionLost:
            raise
        except self._port_errors as error:
            raise self._lost('lost during reset', error) from None
        return '; '.join(done)

    def set_home(self):
        """Make the positions last read the straight pose; return the new ``zero_ticks``."""
        if any(t is None for t in self._last_ticks):
            raise ValueError('no position read yet')
        zeros = [int(t) for t in self._last_ticks]
        self.spool = self.spool.with_zeros(zeros)
        return zeros

    def set_option(self, key, value):
        """``torque_constant`` and ``disable_torque_on_exit`` change at run time."""
        if key == 'torque_constant':
            if not (value >= 0.0):
                raise ValueError('torque_constant must be >= 0 N m/A, got %r' % value)
            self.torque_constant = float(value)
        elif key != 'disable_torque_on_exit':
            super().set_option(key, value)
        self.options[key] = value

    def close(self):
        """Torque off (unless ``disable_torque_on_exit`` is false) and close the port."""
        if self._port is not None and self.options['disable_torque_on_exit']:
            for servo_id in self.ids:
                try:
                    self._packet.write1ByteTxRx(self._port, servo_id, ADDR_TORQUE_ENABLE, 0)
                except self._port_errors:
                    break
        self._drop_port()


class _PortHandler(sdk.PortHandler if sdk is not None else object):
    """The SDK's PortHandler with ``margin`` s more on every status-packet timeout."""

    def __init__(self, port_name, margin):
        super().__init__(port_name)
        self.margin_ms = 1000.0 * margin

    def setPacketTimeout(self, packet_length):  # noqa: N802 (the SDK's name)
        """Set the SDK's timeout for ``packet_length`` bytes, plus the margin."""
        super().setPacketTimeout(packet_length)
        self.packet_timeout += self.margin_ms

    def setPacketTimeoutMillis(self, msec):  # noqa: N802 (the SDK's name)
        """Set a timeout of ``msec`` ms plus the margin."""
        super().setPacketTimeoutMillis(msec + self.margin_ms)


class _Missing(Exception):
    """A status packet did not come (retried once before the servo counts as lost)."""


def _signed32(value):
    return struct.unpack('<i', struct.pack('<I', int(value) & 0xFFFFFFFF))[0]
