"""cable_driver with the dynamixel backend over DDS, against the Protocol 2.0 pty emulator."""
import math

from conftest import REPO
from emulators import dynamixel_bus as dxl
from emulators.dynamixel_bus import DynamixelBus
from nodes_helpers import (
    RELIABLE,
    Collector,
    call,
    diagnostic_values,
    publish_until,
    wait_matched,
    wait_until,
)
import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('dynamixel_sdk')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
IDS = [11, 12, 13, 14]
ZERO = 6000
METRES_PER_TICK = 2 * math.pi * 0.01 / 4096


@pytest.fixture
def bus(tmp_path):
    """Four servos at the straight pose (6000 ticks: the count restarts at 1904 at power-up)."""
    bus = DynamixelBus(IDS, tmp_path / 'ttyDXL', return_delay_us=0, max_speed=20000.0,
                       shafts=[ZERO] * 4).start()
    yield bus
    bus.close()


def start(harness, bus, **overrides):
    parameters = {'backend': 'dynamixel', 'publish_rate': 100.0, 'command_timeout': 0.0,
                  'reconnect_max_interval': 0.2, 'dynamixel.port': bus.port,
                  'dynamixel.baudrate': 1000000, 'dynamixel.ids': IDS,
                  'dynamixel.spool_radius': 0.01, 'dynamixel.zero_ticks': [ZERO],
                  'dynamixel.timeout_margin': 0.2}  # the emulator shares this process's GIL
    parameters.update(overrides)
    driver = harness.add(CableDriverNode, **parameters)
    client = harness.client()
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    commands = client.create_publisher(JointState, 'cable_commands', RELIABLE)
    wait_until(lambda: len(states) >= 5, 10.0, 'cable_states')
    wait_matched(commands, driver)
    return driver, client, states, diagnostics, commands


def status_of(diagnostics):
    found = diagnostic_values(diagnostics, 'cable_driver')
    return found if found is not None else ({}, None)


def wait_status(diagnostics, predicate, what, timeout=10.0):
    def ok():
        values, status = status_of(diagnostics)
        return status is not None and predicate(values, status)
    wait_until(ok, timeout, what)
    return status_of(diagnostics)


def trigger(client, name):
    service = client.create_client(Trigger, name)
    assert service.wait_for_service(timeout_sec=10.0), name
    return call(service, Trigger.Request(), 10.0)


def test_commands_move_the_servos_and_lengths_come_back(harness, bus):
    _, _, states, _, commands = start(harness, bus)
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)
    target = [0.31, 0.29, 0.30, 0.305]
    publish_until(commands, JointState(name=list(ROBOT.cable_names), position=target),
                  lambda: np.allclose(states.last.position, target, atol=METRES_PER_TICK), 10.0,
                  'the cables at the target')
    ticks = round(ZERO + 0.01 / METRES_PER_TICK) - 4096  # one turn lost at power-up
    assert bus.servos[11].get(dxl.ADDR_GOAL_POSITION, 4) == ticks


def test_overload_is_error_commands_are_refused_and_reset_clears_it(harness, bus):
    _, client, states, diagnostics, commands = start(harness, bus)
    bus.fault(12, dxl.OVERLOAD)
    _, status = wait_status(diagnostics, lambda v, s: s.level == b'\x02', 'ERROR')
    assert 'servo 12 (cable_1)' in status.message and 'overload' in status.message
    commands.publish(JointState(name=['cable_0'], position=[0.31]))
    values, _ = wait_status(diagnostics, lambda v, s: v.get('commands_refused') == '1',
                            'the refused command')
    assert 'refused: actuator fault: servo 12 (cable_1) hardware error: overload' in values[
        'last_rejection']
    assert bus.servos[11].get(dxl.ADDR_GOAL_POSITION, 4) == ZERO - 4096
    answer = trigger(client, 'cable_driver/reset')
    assert answer.success and 'rebooted servo 12 (cable_1) (overload (0x20))' in answer.message
    wait_status(diagnostics, lambda v, s: s.level == b'\x00', 'OK after the reset')
    assert bus.servos[12].table[dxl.ADDR_TORQUE_ENABLE] == 1
    publish_until(commands, JointState(name=['cable_0'], position=[0.31]),
                  lambda: abs(states.last.position[0] - 0.31) < METRES_PER_TICK, 10.0,
                  'cable_0 moving after the reset')


def test_port_lost_is_error_without_stale_states_and_publishing_resumes(harness, bus):
    _, _, states, diagnostics, commands = start(harness, bus)
    bus.vanish()
    _, status = wait_status(diagnostics, lambda v, s: s.level == b'\x02', 'ERROR')
    assert 'connection lost: port' in status.message and 'ttyDXL' in status.message
    count = len(states)
    errors = len(diagnostics)
    wait_until(lambda: len(diagnostics) > errors + 10, 10.0, 'more diagnostics while lost')
    assert len(states) <= count + 1  # at most one in flight when the port went
    commands.publish(JointState(name=['cable_0'], position=[0.31]))
    values, status = wait_status(diagnostics, lambda v, s: v.get('commands_refused') == '1',
                                 'the refused command')
    assert status.level == b'\x02'
    assert 'refused: actuators not connected' in values['last_rejection']
    reconnects = int(values['reconnects'])
    bus.restore()
    wait_status(diagnostics, lambda v, s: s.level == b'\x00'
                and int(v.get('reconnects', 0)) > reconnects, 'OK after reconnection')
    count = len(states)
    wait_until(lambda: len(states) > count + 10, 10.0, 'cable_states again')
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)


