"""Dynamixel backend through the real dynamixel-sdk against the Protocol 2.0 pty emulator."""
import math
import struct

from emulators import dynamixel_bus as dxl
from emulators.dynamixel_bus import DynamixelBus, packet
import numpy as np
import pytest

pytest.importorskip('dynamixel_sdk')
from continuum_statics.drivers import ConnectionLost, backend_class  # noqa: E402
from continuum_statics.drivers.dynamixel import DynamixelCableBackend  # noqa: E402

NAMES = ('cable_0', 'cable_1', 'cable_2', 'cable_3')
LIMITS = [[0.27, 0.33]] * 4
STRAIGHT = [0.30] * 4
IDS = [1, 2, 3, 4]
RADIUS = 0.01
METRES_PER_TICK = 2 * math.pi * RADIUS / 4096


@pytest.fixture
def bus(tmp_path):
    """Four servos whose shafts sit 2.5 turns out (multi-turn count lost at power-up)."""
    bus = DynamixelBus(IDS, tmp_path / 'ttyDXL', return_delay_us=0, max_speed=1e6,
                       shafts=[10240.0] * 4).start()
    yield bus
    bus.close()


def make(bus, **options):
    options = dict({'port': bus.port, 'baudrate': 1000000, 'ids': IDS, 'spool_radius': RADIUS,
                    'directions': [1, -1, 1, -1], 'zero_ticks': [10240],
                    'timeout_margin': 0.2}, **options)  # margin: a loaded test machine
    backend = DynamixelCableBackend(NAMES, LIMITS, STRAIGHT, **options)
    backend.start(0.0)
    return backend


def wait_for(predicate, backend, what, cycles=400):
    for _ in range(cycles):
        reading = backend.read(0.0)
        if predicate(reading):
            return reading
    raise AssertionError('no %s after %d reads' % (what, cycles))


def test_packets_match_the_e_manual_examples():
    # Protocol 2.0 e-Manual: PING id 1, its status (model 1030, firmware 38), READ 132/4, and
    # the SYNC_WRITE example (Goal Position 150 to id 1, 170 to id 2).
    assert packet(1, b'\x01').hex() == 'fffffd0001030001194e'
    assert packet(1, bytes([0x55, 0, 6, 4, 0x26])).hex() == 'fffffd0001070055000604266' + '55d'
    assert packet(1, bytes([2, 0x84, 0, 4, 0])).hex() == 'fffffd0001070002840004001d15'
    body = bytes([0x83, 0x74, 0, 4, 0, 1, 0x96, 0, 0, 0, 2, 0xAA, 0, 0, 0])
    assert packet(0xFE, body).hex().endswith('8287')


def test_byte_stuffing_round_trip():
    body = bytes([0x03, 0x74, 0x00, 0xFF, 0xFF, 0xFD, 0x00])
    assert dxl.stuff(body) == bytes([0x03, 0x74, 0x00, 0xFF, 0xFF, 0xFD, 0xFD, 0x00])
    assert dxl.unstuff(dxl.stuff(body)) == body


def test_registry_loads_the_backend_by_name():
    assert backend_class('dynamixel') is DynamixelCableBackend


def test_start_sets_mode_with_torque_off_and_restores_the_turn_count(bus):
    assert bus.position(1) == 10240 - 8192  # the emulator lost two turns at power-up
    backend = make(bus, operating_mode='current_based_position')
    for servo in bus.servos.values():
        assert servo.table[dxl.ADDR_OPERATING_MODE] == 5
        assert servo.table[dxl.ADDR_TORQUE_ENABLE] == 1
        assert servo.get(dxl.ADDR_GOAL_POSITION, 4) == 2048  # Goal = Present: no jump
    reading = backend.read(0.0)
    np.testing.assert_allclose(reading.lengths, STRAIGHT, atol=1e-12)
    assert backend.status().level == 0


