"""CANopen CiA 402 servo drives on spools, in profile position mode (``canopen`` + ``python-can``).

One drive (node) per cable, ``node_ids`` in robot-file order. At start, per node over SDO: the
device type is read (a node that does not answer is named), the producer heartbeat time is set,
the PDOs are mapped (RPDO1 = controlword + target position, TPDO1 = statusword + position
actual value, both synchronous: applied / sent at every SYNC), the mode is set to profile position
(0x6060 = 1), the target to the present position, and the drive is taken through the CiA 402
state machine (shutdown 0x06, switch on 0x07, enable operation 0x0F) to OPERATION ENABLED; then
NMT start and the SYNC producer (``sync_period``).

Set-points use the profile position handshake: the new target goes out with controlword bit 4
(new set-point) and bit 5 (change set immediately); once the drive sets statusword bit 12
(set-point acknowledge) bit 4 is cleared, and the next target waits until the drive has cleared
bit 12. A target that changes meanwhile replaces the waiting one.

Health: a node whose heartbeat is older than ``heartbeat_timeout`` (or whose TPDO stops) makes
``read`` raise :class:`ConnectionLost` naming it; a drive in FAULT is ERROR with its EMCY codes
decoded; :meth:`reset` does the fault reset (rising edge of controlword bit 7) and re-enables.
"""
from pathlib import Path
import threading
import time

import numpy as np

from continuum_statics.drivers.base import (
    ERROR,
    OK,
    BackendOption,
    BackendStatus,
    CableBackend,
    CableReading,
    ConnectionLost,
)
from continuum_statics.drivers.spool import Spool, per_cable

try:
    import can
    import canopen
except ImportError as _error:  # reported when the backend is constructed
    canopen = None
    _IMPORT_ERROR = _error

#: The minimal CiA 402 EDS shipped in the package (for drives without their own file).
DEFAULT_EDS = Path(__file__).with_name('cia402_minimal.eds')
CONTROLWORD, STATUSWORD, MODE, POSITION_ACTUAL, TARGET = 0x6040, 0x6041, 0x6060, 0x6064, 0x607A
PROFILE_VELOCITY, HEARTBEAT_TIME, DEVICE_TYPE, ERROR_CODE = 0x6081, 0x1017, 0x1000, 0x603F
PROFILE_POSITION = 1
SHUTDOWN, SWITCH_ON, ENABLE_OPERATION, FAULT_RESET = 0x06, 0x07, 0x0F, 0x80
NEW_SETPOINT, CHANGE_IMMEDIATELY = 0x10, 0x20
FAULT_BIT, SETPOINT_ACK = 0x08, 0x1000
#: CiA 402 states from the statusword: (mask, value, name).
STATES = [(0x4F, 0x00, 'NOT READY TO SWITCH ON'), (0x4F, 0x40, 'SWITCH ON DISABLED'),
          (0x6F, 0x21, 'READY TO SWITCH ON'), (0x6F, 0x23, 'SWITCHED ON'),
          (0x6F, 0x27, 'OPERATION ENABLED'), (0x6F, 0x07, 'QUICK STOP ACTIVE'),
          (0x4F, 0x0F, 'FAULT REACTION ACTIVE'), (0x4F, 0x08, 'FAULT')]
#: EMCY error codes (CiA 301 / CiA 402 Annex) decoded on diagnostics.
EMCY_CODES = {
    0x1000: 'generic error', 0x2310: 'continuous over-current', 0x2320: 'short circuit',
    0x3210: 'DC link over-voltage', 0x3220: 'DC link under-voltage',
    0x4210: 'excess temperature device', 0x4310: 'excess temperature drive',
    0x5112: 'supply voltage low', 0x5530: 'EEPROM fault', 0x6010: 'software reset (watchdog)',
    0x7121: 'motor blocked', 0x7300: 'sensor fault', 0x7305: 'incremental sensor 1 fault',
    0x8110: 'CAN overrun', 0x8120: 'CAN error passive', 0x8130: 'heartbeat / life guard error',
    0x8140: 'recovered from bus off', 0x8611: 'following error', 0x8612: 'reference limit',
    0xFF00: 'device specific',
}
EMCY_CLASSES = {0x2: 'current', 0x3: 'voltage', 0x4: 'temperature', 0x5: 'device hardware',
                0x6: 'device software', 0x7: 'additional modules', 0x8: 'monitoring',
                0x9: 'external error', 0xF: 'additional functions'}


