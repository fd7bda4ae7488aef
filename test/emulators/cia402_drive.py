"""CiA 402 servo drives as ``canopen.LocalNode`` objects on a python-can ``virtual`` bus.

Written from CiA 301 / CiA 402, not from the backend under test (the object dictionary is built
here in code, not read from the EDS the package ships):

- NMT: a drive boots (boot-up message 0x700+id, data 0), is PRE-OPERATIONAL, and exchanges PDOs
  only when OPERATIONAL; it produces heartbeats (0x700+id, its NMT state) every 0x1017 ms;
- PDOs: the RPDO/TPDO communication (0x1400/0x1800: COB-ID, transmission type) and mapping
  (0x1600/0x1A00: ``index << 16 | subindex << 8 | bits``) objects are whatever the master wrote
  by SDO; a received synchronous RPDO (type 0..240) is applied at the next SYNC (0x80), an
  asynchronous one (254/255) at once; a TPDO of type n in 1..240 goes out on every n-th SYNC;
- the CiA 402 drive state machine on the controlword (0x6040), statusword (0x6041):
  Switch on disabled -> (shutdown 0x06) Ready to switch on -> (switch on 0x07) Switched on ->
  (enable operation 0x0F) Operation enabled; disable voltage, quick stop, disable operation;
  a fault (with an EMCY 0x80+id: error code, error register 0x1001) goes to Fault, and a rising
  edge of controlword bit 7 resets it (EMCY 0x0000) to Switch on disabled;
- profile position mode (0x6060 = 1): a rising edge of controlword bit 4 (new set-point) takes
  the target position 0x607A and sets statusword bit 12 (set-point acknowledge) until bit 4 falls;
  bit 5 (change set immediately); statusword bit 10 (target reached) once the position is there;
  the position 0x6064 moves towards the target at the profile velocity 0x6081.
"""
import struct
import threading
import time

import canopen
from canopen import objectdictionary as od_types
from canopen.objectdictionary import ObjectDictionary, ODArray, ODRecord, ODVariable

SYNC_ID = 0x80
#: Statusword bits.
READY, SWITCHED_ON, ENABLED, FAULT, VOLTAGE, QUICK_STOP, DISABLED = (1 << b for b in (
    0, 1, 2, 3, 4, 5, 6))
TARGET_REACHED, SETPOINT_ACK = 1 << 10, 1 << 12
STATES = {
    'SWITCH ON DISABLED': DISABLED,
    'READY TO SWITCH ON': READY | QUICK_STOP | VOLTAGE,
    'SWITCHED ON': READY | SWITCHED_ON | QUICK_STOP | VOLTAGE,
    'OPERATION ENABLED': READY | SWITCHED_ON | ENABLED | QUICK_STOP | VOLTAGE,
    'QUICK STOP ACTIVE': READY | SWITCHED_ON | ENABLED | VOLTAGE,
    'FAULT': FAULT,
}
#: EMCY codes (CiA 301 / 402) the tests inject.
OVER_CURRENT, OVER_VOLTAGE, DRIVE_TEMPERATURE, FOLLOWING_ERROR = 0x2310, 0x3210, 0x4310, 0x8611


