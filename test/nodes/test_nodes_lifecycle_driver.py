"""cable_driver as a lifecycle node over DDS, against the Dynamixel and CiA 402 emulators.

configure: port/bus open, positions read, torque off; activate: torque on / OPERATION ENABLED,
commands accepted; deactivate: hold, torque off / READY TO SWITCH ON, commands refused;
cleanup: released. The transitions come over DDS (lifecycle_msgs/srv/ChangeState), as from a
lifecycle manager.
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
    wait_until,
)
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
pytest.importorskip('dynamixel_sdk')
pytest.importorskip('canopen')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from emulators import dynamixel_bus as dxl  # noqa: E402
from emulators.cia402_drive import Cia402Bus  # noqa: E402
from emulators.dynamixel_bus import DynamixelBus  # noqa: E402
from lifecycle_msgs.msg import Transition  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetState  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
IDS = [11, 12, 13, 14]
ZERO = 6000
METRES_PER_TICK = 2 * math.pi * 0.01 / 4096


class Lifecycle:
    """A client of the driver's lifecycle services, its cable_states and its diagnostics."""

    def __init__(self, harness):
        self.client = harness.client()
        self.states = Collector(self.client, JointState, 'cable_states', qos_profile_sensor_data)
        self.diagnostics = Collector(self.client, DiagnosticArray, '/diagnostics', 10)
        self.commands = self.client.create_publisher(JointState, 'cable_commands', RELIABLE)
        self.change = self.client.create_client(ChangeState, 'cable_driver/change_state')
        self.get = self.client.create_client(GetState, 'cable_driver/get_state')
        assert self.change.wait_for_service(timeout_sec=10.0)
        assert self.get.wait_for_service(timeout_sec=10.0)

    def transition(self, transition_id):
        request = ChangeState.Request(transition=Transition(id=transition_id))
        assert call(self.change, request, 20.0).success, transition_id

    def state(self):
        return call(self.get, GetState.Request(), 10.0).current_state.label

    def values(self):
        found = diagnostic_values(self.diagnostics, 'cable_driver')
        return found[0] if found else {}

    def refused(self, name, length):
        """Publish a command until the driver says it refused it (because it is inactive)."""
        publish_until(self.commands, JointState(name=[name], position=[length]),
                      lambda: 'activate it to accept commands' in self.values().get(
                          'last_rejection', ''), 10.0, 'the command refused')


def test_dynamixel_transitions_switch_the_torque_and_gate_the_commands(harness, tmp_path):
    bus = DynamixelBus(IDS, tmp_path / 'ttyDXL', return_delay_us=0, max_speed=20000.0,
                       shafts=[ZERO] * 4).start()
    try:
        harness.add(CableDriverNode, backend='dynamixel', autostart=False, publish_rate=100.0,
                    command_timeout=0.0, **{
                        'dynamixel.port': bus.port, 'dynamixel.baudrate': 1000000,
                        'dynamixel.ids': IDS, 'dynamixel.spool_radius': 0.01,
                        'dynamixel.zero_ticks': [ZERO], 'dynamixel.timeout_margin': 0.2})
        life = Lifecycle(harness)
        assert life.state() == 'unconfigured'
        wait_until(lambda: life.values().get('lifecycle') == 'unconfigured', 10.0, 'diagnostics')
        assert len(life.states) == 0  # nothing read before configure

        life.transition(Transition.TRANSITION_CONFIGURE)
        wait_until(lambda: len(life.states) >= 5, 10.0, 'cable_states after configure')
        np.testing.assert_allclose(life.states.last.position, ROBOT.straight_cable_lengths,
                                   atol=1e-12)
        torque = [bus.servos[i].table[dxl.ADDR_TORQUE_ENABLE] for i in IDS]
        assert torque == [0, 0, 0, 0], 'configure reads only'
        life.refused('cable_3', 0.28)

        life.transition(Transition.TRANSITION_ACTIVATE)
        assert life.state() == 'active'
        assert [bus.servos[i].table[dxl.ADDR_TORQUE_ENABLE] for i in IDS] == [1, 1, 1, 1]
        publish_until(life.commands, JointState(name=['cable_3'], position=[0.28]),
                      lambda: abs(life.states.last.position[3] - 0.28) < METRES_PER_TICK, 10.0,
                      'cable_3 at 0.28 m')

        life.transition(Transition.TRANSITION_DEACTIVATE)
        assert [bus.servos[i].table[dxl.ADDR_TORQUE_ENABLE] for i in IDS] == [0, 0, 0, 0]
        life.refused('cable_3', 0.30)
        assert abs(life.states.last.position[3] - 0.28) < METRES_PER_TICK  # held, not moved

        life.transition(Transition.TRANSITION_CLEANUP)
        assert life.state() == 'unconfigured'
        count = len(life.states)
        wait_until(lambda: life.values().get('lifecycle') == 'unconfigured', 10.0,
                   'unconfigured on diagnostics')
        assert len(life.states) <= count + 1  # no readings after cleanup
        # and back up again: no restart needed
        life.transition(Transition.TRANSITION_CONFIGURE)
        life.transition(Transition.TRANSITION_ACTIVATE)
        assert [bus.servos[i].table[dxl.ADDR_TORQUE_ENABLE] for i in IDS] == [1, 1, 1, 1]
    finally:
        bus.close()


def test_canopen_deactivate_switches_the_power_stage_off(harness):
    bus = Cia402Bus([1, 2, 3, 4], 'life_' + uuid.uuid4().hex[:8])
    try:
        harness.add(CableDriverNode, backend='canopen', autostart=False,
                    reconnect_max_interval=0.2, **{
                        'canopen.interface': 'virtual', 'canopen.channel': bus.channel,
                        'canopen.node_ids': [1, 2, 3, 4]})
        life = Lifecycle(harness)
        life.transition(Transition.TRANSITION_CONFIGURE)
        wait_until(lambda: len(life.states) >= 5, 10.0, 'cable_states after configure')
        states = {bus.drives[n].state for n in (1, 2, 3, 4)}
        assert 'OPERATION ENABLED' not in states, states
        life.transition(Transition.TRANSITION_ACTIVATE)
        wait_until(lambda: {bus.drives[n].state for n in (1, 2, 3, 4)} == {'OPERATION ENABLED'},
                   10.0, 'every drive enabled')
        life.transition(Transition.TRANSITION_DEACTIVATE)
        wait_until(lambda: {bus.drives[n].state for n in (1, 2, 3, 4)} == {'READY TO SWITCH ON'},
                   10.0, 'every drive in READY TO SWITCH ON')
        wait_until(lambda: diagnostic_values(life.diagnostics, 'cable_driver')[1].level
                   == b'\x00' and life.values().get('lifecycle') == 'inactive', 10.0,
                   'OK and inactive on diagnostics')
        life.refused('cable_1', 0.31)
    finally:
        bus.close()