def test_mode_change_on_a_servo_with_torque_on(bus):
    servo = bus.servos[3]
    servo.table[dxl.ADDR_TORQUE_ENABLE] = 1
    # The EEPROM lock itself: Operating Mode cannot be written with the torque on.
    assert servo.write(dxl.ADDR_OPERATING_MODE, b'\x04') == dxl.ERR_ACCESS
    make(bus)
    assert servo.table[dxl.ADDR_OPERATING_MODE] == 4
    assert servo.table[dxl.ADDR_TORQUE_ENABLE] == 1


def test_commands_become_goal_positions_and_readings_become_lengths(bus):
    backend = make(bus)
    targets = np.array([0.31, 0.29, 0.30, 0.325])
    backend.command(targets, 0.0)
    backend.read(0.0)  # a round trip after the (unanswered) sync write: the bus took it
    directions = np.array([1, -1, 1, -1])
    expected = np.round(10240 + directions * (targets - 0.30) / METRES_PER_TICK) - 8192
    goals = [bus.servos[i].get(dxl.ADDR_GOAL_POSITION, 4) for i in IDS]
    np.testing.assert_array_equal(goals, expected)
    reading = wait_for(lambda r: np.allclose(r.lengths, targets, atol=METRES_PER_TICK), backend,
                       'lengths at the targets')
    assert reading.tensions is None


def test_tension_from_present_current(bus):
    backend = make(bus, torque_constant=1.5)
    bus.set_load_current(1, -100)   # direction +1: pulling = negative torque
    bus.set_load_current(2, 100)    # direction -1: pulling = positive torque
    bus.set_load_current(3, 100)    # pushing on a cable: slack, 0 N
    reading = backend.read(0.0)
    expected = 1.5 * 100 * 2.69e-3 / RADIUS
    np.testing.assert_allclose(reading.tensions, [expected, expected, 0.0, 0.0])


@pytest.mark.parametrize('bits, names, shuts_down', [
    (dxl.OVERLOAD, 'overload', True),
    (dxl.OVERHEATING | dxl.OVERLOAD, 'overheating, overload', True),
    (dxl.INPUT_VOLTAGE, 'input voltage', False),
    (dxl.ELECTRICAL_SHOCK, 'electrical shock', True),
])
def test_hardware_error_is_error_naming_the_servo_and_reset_clears_it(bus, bits, names,
                                                                       shuts_down):
    backend = make(bus)
    bus.fault(2, bits)
    assert bus.servos[2].table[dxl.ADDR_TORQUE_ENABLE] == (0 if shuts_down else 1)
    backend.read(0.0)
    status = backend.status()
    assert status.level == 2
    assert 'servo 2 (cable_1)' in status.message and names in status.message, status.message
    done = backend.reset()
    assert 'rebooted servo 2' in done and names in done
    backend.read(0.0)
    assert backend.status().level == 0, backend.status().message
    assert bus.servos[2].table[dxl.ADDR_TORQUE_ENABLE] == 1
    np.testing.assert_allclose(backend.read(0.0).lengths, STRAIGHT, atol=1e-12)


def test_missing_servo_at_start_is_named(bus):
    bus.set_online(3, False)
    with pytest.raises(ConnectionLost, match=r'servo 3 \(cable_2\) not answering'):
        make(bus)


def test_servo_power_loss_and_return_keeps_the_multi_turn_position(bus):
    backend = make(bus)
    backend.command([0.31, 0.30, 0.30, 0.30], 0.0)
    moved = wait_for(lambda r: abs(r.lengths[0] - 0.31) < METRES_PER_TICK, backend, 'cable_0')
    bus.set_online(1, False)
    with pytest.raises(ConnectionLost, match=r'servo 1 \(cable_0\) stopped answering'):
        backend.read(0.0)
    bus.power_cycle(1)  # back with torque off, inside one turn
    bus.set_online(1, True)
    backend.start(0.0)
    assert bus.servos[1].table[dxl.ADDR_TORQUE_ENABLE] == 1
    np.testing.assert_allclose(backend.read(0.0).lengths, moved.lengths, atol=1e-12)