def _object_dictionary():
    od = ObjectDictionary()

    def var(index, name, data_type, access='rw', default=0, subindex=0, pdo=False):
        variable = ODVariable(name, index, subindex)
        variable.data_type, variable.access_type, variable.default = data_type, access, default
        variable.pdo_mappable = pdo
        return variable

    for index, name, data_type, access, default in [
            (0x1000, 'Device type', od_types.UNSIGNED32, 'ro', 0x00020192),
            (0x1001, 'Error register', od_types.UNSIGNED8, 'ro', 0),
            (0x1017, 'Producer heartbeat time', od_types.UNSIGNED16, 'rw', 0),
            (0x603F, 'Error code', od_types.UNSIGNED16, 'ro', 0),
            (0x6040, 'Controlword', od_types.UNSIGNED16, 'rw', 0),
            (0x6041, 'Statusword', od_types.UNSIGNED16, 'ro', 0),
            (0x6060, 'Modes of operation', od_types.INTEGER8, 'rw', 0),
            (0x6061, 'Modes of operation display', od_types.INTEGER8, 'ro', 0),
            (0x6064, 'Position actual value', od_types.INTEGER32, 'ro', 0),
            (0x606C, 'Velocity actual value', od_types.INTEGER32, 'ro', 0),
            (0x607A, 'Target position', od_types.INTEGER32, 'rw', 0),
            (0x6081, 'Profile velocity', od_types.UNSIGNED32, 'rw', 0)]:
        od.add_object(var(index, name, data_type, access, default, pdo=index >= 0x6000))
    for number in range(4):
        for base, kind, cob in ((0x1400, 'RPDO', 0x200), (0x1800, 'TPDO', 0x180)):
            record = ODRecord('%s %d communication' % (kind, number + 1), base + number)
            record.add_member(var(base + number, 'count', od_types.UNSIGNED8, 'const', 5, 0))
            record.add_member(var(base + number, 'COB-ID', od_types.UNSIGNED32, 'rw',
                                  cob + 0x100 * number, 1))
            record.add_member(var(base + number, 'type', od_types.UNSIGNED8, 'rw', 255, 2))
            record.add_member(var(base + number, 'inhibit', od_types.UNSIGNED16, 'rw', 0, 3))
            record.add_member(var(base + number, 'event timer', od_types.UNSIGNED16, 'rw', 0, 5))
            od.add_object(record)
        for base, kind in ((0x1600, 'RPDO'), (0x1A00, 'TPDO')):
            array = ODArray('%s %d mapping' % (kind, number + 1), base + number)
            array.add_member(var(base + number, 'count', od_types.UNSIGNED8, 'rw', 0, 0))
            for sub in range(1, 9):
                array.add_member(var(base + number, 'entry %d' % sub, od_types.UNSIGNED32,
                                     'rw', 0, sub))
            od.add_object(array)
    return od