def state_name(statusword):
    """CiA 402 state of a statusword (e.g. 'OPERATION ENABLED')."""
    for mask, value, name in STATES:
        if statusword & mask == value:
            return name
    return 'UNKNOWN (0x%04x)' % statusword


def emcy_text(code):
    """'0x2310 continuous over-current' for an EMCY error code."""
    description = EMCY_CODES.get(code) or EMCY_CLASSES.get(code >> 12, 'unknown')
    return '0x%04X %s' % (code, description)


class CanopenCableBackend(CableBackend):
    """CiA 402 drives (profile position mode) driving cable spools over CANopen."""

    name = 'canopen'
    zero_option = 'zero_counts'
    options_spec = (
        BackendOption('interface', 'socketcan', 'python-can interface: socketcan, pcan, '
                      'kvaser, virtual, ...', read_only=True),
        BackendOption('channel', 'can0', 'python-can channel', read_only=True),
        BackendOption('bitrate', 1000000, 'CAN bit rate, bit/s', 10000, 1000000,
                      read_only=True),
        BackendOption('node_ids', [1, 2, 3, 4], 'node id per cable, robot-file order',
                      read_only=True),
        BackendOption('eds', '', 'EDS file of the drives (empty: the minimal CiA 402 EDS '
                      'shipped in the package)', read_only=True),
        BackendOption('counts_per_rev', 4096, 'position counts per motor revolution', 1,
                      2 ** 31 - 1, read_only=True),
        BackendOption('gear_ratio', 1.0, 'motor revolutions per spool revolution', 1e-6, 1e6,
                      read_only=True),
        BackendOption('spool_radius', 0.01, 'spool radius, m', 1e-4, 1.0, read_only=True),
        BackendOption('directions', [1], '+1/-1 per cable (one value: all); +1 = rising '
                      'position lengthens the cable', read_only=True),
        BackendOption('zero_counts', [0], 'position at the straight pose per cable, counts '
                      '(one value: all; home_file overrides)', read_only=True),
        BackendOption('sync_period', 0.01, 'SYNC period, s (PDOs are exchanged on SYNC)',
                      0.0005, 1.0, read_only=True),
        BackendOption('heartbeat_period', 0.1, 'producer heartbeat time written to 0x1017, s',
                      0.01, 10.0, read_only=True),
        BackendOption('heartbeat_timeout', 0.5, 'a node silent this long is lost, s', 0.05,
                      10.0),
        BackendOption('profile_velocity', 0, 'profile velocity 0x6081, counts/s (0: leave '
                      "the drive's)", 0, 2 ** 31 - 1, read_only=True),
        BackendOption('sdo_timeout', 0.3, 'SDO response timeout, s', 0.01, 5.0,
                      read_only=True),
        BackendOption('disable_on_exit', True, 'shutdown (power stage off) when the driver '
                      'exits'),
    )

    def __init__(self, cable_names, length_limits, initial_lengths, **options):
        if canopen is None:
            raise ValueError('the canopen backend needs canopen and python-can (pip install '
                             'canopen python-can): %s' % _IMPORT_ERROR)
        super().__init__(cable_names, length_limits, initial_lengths, **options)
        merged = self.options
        n = len(self.cable_names)
        self.node_ids = [int(i) for i in per_cable('node_ids', merged['node_ids'], n, True)]
        if len(set(self.node_ids)) != n or not all(1 <= i <= 127 for i in self.node_ids):
            raise ValueError('node_ids must be %d distinct ids in 1..127, got %s'
                             % (n, self.node_ids))
        self.eds = Path(merged['eds'] or DEFAULT_EDS).expanduser()
        if not self.eds.is_file():
            raise ValueError('eds file %s does not exist' % self.eds)
        self.spool = Spool.from_options(
            self.initial_lengths, merged['directions'],
            per_cable('zero_counts', merged['zero_counts'], n, True), merged['spool_radius'],
            float(merged['counts_per_rev']), float(merged['gear_ratio']))
        self.bus_name = '%s:%s' % (merged['interface'], merged['channel'])
        self.heartbeat_timeout = float(merged['heartbeat_timeout'])
        self._network = None
        self._nodes = []
        self._lock = threading.Lock()  # EMCY callbacks arrive on the CAN notifier thread
        self._emcy = [[] for _ in range(n)]
        self._positions = np.zeros(n, dtype=np.int64)
        self._statuswords = np.zeros(n, dtype=np.int64)
        self._wanted = [None] * n
        self._sent = [None] * n
        self._bit4 = [False] * n
        self._started = 0.0
        self.setpoints = 0

    def _label(self, j):
        return 'node %d (%s)' % (self.node_ids[j], self.cable_names[j])

    # -- connection -----------------------------------------------------------------------
    def _drop_network(self):
        network, self._network, self._nodes = self._network, None, []
        if network is None:
            return
        try:
            network.sync.stop()
        except Exception:  # the bus is gone already
            pass
        try:
            network.disconnect()
        except Exception:
            pass

    def _lost(self, what):
        self._drop_network()
        return ConnectionLost('CAN bus %s: %s' % (self.bus_name, what))

    def start(self, now):
        """Connect, configure every node over SDO, enable it, NMT start, SYNC on.

        :raises ConnectionLost: the bus does not open or a node does not answer (named)
        """
        self._drop_network()
        options = self.options
        network = canopen.Network()
        try:
            network.connect(interface=options['interface'], channel=options['channel'],
                            bitrate=int(options['bitrate']))
        except (can.CanError, OSError, ValueError, ImportError) as error:
            raise ConnectionLost('CAN bus %s cannot be opened: %s' % (self.bus_name, error)) \
                from None
        self._network = network
        nodes = []
        for node_id in self.node_ids:
            node = canopen.RemoteNode(node_id, str(self.eds))
            node.sdo.RESPONSE_TIMEOUT = float(options['sdo_timeout'])
            network.add_node(node)
            nodes.append(node)
        self._nodes = nodes
        missing = []
        for j, node in enumerate(nodes):
            try:
                node.sdo[DEVICE_TYPE].raw
            except canopen.SdoCommunicationError:
                missing.append(self._label(j))
            except (can.CanError, OSError) as error:
                raise self._lost('lost during start: %s' % error) from None
        if missing:
            raise self._lost('%s not answering' % ', '.join(missing))
        with self._lock:
            self._emcy = [[] for _ in nodes]
        try:
            for j, node in enumerate(nodes):
                self._configure(j, node)
            self._started = time.time()
            for node in nodes:
                node.nmt.state = 'OPERATIONAL'
            network.sync.start(float(options['sync_period']))
        except (canopen.SdoCommunicationError, can.CanError, OSError) as error:
            raise self._lost('lost during start: %s' % error) from None

    def _configure(self, j, node):
        node.nmt.state = 'PRE-OPERATIONAL'
        node.sdo[HEARTBEAT_TIME].raw = int(round(self.options['heartbeat_period'] * 1000))
        node.emcy.add_callback(lambda error, j=j: self._on_emcy(j, error))
        # PDO mapping: RPDO1 out, TPDO1 in, both on SYNC; the second ones off.
        sync = 1
        for pdo, number, cob, entries in ((node.rpdo, 1, 0x200, (CONTROLWORD, TARGET)),
                                          (node.tpdo, 1, 0x180, (STATUSWORD, POSITION_ACTUAL)),
                                          (node.rpdo, 2, 0x300, ()), (node.tpdo, 2, 0x280, ())):
            pdo_map = pdo[number]
            pdo_map.clear()
            for index in entries:
                pdo_map.add_variable(index)
            pdo_map.cob_id = cob + node.id
            pdo_map.trans_type = sync
            pdo_map.enabled = bool(entries)
            pdo_map.save()
        node.sdo[MODE].raw = PROFILE_POSITION
        if self.options['profile_velocity']:
            node.sdo[PROFILE_VELOCITY].raw = int(self.options['profile_velocity'])
        if self.power:
            self._enable(j, node)
        else:
            self._read_position(j, node, SHUTDOWN)

    def _read_position(self, j, node, controlword):
        """Target = actual position (no jump); RPDO1 carries ``controlword``; the statusword."""
        position = node.sdo[POSITION_ACTUAL].raw
        self._positions[j] = position
        statusword = node.sdo[STATUSWORD].raw
        self._statuswords[j] = statusword
        self._wanted[j] = self._sent[j] = position
        self._bit4[j] = False
        rpdo = node.rpdo[1]
        rpdo[CONTROLWORD].raw = controlword
        rpdo[TARGET].raw = position
        return position, statusword

    def _enable(self, j, node):
        """Target = actual position, then through the state machine (unless in FAULT)."""
        position, statusword = self._read_position(j, node, ENABLE_OPERATION)
        if statusword & FAULT_BIT:
            return
        node.sdo[TARGET].raw = position
        for word, wanted in ((SHUTDOWN, 'READY TO SWITCH ON'), (SWITCH_ON, 'SWITCHED ON'),
                             (ENABLE_OPERATION, 'OPERATION ENABLED')):
            node.sdo[CONTROLWORD].raw = word
            statusword = self._wait_state(node, wanted)
        self._statuswords[j] = statusword

    @staticmethod
    def _wait_state(node, wanted, timeout=1.0):
        deadline = time.monotonic() + timeout
        while True:
            statusword = node.sdo[STATUSWORD].raw
            if state_name(statusword) == wanted or time.monotonic() > deadline:
                return statusword
            time.sleep(0.002)

    def _on_emcy(self, j, error):
        with self._lock:
            if error.code & 0xFF00 == 0:  # error reset / no error
                self._emcy[j] = []
            elif error.code not in (e.code for e in self._emcy[j]):
                self._emcy[j].append(error)

    # -- cycle --------------------------------------------------------------------------------
    def _check(self):
        network = self._network
        if network is None:
            raise ConnectionLost('CAN bus %s is not open' % self.bus_name)
        try:
            network.check()
        except Exception as error:  # the notifier thread died: the adapter is gone
            raise self._lost('receive failed: %s' % error) from None
        now = time.time()
        silent = []
        for j, node in enumerate(self._nodes):
            last = node.nmt.timestamp or self._started
            if now - max(last, self._started) > self.heartbeat_timeout:
                silent.append('%s (no heartbeat for %.2f s)' % (self._label(j), now - last))
        if silent:
            raise self._lost(', '.join(silent) + ' lost')

    def _step(self, j, node):
        """Advance the set-point handshake of node j and send its RPDO (cyclic, every call).

        Sending the RPDO every cycle (as CANopen masters do) also repeats a set-point whose
        first RPDO the drive missed, so the handshake cannot stall.
        """
        ack = bool(self._statuswords[j] & SETPOINT_ACK)
        word = ENABLE_OPERATION | CHANGE_IMMEDIATELY
        if not self.power:  # powered off (lifecycle inactive): keep saying Shutdown, no set-point
            word = SHUTDOWN
        elif self._bit4[j]:
            if ack:  # acknowledged: clear bit 4
                self._bit4[j] = False
            else:
                word |= NEW_SETPOINT
        elif not ack and self._wanted[j] != self._sent[j] and not (
                self._statuswords[j] & FAULT_BIT):
            self._sent[j] = self._wanted[j]
            self._bit4[j] = True
            word |= NEW_SETPOINT
            self.setpoints += 1
        rpdo = node.rpdo[1]
        rpdo[CONTROLWORD].raw = word
        rpdo[TARGET].raw = int(self._sent[j])
        try:
            rpdo.transmit()
        except (can.CanError, OSError) as error:
            raise self._lost('send failed: %s' % error) from None

    def command(self, target_lengths, now):
        """Queue the targets (counts) and start the handshake where it is free."""
        self._check()
        counts = np.round(self.spool.positions(target_lengths)).astype(np.int64)
        for j, node in enumerate(self._nodes):
            self._wanted[j] = int(counts[j])
            self._step(j, node)

    def enable(self, now):
        """Every drive to OPERATION ENABLED at its actual position (lifecycle activate)."""
        self.power = True
        if self._network is None:
            return  # the next (re)connection enables them
        try:
            for j, node in enumerate(self._nodes):
                self._enable(j, node)
        except (canopen.SdoCommunicationError, can.CanError, OSError) as error:
            raise self._lost('lost while enabling: %s' % error) from None

    def disable(self, now):
        """Hold, then Shutdown (READY TO SWITCH ON: power stage off; lifecycle deactivate)."""
        self.power = False
        if self._network is None:
            return
        try:
            for j, node in enumerate(self._nodes):
                self._read_position(j, node, SHUTDOWN)
                node.sdo[CONTROLWORD].raw = SHUTDOWN
                self._statuswords[j] = self._wait_state(node, 'READY TO SWITCH ON')
        except (canopen.SdoCommunicationError, can.CanError, OSError) as error:
            raise self._lost('lost while disabling: %s' % error) from None

    def hold(self, now):
        """Target = the positions last read."""
        if self._network is None:
            return
        for j, node in enumerate(self._nodes):
            self._wanted[j] = int(self._positions[j])
            self._step(j, node)

    def read(self, now):
        """Statusword and position from TPDO1; lengths; the handshake advances.

        :raises ConnectionLost: a node's TPDO1 is older than ``heartbeat_timeout`` (it left
            OPERATIONAL or stopped sending): its position would be stale
        """
        self._check()
        wall = time.time()
        stale = []
        for j, node in enumerate(self._nodes):
            tpdo = node.tpdo[1]
            last = tpdo.timestamp if tpdo.timestamp is not None else self._started
            if wall - max(last, self._started) > self.heartbeat_timeout:
                stale.append('%s (no TPDO for %.2f s, NMT %s)' % (
                    self._label(j), wall - last, node.nmt.state))
                continue
            if tpdo.timestamp is not None:
                self._statuswords[j] = tpdo[STATUSWORD].raw
                self._positions[j] = tpdo[POSITION_ACTUAL].raw
            self._step(j, node)
        if stale:
            raise self._lost(', '.join(stale))
        return CableReading(lengths=self.spool.lengths(self._positions))

    # -- health, faults, homing -----------------------------------------------------------
    def status(self):
        """ERROR naming each node in FAULT (with its EMCY codes) or not enabled."""
        values = {'bus': self.bus_name, 'connected': self._network is not None,
                  'setpoints': self.setpoints}
        problems = []
        with self._lock:
            emcy = [list(e) for e in self._emcy]
        for j in range(len(self.node_ids)):
            state = state_name(int(self._statuswords[j]))
            values['state_%d' % self.node_ids[j]] = state
            values['position_%d' % self.node_ids[j]] = int(self._positions[j])
            codes = ', '.join('EMCY ' + emcy_text(e.code) for e in emcy[j])
            wanted = 'OPERATION ENABLED' if self.power else 'READY TO SWITCH ON'
            if state != wanted and self._network is not None:
                problems.append('%s %s%s' % (self._label(j), state.lower(),
                                             ': ' + codes if codes else ''))
            elif codes:
                values['emcy_%d' % self.node_ids[j]] = codes
        if problems:
            return BackendStatus(ERROR, '; '.join(problems) + ' (call cable_driver/reset)',
                                 values)
        return BackendStatus(OK, 'canopen: %d drives on %s' % (len(self.node_ids),
                                                                self.bus_name), values)

    def reset(self):
        """Fault reset (rising edge of controlword bit 7) and re-enable every drive not enabled."""
        if self._network is None:
            raise ConnectionLost('CAN bus %s is not open' % self.bus_name)
        done = []
        try:
            for j, node in enumerate(self._nodes):
                statusword = node.sdo[STATUSWORD].raw
                state = state_name(statusword)
                if state == 'OPERATION ENABLED':
                    continue
                with self._lock:
                    codes = ', '.join('EMCY ' + emcy_text(e.code) for e in self._emcy[j])
                if statusword & FAULT_BIT:
                    node.sdo[CONTROLWORD].raw = 0
                    node.sdo[CONTROLWORD].raw = FAULT_RESET
                    self._wait_state(node, 'SWITCH ON DISABLED')
                self._enable(j, node)
                state = state_name(int(self._statuswords[j]))
                done.append('%s: %s%s -> %s' % (
                    self._label(j), 'fault reset' if statusword & FAULT_BIT else 're-enabled',
                    ' (%s)' % codes if codes else '', state.lower()))
        except (canopen.SdoCommunicationError, can.CanError, OSError) as error:
            raise self._lost('lost during reset: %s' % error) from None
        return '; '.join(done) or 'no drive in fault'

    def set_home(self):
        """Make the positions last read the straight pose; return the new ``zero_counts``."""
        zeros = [int(p) for p in self._positions]
        self.spool = self.spool.with_zeros(zeros)
        return zeros

    def set_option(self, key, value):
        """``heartbeat_timeout`` and ``disable_on_exit`` change at run time."""
        if key == 'heartbeat_timeout':
            self.heartbeat_timeout = float(value)
        elif key != 'disable_on_exit':
            super().set_option(key, value)
        self.options[key] = value

    def close(self):
        """Shutdown (power stage off) unless ``disable_on_exit`` is false; leave the bus."""
        if self._network is not None:
            try:
                self._network.sync.stop()
                for node in self._nodes:
                    if self.options['disable_on_exit']:
                        node.sdo[CONTROLWORD].raw = SHUTDOWN
                    node.nmt.state = 'PRE-OPERATIONAL'
            except Exception:  # best effort: the bus may be gone
                pass
        self._drop_network()
