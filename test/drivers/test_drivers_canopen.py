"""canopen backend against CiA 402 LocalNode drives on python-can's virtual bus."""
import math
import time
import uuid

import numpy as np
import pytest

pytest.importorskip('canopen')
from emulators import cia402_drive as cia  # noqa: E402
from emulators.cia402_drive import Cia402Bus  # noqa: E402

from continuum_statics.drivers import ConnectionLost, backend_class  # noqa: E402
from continuum_statics.drivers.canopen_drive import (  # noqa: E402
    DEFAULT_EDS,
    CanopenCableBackend,
    emcy_text,
    state_name,
)

NAMES = ('cable_0', 'cable_1', 'cable_2', 'cable_3')
LIMITS = [[0.27, 0.33]] * 4
STRAIGHT = [0.30] * 4
NODE_IDS = [3, 4, 5, 6]
COUNTS_PER_METRE = 4096 * 10 / (2 * math.pi * 0.012)  # 4096 counts, 10:1 gear, 12 mm spool


@pytest.fixture
def bus():
    """Four drives at 1000 counts each (the straight pose) on a fresh virtual channel."""
    bus = Cia402Bus(NODE_IDS, 'cia402_' + uuid.uuid4().hex[:8], positions=[1000] * 4)
    yield bus
    bus.close()


@pytest.fixture
def make(bus):
    """Build and start backends on the bus; close them at the end."""
    made = []

    def make(**options):
        options = dict({'interface': 'virtual', 'channel': bus.channel, 'node_ids': NODE_IDS,
                        'counts_per_rev': 4096, 'gear_ratio': 10.0, 'spool_radius': 0.012,
                        'directions': [1, 1, -1, -1], 'zero_counts': [1000],
                        'sync_period': 0.005, 'heartbeat_period': 0.05,
                        'heartbeat_timeout': 0.3}, **options)
        backend = CanopenCableBackend(NAMES, LIMITS, STRAIGHT, **options)
        made.append(backend)
        backend.start(time.monotonic())
        return backend

    yield make
    for backend in made:
        backend.close()