class Cia402Drive:
    """One servo drive: a LocalNode plus its state machine and motion.

    :param network: a connected ``canopen.Network`` (the drives' side of the bus)
    :param node_id: CANopen node id
    :param position: initial position actual value, counts
    :param speed: profile velocity used when 0x6081 is 0, counts/s
    """

    def __init__(self, network, node_id, position=0, speed=200000.0):
        self.node = canopen.LocalNode(node_id, _object_dictionary())
        self.node_id = node_id
        self.lock = threading.RLock()
        self.position = float(position)
        self.target = float(position)
        self.default_speed = float(speed)
        self.state = 'SWITCH ON DISABLED'
        self.controlword = 0
        self.ack = False
        self.online = True
        self.sync_count = 0
        self.pending_rpdo = {}
        self.applied = []  # controlwords applied, in order (the handshake, for tests)
        self._last_time = time.monotonic()
        self.node.add_write_callback(self._on_write)
        self.node.add_read_callback(self._on_read)
        network.add_node(self.node)
        self.network = network
        self._subscriptions = []
        self._subscribe(SYNC_ID, self._on_sync)
        for number in range(4):
            self._subscribe(0x200 + 0x100 * number + node_id, self._on_rpdo)
        self.boot()

    def _subscribe(self, can_id, callback):
        self.network.subscribe(can_id, callback)
        self._subscriptions.append((can_id, callback))

    # -- NMT ------------------------------------------------------------------------------------
    def boot(self):
        """Power-up: boot-up message, PRE-OPERATIONAL, heartbeat, Switch on disabled."""
        with self.lock:
            self.state = 'SWITCH ON DISABLED'
            self.controlword = 0
            self.ack = False
            self._store(0x1001, 0, 0)
            self._store(0x603F, 0, 0)
            self.node.nmt.stop_heartbeat()
            self.node.nmt._state = 0
            self.network.send_message(0x700 + self.node_id, [0])
            self.node.nmt._state = 127
            heartbeat = self._get(0x1017, 0)
            if heartbeat:
                self.node.nmt.start_heartbeat(heartbeat)

    def set_online(self, online):
        """Cut (False) or restore (True) the drive's CAN connection; it reboots when restored."""
        with self.lock:
            if bool(online) == self.online:
                return
            self.online = bool(online)
            links = [(self.node.sdo.rx_cobid, self.node.sdo.on_request),
                     (0, self.node.nmt.on_command)] + self._subscriptions
            if not online:
                self.node.nmt.stop_heartbeat()
                for can_id, callback in links:
                    self.network.unsubscribe(can_id, callback)
            else:
                for can_id, callback in links:
                    self.network.subscribe(can_id, callback)
                self.boot()

    @property
    def operational(self):
        """True when the NMT state is OPERATIONAL."""
        return self.node.nmt.state == 'OPERATIONAL'

    # -- object dictionary -------------------------------------------------------------------
    def _store(self, index, subindex, value):
        raw = self.node.object_dictionary[index]
        variable = raw if isinstance(raw, ODVariable) else raw[subindex]
        self.node.data_store.setdefault(index, {})[subindex] = variable.encode_raw(value)

    def _get(self, index, subindex):
        """Return the stored value of an object (no read callbacks: the drive's memory)."""
        raw = self.node.object_dictionary[index]
        variable = raw if isinstance(raw, ODVariable) else raw[subindex]
        data = self.node.data_store.get(index, {}).get(subindex)
        return variable.default if data is None else variable.decode_raw(data)

    def _on_read(self, index, subindex, od):
        if index not in (0x6041, 0x6064, 0x6061):
            return None
        with self.lock:
            self._advance()
            if index == 0x6041:
                return self.statusword
            if index == 0x6064:
                return int(round(self.position))
            if index == 0x6061:
                return self._get(0x6060, 0)
        return None

    def _on_write(self, index, subindex, od, data):
        if not self.online:
            return
        if index == 0x6040:
            with self.lock:
                self._controlword(struct.unpack('<H', data)[0])

    # -- CiA 402 ------------------------------------------------------------------------------
    @property
    def statusword(self):
        """Statusword 0x6041 of the present state, with target reached and set-point ack."""
        word = STATES[self.state]
        if self.state == 'OPERATION ENABLED' and abs(self.position - self.target) < 0.5:
            word |= TARGET_REACHED
        if self.ack:
            word |= SETPOINT_ACK
        return word | 1 << 9  # remote

    def _controlword(self, word):
        previous, self.controlword = self.controlword, word
        self.applied.append(word)
        if self.state == 'FAULT':
            if word & 0x80 and not previous & 0x80:
                self.state = 'SWITCH ON DISABLED'
                self._store(0x1001, 0, 0)
                self._store(0x603F, 0, 0)
                self.node.emcy.send(0x0000, 0)
            return
        command = word & 0x0F
        if not command & 0x02:  # disable voltage
            self.state = 'SWITCH ON DISABLED'
        elif not command & 0x04:  # quick stop
            self.state = 'QUICK STOP ACTIVE' if self.state == 'OPERATION ENABLED' else \
                'SWITCH ON DISABLED'
        elif command & 0x07 == 0x06:  # shutdown
            self.state = 'READY TO SWITCH ON'
        elif command == 0x07:  # switch on / disable operation
            if self.state in ('READY TO SWITCH ON', 'OPERATION ENABLED'):
                self.state = 'SWITCHED ON'
        elif command == 0x0F:  # enable operation (switch on first from ready)
            if self.state in ('READY TO SWITCH ON', 'SWITCHED ON', 'QUICK STOP ACTIVE'):
                self.state = 'OPERATION ENABLED'
        if self.state != 'OPERATION ENABLED':
            self.ack = False
            return
        # Profile position: set-point handshake on bit 4.
        if self._get(0x6060, 0) == 1:
            if word & 0x10 and not previous & 0x10 and not self.ack:
                self.target = float(self._get(0x607A, 0))
                self.ack = True
            elif not word & 0x10:
                self.ack = False

    def fault(self, code, register=0x01):
        """Enter Fault with an EMCY ``code`` (error register ``register``)."""
        with self.lock:
            self.state = 'FAULT'
            self.ack = False
            self.target = self.position
            self._store(0x1001, 0, register)
            self._store(0x603F, 0, code)
            if self.online:
                self.node.emcy.send(code, register)

    def _advance(self):
        now = time.monotonic()
        dt, self._last_time = now - self._last_time, now
        if self.state != 'OPERATION ENABLED':
            return
        speed = self._get(0x6081, 0) or self.default_speed
        gap = self.target - self.position
        self.position += max(-speed * dt, min(speed * dt, gap))

    # -- PDOs ---------------------------------------------------------------------------------
    def _mapping(self, base, number):
        entries = []
        for sub in range(1, self._get(base + number, 0) + 1):
            value = self._get(base + number, sub)
            entries.append((value >> 16, (value >> 8) & 0xFF, value & 0xFF))
        return entries

    def _on_rpdo(self, can_id, data, timestamp):
        if not (self.online and self.operational):
            return
        number = (can_id - self.node_id - 0x200) // 0x100
        cob = self._get(0x1400 + number, 1)
        if cob & 0x80000000 or cob & 0x7FF != can_id:
            return
        with self.lock:
            if self._get(0x1400 + number, 2) <= 240:
                self.pending_rpdo[number] = bytes(data)  # applied at the next SYNC
            else:
                self._apply_rpdo(number, bytes(data))

    def _apply_rpdo(self, number, data):
        """Store the mapped objects, then act on the controlword (a PDO applies as a whole)."""
        offset, controlword = 0, None
        for index, subindex, bits in self._mapping(0x1600, number):
            size = bits // 8
            chunk = data[offset:offset + size]
            offset += size
            if index == 0x6040:
                controlword = struct.unpack('<H', chunk)[0]
            else:
                self.node.data_store.setdefault(index, {})[subindex] = chunk
        if controlword is not None:
            self._controlword(controlword)

    def _on_sync(self, can_id, data, timestamp):
        if not (self.online and self.operational):
            return
        with self.lock:
            self.sync_count += 1
            pending, self.pending_rpdo = self.pending_rpdo, {}
            for number, payload in sorted(pending.items()):
                self._apply_rpdo(number, payload)
            self._advance()
            frames = []
            for number in range(4):
                cob = self._get(0x1800 + number, 1)
                kind = self._get(0x1800 + number, 2)
                if cob & 0x80000000 or not 1 <= kind <= 240 or self.sync_count % kind:
                    continue
                payload = b''.join(self.node.get_data(index, subindex)[:bits // 8]
                                   for index, subindex, bits in self._mapping(0x1A00, number))
                frames.append((cob & 0x7FF, payload))
        for cob, payload in frames:
            self.network.send_message(cob, payload)

    def close(self):
        """Stop the heartbeat and leave the bus."""
        self.set_online(False)


class Cia402Bus:
    """Drives on a python-can ``virtual`` channel (the master connects to the same channel).

    :param node_ids: node ids of the drives
    :param channel: virtual channel name (unique per test)
    :param positions: initial positions, counts
    """

    def __init__(self, node_ids, channel, positions=None):
        self.channel = channel
        self.network = canopen.Network()
        self.network.connect(interface='virtual', channel=channel, receive_own_messages=False)
        positions = positions or [0] * len(node_ids)
        self.drives = {node_id: Cia402Drive(self.network, node_id, position)
                       for node_id, position in zip(node_ids, positions)}

    def close(self):
        """Stop every drive and disconnect."""
        for drive in self.drives.values():
            drive.close()
        self.network.disconnect()