def test_port_vanishing_and_coming_back(bus):
    backend = make(bus)
    bus.vanish()
    with pytest.raises(ConnectionLost, match='port .*ttyDXL'):
        for _ in range(3):
            backend.read(0.0)
    with pytest.raises(ConnectionLost, match='cannot be opened'):
        backend.start(0.0)
    with pytest.raises(ConnectionLost):
        backend.command(STRAIGHT, 0.0)
    bus.restore()
    backend.start(0.0)
    np.testing.assert_allclose(backend.read(0.0).lengths, STRAIGHT, atol=1e-12)


def test_set_home_makes_the_current_pose_straight(bus):
    backend = make(bus)
    backend.command([0.31, 0.30, 0.30, 0.30], 0.0)
    wait_for(lambda r: abs(r.lengths[0] - 0.31) < METRES_PER_TICK, backend, 'cable_0')
    zeros = backend.set_home()
    assert zeros[1:] == [10240] * 3 and abs(zeros[0] - (10240 + 0.01 / METRES_PER_TICK)) <= 1
    np.testing.assert_allclose(backend.read(0.0).lengths, STRAIGHT, atol=1e-12)


def test_close_turns_the_torque_off_unless_told_otherwise(bus):
    make(bus).close()
    assert all(s.table[dxl.ADDR_TORQUE_ENABLE] == 0 for s in bus.servos.values())
    make(bus, disable_torque_on_exit=False).close()
    assert all(s.table[dxl.ADDR_TORQUE_ENABLE] == 1 for s in bus.servos.values())


@pytest.mark.parametrize('options, message', [
    ({'ids': [1, 2, 3]}, 'ids needs 1 or 4'),
    ({'ids': [1, 1, 2, 3]}, 'distinct'),
    ({'directions': [1, 0, 1, 1]}, 'directions'),
    ({'operating_mode': 'velocity'}, 'operating_mode'),
    ({'spool_radius': -0.01}, 'spool_radius'),
    ({'speed': 3}, 'unknown option'),
])
def test_bad_options_are_named(options, message):
    with pytest.raises(ValueError, match=message):
        DynamixelCableBackend(NAMES, LIMITS, STRAIGHT, **options)


def test_goal_position_limit_in_the_emulator():
    servo = dxl.Servo(1)
    servo.table[dxl.ADDR_OPERATING_MODE] = 4
    assert servo.write(dxl.ADDR_GOAL_POSITION, struct.pack('<i', 2_000_000)) == dxl.ERR_LIMIT


def test_byte_stuffing_both_ways_through_the_real_sdk(bus):
    import dynamixel_sdk as sdk

    port = sdk.PortHandler(bus.port)
    assert port.openPort()
    packet_handler = sdk.PacketHandler(2.0)
    # Homing Offset -65536 then Moving Threshold 253: the bytes 00 00 FF FF FD 00 00 00 carry
    # the header pattern FF FF FD, stuffed in the WRITE and again in the status of the READ.
    data = [0x00, 0x00, 0xFF, 0xFF, 0xFD, 0x00, 0x00, 0x00]
    result, error = packet_handler.writeTxRx(port, 1, dxl.ADDR_HOMING_OFFSET, 8, data)
    assert (result, error) == (sdk.COMM_SUCCESS, 0)
    assert bus.servos[1].get(dxl.ADDR_HOMING_OFFSET, 4) == -65536
    read, result, error = packet_handler.readTxRx(port, 1, dxl.ADDR_HOMING_OFFSET, 8)
    assert (result, error) == (sdk.COMM_SUCCESS, 0)
    assert list(read) == data
    assert b'\xff\xff\xfd\xfd' in dxl.packet(1, bytes([dxl.STATUS, 0] + data))  # stuffed
    port.closePort()
