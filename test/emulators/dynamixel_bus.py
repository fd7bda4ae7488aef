"""A ROBOTIS Protocol 2.0 bus of X-series servos on a pseudo-terminal.

Written from the ROBOTIS e-Manual (Protocol 2.0 and the XM430-W350 control table), not from the
backend under test:

- instruction packet ``FF FF FD 00 ID LEN_L LEN_H INST PARAM... CRC_L CRC_H``; LEN counts INST,
  the (stuffed) parameters and the CRC; status packets carry INST 0x55 and an ERR byte whose bit
  7 is the hardware-alert flag and whose low 7 bits are the error number (1 result fail,
  2 instruction, 3 CRC, 4 data range, 5 data length, 6 data limit, 7 access);
- CRC-16 with polynomial 0x8005 (no reflection, initial value 0) over header to last parameter;
- byte stuffing: ``FF FF FD`` inside INST..PARAM is sent as ``FF FF FD FD``;
- PING, READ, WRITE, REBOOT, SYNC_READ (0x82, one status packet per id, in the order asked),
  SYNC_WRITE (0x83, no status);
- control table: Model Number 0 (XM430-W350: 1020), ID 7, Return Delay Time 9 (2 us units,
  default 250), Operating Mode 11, Homing Offset 20, Shutdown 63 (default 0x34), Torque Enable
  64, Hardware Error Status 70, Goal Position 116, Present Current 126 (2.69 mA units),
  Present Velocity 128 (0.229 rpm units), Present Position 132; the EEPROM area (address < 64)
  is write-locked while torque is on (access error);
- a hardware error whose bit is set in Shutdown turns the torque off; status packets then carry
  the alert bit and torque stays off until REBOOT;
- power-up and REBOOT keep the shaft where it is but lose the multi-turn count: Present Position
  restarts within one turn (0..4095, plus Homing Offset).

The wire is simulated at ``baudrate`` (10 bits per byte): the reply to an instruction is written
only when the instruction and the reply would have crossed a real half-duplex bus.

Run alone (another process) with ``python -m emulators.dynamixel_bus --ids 1 2 3 4 --link PATH``
from ``test/``; it prints ``ready PATH`` and reads commands on stdin (``fault ID BITS``,
``power_cycle ID``, ``offline ID``, ``online ID``, ``vanish``, ``restore``, ``quit``).
"""
import argparse
import math
import os
import select
import struct
import sys
import threading
import time
import tty

HEADER = b'\xff\xff\xfd\x00'
BROADCAST = 0xFE
PING, READ, WRITE, REBOOT, STATUS, SYNC_READ, SYNC_WRITE = 0x01, 0x02, 0x03, 0x08, 0x55, 0x82, 0x83
ERR_RESULT, ERR_INSTRUCTION, ERR_CRC, ERR_RANGE, ERR_LENGTH, ERR_LIMIT, ERR_ACCESS = range(1, 8)
ALERT = 0x80

MODEL_XM430_W350 = 1020
ADDR_MODEL, ADDR_FIRMWARE, ADDR_ID, ADDR_RETURN_DELAY = 0, 6, 7, 9
ADDR_OPERATING_MODE, ADDR_HOMING_OFFSET, ADDR_SHUTDOWN = 11, 20, 63
ADDR_TORQUE_ENABLE, ADDR_HARDWARE_ERROR, ADDR_GOAL_POSITION = 64, 70, 116
ADDR_PRESENT_CURRENT, ADDR_PRESENT_VELOCITY, ADDR_PRESENT_POSITION = 126, 128, 132
EEPROM_END = 64
TABLE_SIZE = 147
#: Hardware Error Status bits.
INPUT_VOLTAGE, OVERHEATING, MOTOR_ENCODER = 0x01, 0x04, 0x08
ELECTRICAL_SHOCK, OVERLOAD = 0x10, 0x20
TICKS_PER_REV = 4096
VELOCITY_UNIT_RPM = 0.229
#: Read-only RAM addresses (writes are access errors).
READ_ONLY = set(range(ADDR_HARDWARE_ERROR, ADDR_HARDWARE_ERROR + 1)) | set(range(122, 147))


