"""cable_driver with the canopen backend over DDS against CiA 402 emulated drives.

Configured by config/canopen_example.params.yaml (only the bus moved to python-can's virtual one).
"""
import math
import uuid

from conftest import REPO
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
pytest.importorskip('canopen')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from emulators import cia402_drive as cia  # noqa: E402
from emulators.cia402_drive import Cia402Bus  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_srvs.srv import Trigger  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
COUNTS_PER_METRE = 4096 * 10.0 / (2 * math.pi * 0.010)  # the example file's spool


def flatten(tree, prefix=''):
    """ros__parameters as {'canopen.channel': ..., ...}."""
    flat = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            flat.update(flatten(value, prefix + key + '.'))
        else:
            flat[prefix + key] = value
    return flat


def example_parameters(channel, tmp_path):
    tree = yaml.safe_load((REPO / 'config' / 'canopen_example.params.yaml').read_text())
    parameters = flatten(tree['/**/cable_driver']['ros__parameters'])
    parameters.update({'canopen.interface': 'virtual', 'canopen.channel': channel,
                       'home_file': str(tmp_path / 'home.yaml'),
                       'robot_file': str(REPO / 'config' / 'tendon_robot.yaml'),
                       'reconnect_max_interval': 0.2})
    return parameters


@pytest.fixture
def bus():
    bus = Cia402Bus([1, 2, 3, 4], 'node_' + uuid.uuid4().hex[:8])
    yield bus
    bus.close()


def test_example_config_drives_faults_and_resets(harness, bus, tmp_path):
    driver = harness.add(CableDriverNode, **example_parameters(bus.channel, tmp_path))
    client = harness.client()
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    commands = client.create_publisher(JointState, 'cable_commands', RELIABLE)
    wait_until(lambda: len(states) >= 5, 10.0, 'cable_states')
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)
    wait_matched(commands, driver)
    publish_until(commands, JointState(name=['cable_2'], position=[0.315]),
                  lambda: abs(states.last.position[2] - 0.315) < 1 / COUNTS_PER_METRE, 10.0,
                  'cable_2 at 0.315 m')
    assert bus.drives[3].target == round(0.015 * COUNTS_PER_METRE)

    bus.drives[2].fault(cia.OVER_CURRENT)

    def status():
        found = diagnostic_values(diagnostics, 'cable_driver')
        return found[1] if found else None

    wait_until(lambda: status() is not None and status().level == b'\x02', 10.0, 'ERROR')
    assert 'node 2 (cable_1) fault: EMCY 0x2310 continuous over-current' in status().message
    commands.publish(JointState(name=['cable_1'], position=[0.31]))
    wait_until(lambda: diagnostic_values(diagnostics, 'cable_driver')[0].get(
        'commands_refused') == '1', 10.0, 'the refused command')
    service = client.create_client(Trigger, 'cable_driver/reset')
    assert service.wait_for_service(timeout_sec=10.0)
    answer = call(service, Trigger.Request(), 10.0)
    assert answer.success, answer.message
    assert 'node 2 (cable_1): fault reset (EMCY 0x2310' in answer.message
    wait_until(lambda: status().level == b'\x00', 10.0, 'OK after the reset')
    publish_until(commands, JointState(name=['cable_1'], position=[0.31]),
                  lambda: abs(states.last.position[1] - 0.31) < 1 / COUNTS_PER_METRE, 10.0,
                  'cable_1 at 0.31 m after the reset')

    # A drive losing power: ERROR naming it, no readings, back by itself after it reboots.
    bus.drives[4].set_online(False)
    wait_until(lambda: 'node 4 (cable_3)' in status().message, 10.0, 'node 4 lost')
    assert status().level == b'\x02'
    count = len(states)
    seen = len(diagnostics)
    wait_until(lambda: len(diagnostics) > seen + 3, 10.0, 'diagnostics while node 4 is lost')
    assert len(states) <= count + 1
    bus.drives[4].set_online(True)
    wait_until(lambda: status().level == b'\x00', 15.0, 'OK after node 4 came back')
    count = len(states)
    wait_until(lambda: len(states) > count + 5, 10.0, 'cable_states again')