def test_servo_power_loss_is_named_and_survived(harness, bus):
    _, _, states, diagnostics, commands = start(harness, bus)
    publish_until(commands, JointState(name=['cable_2'], position=[0.32]),
                  lambda: abs(states.last.position[2] - 0.32) < METRES_PER_TICK, 10.0,
                  'cable_2 at 0.32 m')
    bus.set_online(13, False)
    _, status = wait_status(diagnostics, lambda v, s: s.level == b'\x02', 'ERROR')
    assert 'servo 13 (cable_2)' in status.message
    bus.power_cycle(13)
    bus.set_online(13, True)
    wait_status(diagnostics, lambda v, s: s.level == b'\x00', 'OK after the servo came back')
    count = len(states)
    wait_until(lambda: len(states) > count + 5, 10.0, 'cable_states again')
    assert abs(states.last.position[2] - 0.32) < METRES_PER_TICK  # turn count restored


def test_set_home_writes_the_home_file_and_a_new_driver_loads_it(harness, bus, tmp_path):
    home = tmp_path / 'home.yaml'
    # the previous home is off by 20 mm on cable_3: forced (a straight robot reads bent)
    driver, client, states, _, commands = start(harness, bus, home_file=str(home),
                                                home_force=True)
    publish_until(commands, JointState(name=['cable_3'], position=[0.28]),
                  lambda: abs(states.last.position[3] - 0.28) < METRES_PER_TICK, 10.0,
                  'cable_3 at 0.28 m')
    answer = trigger(client, 'cable_driver/set_home')
    assert answer.success and str(home) in answer.message, answer.message
    saved = yaml.safe_load(home.read_text())
    assert saved['backend'] == 'dynamixel' and saved['cable_names'] == list(ROBOT.cable_names)
    assert saved['zero_ticks'][:3] == [ZERO] * 3
    assert abs(saved['zero_ticks'][3] - (ZERO - 0.02 / METRES_PER_TICK)) <= 1
    wait_until(lambda: np.allclose(states.last.position, ROBOT.straight_cable_lengths,
                                   atol=1e-12), 5.0, 'straight lengths after set_home')
    harness.nodes.remove(driver)
    executor, thread = harness._spinning.pop(0)
    executor.remove_node(driver)
    executor.shutdown(timeout_sec=2.0)
    driver.destroy_node()
    assert bus.servos[14].table[dxl.ADDR_TORQUE_ENABLE] == 0  # torque off on exit
    _, _, states, _, _ = start(harness, bus, home_file=str(home),
                               **{'dynamixel.zero_ticks': [0]})
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)


def test_set_home_is_refused_while_the_robot_is_bent(harness, bus, tmp_path):
    home = tmp_path / 'home.yaml'
    _, client, states, _, commands = start(harness, bus, home_file=str(home))
    publish_until(commands, JointState(name=['cable_3'], position=[0.2906]),
                  lambda: abs(states.last.position[3] - 0.2906) < METRES_PER_TICK, 10.0,
                  'cable_3 9.4 mm short')
    answer = trigger(client, 'cable_driver/set_home')
    assert not answer.success and 'not straight' in answer.message, answer.message
    assert 'cable_3' in answer.message and '-9.4' in answer.message, answer.message
    assert not home.exists()
    straight = float(ROBOT.straight_cable_lengths[3])
    publish_until(commands, JointState(name=['cable_3'], position=[straight]),
                  lambda: abs(states.last.position[3] - straight) < METRES_PER_TICK, 10.0,
                  'cable_3 straight again')
    answer = trigger(client, 'cable_driver/set_home')
    assert answer.success and home.exists(), answer.message


def test_the_example_params_file_runs(harness, bus, tmp_path):
    tree = yaml.safe_load((REPO / 'config' / 'dynamixel_example.params.yaml').read_text())
    parameters = {}
    for key, value in tree['/**/cable_driver']['ros__parameters'].items():
        if isinstance(value, dict):
            parameters.update({'%s.%s' % (key, k): v for k, v in value.items()})
        else:
            parameters[key] = value
    parameters.update({'dynamixel.port': bus.port, 'dynamixel.ids': IDS,
                       'dynamixel.zero_ticks': [ZERO], 'home_file': str(tmp_path / 'h.yaml'),
                       'robot_file': str(REPO / 'config' / 'tendon_robot.yaml')})
    _, _, states, _, _ = start(harness, bus, **parameters)
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)