def crc16(data):
    """CRC-16 of ``data``: polynomial 0x8005, MSB first, initial value 0 (e-Manual 2.0)."""
    crc = 0
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
    return crc


def stuff(body):
    """Insert 0xFD after every FF FF FD in ``body`` (INST and parameters)."""
    out = bytearray()
    for byte in body:
        out.append(byte)
        if byte == 0xFD and out[-3:-1] == b'\xff\xff' and len(out) >= 3:
            out.append(0xFD)
    return bytes(out)


def unstuff(body):
    """Remove the 0xFD inserted by :func:`stuff`."""
    out = bytearray()
    i = 0
    while i < len(body):
        out.append(body[i])
        if body[i] == 0xFD and len(out) >= 3 and out[-3:-1] == b'\xff\xff' and \
                i + 1 < len(body) and body[i + 1] == 0xFD:
            i += 1
        i += 1
    return bytes(out)


def packet(servo_id, body):
    """Return a complete packet: header, id, length, stuffed ``body`` (INST...), CRC."""
    stuffed = stuff(body)
    head = HEADER + bytes([servo_id]) + struct.pack('<H', len(stuffed) + 2) + stuffed
    return head + struct.pack('<H', crc16(head))


class Servo:
    """One X-series servo: control table, shaft and a simple position servo loop.

    :param servo_id: bus id
    :param shaft: shaft angle at power-up, ticks (the physical position, multi-turn)
    :param max_speed: speed of the position loop, ticks/s
    """

    def __init__(self, servo_id, shaft=0.0, max_speed=4096.0):
        self.table = bytearray(TABLE_SIZE)
        struct.pack_into('<H', self.table, ADDR_MODEL, MODEL_XM430_W350)
        self.table[ADDR_FIRMWARE] = 46
        self.table[ADDR_ID] = servo_id
        self.table[ADDR_RETURN_DELAY] = 250
        self.table[ADDR_OPERATING_MODE] = 3
        self.table[ADDR_SHUTDOWN] = OVERHEATING | ELECTRICAL_SHOCK | OVERLOAD
        self.shaft = float(shaft)
        self.max_speed = float(max_speed)
        self.load_current = 0  # Present Current while holding, units of 2.69 mA
        self.online = True
        self.power_up()

    @property
    def servo_id(self):
        """Bus id (control table address 7)."""
        return self.table[ADDR_ID]

    def power_up(self):
        """Power-up / reboot: torque off, errors cleared, multi-turn count lost."""
        self.table[ADDR_TORQUE_ENABLE] = 0
        self.table[ADDR_HARDWARE_ERROR] = 0
        # Present Position restarts within one turn of the shaft's absolute angle.
        self.turn_base = math.floor(self.shaft / TICKS_PER_REV) * TICKS_PER_REV
        self.velocity = 0.0
        self._set_present()
        struct.pack_into('<i', self.table, ADDR_GOAL_POSITION, self.present_position)

    def get(self, address, size):
        """Signed little-endian integer of ``size`` bytes at ``address``."""
        return int.from_bytes(self.table[address:address + size], 'little', signed=True)

    @property
    def present_position(self):
        """Present Position (ticks): shaft minus lost turns plus Homing Offset."""
        return int(round(self.shaft - self.turn_base)) + self.get(ADDR_HOMING_OFFSET, 4)

    def _set_present(self):
        struct.pack_into('<i', self.table, ADDR_PRESENT_POSITION, self.present_position)
        rpm = self.velocity / TICKS_PER_REV * 60.0
        struct.pack_into('<i', self.table, ADDR_PRESENT_VELOCITY,
                         int(round(rpm / VELOCITY_UNIT_RPM)))
        current = self.load_current if self.table[ADDR_TORQUE_ENABLE] else 0
        struct.pack_into('<h', self.table, ADDR_PRESENT_CURRENT, current)

    def advance(self, dt):
        """Move the shaft towards Goal Position for ``dt`` s (only with torque on)."""
        self.velocity = 0.0
        if self.table[ADDR_TORQUE_ENABLE] and dt > 0.0:
            goal_shaft = (self.get(ADDR_GOAL_POSITION, 4) - self.get(ADDR_HOMING_OFFSET, 4)
                          + self.turn_base)
            gap = goal_shaft - self.shaft
            step = max(-self.max_speed * dt, min(self.max_speed * dt, gap))
            self.shaft += step
            self.velocity = step / dt
        self._set_present()

    def hardware_fault(self, bits):
        """Raise Hardware Error Status ``bits``; shutdown bits turn the torque off."""
        self.table[ADDR_HARDWARE_ERROR] |= bits
        if bits & self.table[ADDR_SHUTDOWN]:
            self.table[ADDR_TORQUE_ENABLE] = 0

    def error_byte(self, number=0):
        """Status ERR byte: the error number plus the alert bit while a hardware error is set."""
        return number | (ALERT if self.table[ADDR_HARDWARE_ERROR] else 0)

    def read(self, address, length):
        """Return (error number, data) for a READ."""
        if address + length > TABLE_SIZE or length == 0:
            return ERR_ACCESS, b''
        return 0, bytes(self.table[address:address + length])

    def write(self, address, data):
        """Apply a WRITE; return its error number (0 = ok)."""
        end = address + len(data)
        if end > TABLE_SIZE or not data:
            return ERR_ACCESS
        if any(a in READ_ONLY for a in range(address, end)):
            return ERR_ACCESS
        if address < EEPROM_END and self.table[ADDR_TORQUE_ENABLE]:
            return ERR_ACCESS  # EEPROM is locked while torque is on
        if address <= ADDR_TORQUE_ENABLE < end:
            value = data[ADDR_TORQUE_ENABLE - address]
            if value > 1:
                return ERR_RANGE
            if value and self.table[ADDR_HARDWARE_ERROR] & self.table[ADDR_SHUTDOWN]:
                return ERR_RESULT  # shutdown: only REBOOT brings the torque back
        if address <= ADDR_OPERATING_MODE < end and data[ADDR_OPERATING_MODE - address] not in (
                0, 1, 3, 4, 5, 16):
            return ERR_RANGE
        if address <= ADDR_GOAL_POSITION and end >= ADDR_GOAL_POSITION + 4:
            goal = struct.unpack_from('<i', data, ADDR_GOAL_POSITION - address)[0]
            mode = self.table[ADDR_OPERATING_MODE]
            low, high = (0, 4095) if mode == 3 else (-1048575, 1048575)
            if not low <= goal <= high:
                return ERR_LIMIT
        self.table[address:end] = data
        return 0