def poll(backend, predicate, what, timeout=5.0):
    """Read until ``predicate(reading)``; fail after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        reading = backend.read(time.monotonic())
        if predicate(reading):
            return reading
        assert time.monotonic() < deadline, 'timed out waiting for %s' % what
        time.sleep(0.002)


def test_shipped_eds_has_the_cia402_objects_where_the_standard_puts_them():
    import canopen
    od = canopen.import_od(str(DEFAULT_EDS), 7)
    expected = {0x1000: 'Device type', 0x1017: 'Producer heartbeat time',
                0x6040: 'Controlword', 0x6041: 'Statusword', 0x6060: 'Modes of operation',
                0x6064: 'Position actual value', 0x607A: 'Target position'}
    for index, name in expected.items():
        assert od[index].name == name
    assert od[0x1400][1].default == 0x207 and od[0x1800][1].default == 0x187
    assert od[0x6041].pdo_mappable and od[0x607A].pdo_mappable
    assert backend_class('canopen') is CanopenCableBackend


def test_state_and_emcy_decoding():
    assert state_name(0x0237) == 'OPERATION ENABLED'
    assert state_name(0x0250) == 'SWITCH ON DISABLED'
    assert state_name(0x0218) == 'FAULT'
    assert emcy_text(0x2310) == '0x2310 continuous over-current'
    assert emcy_text(0x2399) == '0x2399 current'


def test_start_maps_pdos_and_enables_every_drive(bus, make):
    backend = make()
    poll(backend, lambda r: all(d.operational for d in bus.drives.values()), 'OPERATIONAL')
    for drive in bus.drives.values():
        assert drive.state == 'OPERATION ENABLED'
        assert drive._get(0x6060, 0) == 1
        assert drive._get(0x1017, 0) == 50
        assert drive._mapping(0x1600, 0) == [(0x6040, 0, 16), (0x607A, 0, 32)]
        assert drive._mapping(0x1A00, 0) == [(0x6041, 0, 16), (0x6064, 0, 32)]
        assert drive._get(0x1400, 2) == 1 and drive._get(0x1800, 2) == 1  # synchronous
    reading = poll(backend, lambda r: True, 'a reading')
    np.testing.assert_allclose(reading.lengths, STRAIGHT, atol=1e-12)
    poll(backend, lambda r: all(d.sync_count > 3 for d in bus.drives.values()), 'SYNCs')
    assert backend.status().level == 0, backend.status().message


def test_commands_go_through_the_setpoint_handshake(bus, make):
    backend = make()
    targets = np.array([0.31, 0.29, 0.305, 0.30])
    backend.command(targets, time.monotonic())
    drive = bus.drives[3]

    def handshake_done():  # bit 4 raised with the target, then cleared after the ack
        words = [w for w in drive.applied if w & 0x0F == 0x0F]
        return 0x3F in words and 0x2F in words[words.index(0x3F):]

    reading = poll(backend, lambda r: np.allclose(r.lengths, targets, atol=1 / COUNTS_PER_METRE)
                   and handshake_done(), 'the drives at the targets, handshake done')
    np.testing.assert_allclose(reading.lengths, targets, atol=1 / COUNTS_PER_METRE)
    assert drive.target == round(1000 + 0.01 * COUNTS_PER_METRE)
    assert bus.drives[5].target == round(1000 - 0.005 * COUNTS_PER_METRE)  # direction -1
    words = [w for w in drive.applied if w & 0x0F == 0x0F]
    first = words.index(0x3F)
    assert set(words[first:words.index(0x2F, first)]) == {0x3F}  # held until acknowledged
    # Targets that change while a set-point is pending: the latest one wins.
    for k in range(20):
        backend.command(targets + 0.0005 * k, time.monotonic())
    final = targets + 0.0095
    poll(backend, lambda r: np.allclose(r.lengths, final, atol=1 / COUNTS_PER_METRE),
         'the last of 20 quick targets')


@pytest.mark.parametrize('code, text', [
    (cia.OVER_CURRENT, '0x2310 continuous over-current'),
    (cia.DRIVE_TEMPERATURE, '0x4310 excess temperature drive'),
    (cia.FOLLOWING_ERROR, '0x8611 following error'),
])
def test_fault_with_emcy_is_error_and_reset_clears_it(bus, make, code, text):
    backend = make()
    bus.drives[4].fault(code)
    poll(backend, lambda r: backend.status().level == 2, 'ERROR')
    message = backend.status().message
    assert 'node 4 (cable_1) fault: EMCY ' + text in message, message
    answer = backend.reset()
    assert 'node 4 (cable_1): fault reset (EMCY %s) -> operation enabled' % text == answer
    poll(backend, lambda r: backend.status().level == 0, 'OK after the reset')
    backend.command([0.30, 0.31, 0.30, 0.30], time.monotonic())
    poll(backend, lambda r: abs(r.lengths[1] - 0.31) < 1 / COUNTS_PER_METRE, 'cable_1 moving')


def test_a_silent_node_is_lost_within_a_second_and_comes_back(bus, make):
    backend = make()
    poll(backend, lambda r: True, 'a reading')
    bus.drives[5].set_online(False)
    started = time.monotonic()
    with pytest.raises(ConnectionLost, match=r'node 5 \(cable_2\) \(no heartbeat'):
        poll(backend, lambda r: False, 'the loss', timeout=1.0)
    assert time.monotonic() - started < 1.0
    with pytest.raises(ConnectionLost, match=r'node 5 \(cable_2\) not answering'):
        backend.start(time.monotonic())
    bus.drives[5].set_online(True)  # power back: boots in SWITCH ON DISABLED
    backend.start(time.monotonic())
    assert bus.drives[5].state == 'OPERATION ENABLED'
    reading = poll(backend, lambda r: True, 'a reading')
    np.testing.assert_allclose(reading.lengths, STRAIGHT, atol=1e-12)


def test_the_adapter_vanishing_and_coming_back(bus, make):
    backend = make()
    poll(backend, lambda r: True, 'a reading')
    backend._network.bus.shutdown()  # the USB-CAN adapter is unplugged
    with pytest.raises(ConnectionLost, match='CAN bus virtual:'):
        for _ in range(200):
            backend.command([0.31, 0.30, 0.30, 0.30], time.monotonic())
            backend.read(time.monotonic())
            time.sleep(0.005)
    backend.start(time.monotonic())  # plugged back in: a new bus on the same channel
    reading = poll(backend, lambda r: True, 'a reading')
    np.testing.assert_allclose(reading.lengths, STRAIGHT, atol=1e-12)


def test_the_whole_bus_going_silent_names_every_node(bus, make):
    backend = make()
    for drive in bus.drives.values():
        drive.set_online(False)
    with pytest.raises(ConnectionLost) as lost:
        poll(backend, lambda r: False, 'the loss', timeout=1.0)
    assert all('node %d' % i in str(lost.value) for i in NODE_IDS), lost.value


def test_a_drive_in_fault_at_start_is_reported_not_silently_reset(bus, make):
    bus.drives[6].fault(cia.OVER_VOLTAGE)
    backend = make()
    poll(backend, lambda r: backend.status().level == 2, 'ERROR')
    assert 'node 6 (cable_3) fault' in backend.status().message
    assert bus.drives[6].state == 'FAULT'


def test_set_home_and_close(bus, make):
    backend = make()
    backend.command([0.31, 0.30, 0.30, 0.30], time.monotonic())
    poll(backend, lambda r: abs(r.lengths[0] - 0.31) < 1 / COUNTS_PER_METRE, 'cable_0')
    zeros = backend.set_home()
    assert zeros[1:] == [1000] * 3
    assert abs(zeros[0] - (1000 + 0.01 * COUNTS_PER_METRE)) <= 1
    np.testing.assert_allclose(backend.read(time.monotonic()).lengths, STRAIGHT, atol=1e-12)
    backend.close()
    assert all(d.state == 'READY TO SWITCH ON' for d in bus.drives.values())


@pytest.mark.parametrize('options, message', [
    ({'node_ids': [1, 2]}, 'node_ids needs 1 or 4'),
    ({'node_ids': [0, 1, 2, 3]}, '1..127'),
    ({'eds': '/nonexistent.eds'}, 'does not exist'),
    ({'gear_ratio': 0.0}, 'gear_ratio'),
    ({'speed': 1}, 'unknown option'),
])
def test_bad_options_are_named(options, message):
    with pytest.raises(ValueError, match=message):
        CanopenCableBackend(NAMES, LIMITS, STRAIGHT, **options)


def test_a_bus_that_does_not_open_is_connection_lost():
    backend = CanopenCableBackend(NAMES, LIMITS, STRAIGHT, interface='no_such_interface',
                                  channel='x')
    with pytest.raises(ConnectionLost, match='no_such_interface:x cannot be opened'):
        backend.start(0.0)


def test_a_node_that_stops_its_pdos_gives_no_stale_positions(bus, make):
    backend = make()
    poll(backend, lambda r: all(d.operational for d in bus.drives.values()), 'OPERATIONAL')
    bus.drives[6].node.nmt.state = 'PRE-OPERATIONAL'  # heartbeats go on, PDOs stop
    with pytest.raises(ConnectionLost, match=r'node 6 \(cable_3\) \(no TPDO for .* NMT '
                                             r'PRE-OPERATIONAL\)'):
        poll(backend, lambda r: False, 'the stale node', timeout=2.0)
    backend.start(time.monotonic())  # NMT start again
    poll(backend, lambda r: bus.drives[6].operational, 'node 6 OPERATIONAL again')