class DynamixelBus:
    """Servos on one pseudo-terminal; the host opens :attr:`port` (a symlink to /dev/pts/N).

    :param ids: servo ids on the bus
    :param link: path of the symlink the host opens (like a udev /dev/serial/by-id name)
    :param baudrate: simulated wire speed, bit/s (10 bits per byte)
    :param shafts: initial shaft angle of each servo, ticks (default 0)
    :param return_delay_us: Return Delay Time of every servo, us (e-Manual default 500 us)
    """

    def __init__(self, ids, link, baudrate=1_000_000, shafts=None, return_delay_us=500,
                 max_speed=4096.0):
        self.servos = {}
        shafts = shafts or [0.0] * len(ids)
        for servo_id, shaft in zip(ids, shafts):
            servo = Servo(servo_id, shaft, max_speed)
            servo.table[ADDR_RETURN_DELAY] = min(254, int(return_delay_us) // 2)
            self.servos[servo_id] = servo
        self.link = str(link)
        self.byte_time = 10.0 / float(baudrate)
        self.lock = threading.RLock()
        self.instructions = 0
        self.crc_errors = 0
        self._master = self._slave = None
        self._thread = None
        self._running = False
        self._last_advance = time.monotonic()
        self.port = self.link

    # -- life cycle -------------------------------------------------------------------------
    def start(self):
        """Create the pseudo-terminal and the symlink, and serve it in a thread."""
        self._open_pty()
        self._running = True
        self._thread = threading.Thread(target=self._serve, name='dynamixel_bus', daemon=True)
        self._thread.start()
        return self

    def close(self):
        """Stop serving and remove the port."""
        self._running = False
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._close_pty()

    def _open_pty(self):
        master, slave = os.openpty()
        tty.setraw(slave)
        tty.setraw(master)
        name = os.ttyname(slave)
        tmp = self.link + '.tmp'
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(name, tmp)
        os.replace(tmp, self.link)
        with self.lock:
            self._master, self._slave = master, slave

    def _close_pty(self):
        with self.lock:
            master, slave, self._master, self._slave = self._master, self._slave, None, None
        if os.path.lexists(self.link):
            os.unlink(self.link)
        for fd in (master, slave):
            if fd is not None:
                os.close(fd)

    # -- fault injection --------------------------------------------------------------------
    def vanish(self):
        """Unplug the adapter: the pseudo-terminal and the symlink disappear."""
        self._close_pty()

    def restore(self):
        """Plug the adapter back in: a new pseudo-terminal under the same symlink."""
        self._open_pty()

    def fault(self, servo_id, bits):
        """Raise Hardware Error Status ``bits`` on one servo."""
        with self.lock:
            self.servos[servo_id].hardware_fault(bits)

    def power_cycle(self, servo_id):
        """Cut and restore one servo's power (multi-turn count lost, torque off)."""
        with self.lock:
            self.servos[servo_id].power_up()

    def set_online(self, servo_id, online):
        """Disconnect (False) or reconnect (True) one servo's bus cable."""
        with self.lock:
            self.servos[servo_id].online = bool(online)

    def set_load_current(self, servo_id, units):
        """Present Current the servo reports while its torque is on, units of 2.69 mA."""
        with self.lock:
            self.servos[servo_id].load_current = int(units)

    def position(self, servo_id):
        """Present Position of one servo, ticks."""
        with self.lock:
            self._advance()
            return self.servos[servo_id].present_position

    # -- serving ----------------------------------------------------------------------------
    def _advance(self):
        now = time.monotonic()
        dt, self._last_advance = now - self._last_advance, now
        for servo in self.servos.values():
            servo.advance(dt)

    def _serve(self):
        buffer = bytearray()
        wire_free = 0.0
        while self._running:
            master = self._master
            if master is None:
                buffer.clear()
                time.sleep(0.01)
                continue
            try:
                ready, _, _ = select.select([master], [], [], 0.05)
                if not ready:
                    continue
                chunk = os.read(master, 4096)
            except OSError:  # closed by vanish(), or the host went away
                time.sleep(0.01)
                continue
            arrived = time.perf_counter()
            buffer.extend(chunk)
            while True:
                parsed = self._take_packet(buffer)
                if parsed is None:
                    break
                raw_length, servo_id, body = parsed
                # The instruction occupies the wire for its own length before a servo acts.
                wire_free = max(wire_free, arrived) + raw_length * self.byte_time
                replies = self._handle(servo_id, body)
                for delay, reply in replies:
                    wire_free += delay + len(reply) * self.byte_time
                    _sleep_until(wire_free)
                    try:
                        os.write(master, reply)
                    except OSError:
                        break

    def _take_packet(self, buffer):
        """Remove and return (raw length, id, unstuffed INST+params) of the first good packet."""
        while True:
            start = buffer.find(HEADER)
            if start < 0:
                del buffer[:max(0, len(buffer) - 3)]
                return None
            del buffer[:start]
            if len(buffer) < 7:
                return None
            length = struct.unpack_from('<H', buffer, 5)[0]
            total = 7 + length
            if length < 3:
                del buffer[:1]
                continue
            if len(buffer) < total:
                return None
            raw = bytes(buffer[:total])
            del buffer[:total]
            if crc16(raw[:-2]) != struct.unpack_from('<H', raw, total - 2)[0]:
                self.crc_errors += 1
                continue  # a corrupt instruction gets no status (the id is not trusted)
            return total, raw[4], unstuff(raw[7:-2])

    def _handle(self, servo_id, body):
        """Execute one instruction; return [(return delay s, status packet bytes), ...]."""
        with self.lock:
            self.instructions += 1
            self._advance()
            inst, params = body[0], body[1:]
            if inst == SYNC_READ and servo_id == BROADCAST:
                return self._sync_read(params)
            if inst == SYNC_WRITE and servo_id == BROADCAST:
                self._sync_write(params)
                return []
            if servo_id == BROADCAST:
                if inst == PING:
                    return [self._status(s, 0, self._ping_data(s)) for s in self._present()]
                for servo in self._present():
                    self._execute(servo, inst, params)
                return []
            servo = self.servos.get(servo_id)
            if servo is None or not servo.online:
                return []
            error, data = self._execute(servo, inst, params)
            return [self._status(servo, error, data)]

    def _present(self):
        return [s for _, s in sorted(self.servos.items()) if s.online]

    @staticmethod
    def _ping_data(servo):
        return bytes(servo.table[ADDR_MODEL:ADDR_MODEL + 2]) + bytes([servo.table[ADDR_FIRMWARE]])

    def _execute(self, servo, inst, params):
        if inst == PING:
            return 0, self._ping_data(servo)
        if inst == READ:
            if len(params) != 4:
                return ERR_LENGTH, b''
            address, length = struct.unpack('<HH', params)
            return servo.read(address, length)
        if inst == WRITE:
            if len(params) < 3:
                return ERR_LENGTH, b''
            return servo.write(struct.unpack_from('<H', params)[0], params[2:]), b''
        if inst == REBOOT:
            servo.power_up()
            return 0, b''
        return ERR_INSTRUCTION, b''

    def _status(self, servo, error, data):
        delay = servo.table[ADDR_RETURN_DELAY] * 2e-6
        return delay, packet(servo.servo_id, bytes([STATUS, servo.error_byte(error)]) + data)

    def _sync_read(self, params):
        if len(params) < 5:
            return []
        address, length = struct.unpack_from('<HH', params)
        replies = []
        for servo_id in params[4:]:
            servo = self.servos.get(servo_id)
            if servo is None or not servo.online:
                continue
            error, data = servo.read(address, length)
            replies.append(self._status(servo, error, data))
        return replies

    def _sync_write(self, params):
        if len(params) < 4:
            return
        address, length = struct.unpack_from('<HH', params)
        for offset in range(4, len(params) - length, length + 1):
            servo = self.servos.get(params[offset])
            if servo is not None and servo.online:
                servo.write(address, params[offset + 1:offset + 1 + length])


def _sleep_until(deadline):
    remaining = deadline - time.perf_counter()
    if remaining > 0.0:
        time.sleep(remaining)


def main(argv=None):
    """Serve a bus in this process; fault commands on stdin, one per line."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--ids', type=int, nargs='+', default=[1, 2, 3, 4])
    parser.add_argument('--link', required=True)
    parser.add_argument('--baudrate', type=int, default=1_000_000)
    parser.add_argument('--return-delay-us', type=int, default=0)
    parser.add_argument('--max-speed', type=float, default=8192.0, help='ticks/s')
    args = parser.parse_args(argv)
    bus = DynamixelBus(args.ids, args.link, args.baudrate, return_delay_us=args.return_delay_us,
                       max_speed=args.max_speed).start()
    print('ready %s' % bus.port, flush=True)
    actions = {'fault': lambda i, b: bus.fault(int(i), int(b, 0)),
               'power_cycle': lambda i: bus.power_cycle(int(i)),
               'offline': lambda i: bus.set_online(int(i), False),
               'online': lambda i: bus.set_online(int(i), True),
               'vanish': bus.vanish, 'restore': bus.restore}
    try:
        for line in sys.stdin:
            words = line.split()
            if not words:
                continue
            if words[0] == 'quit':
                break
            actions[words[0]](*words[1:])
            print('done %s' % words[0], flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        bus.close()
    return 0


if __name__ == '__main__':
    sys.exit(main())
