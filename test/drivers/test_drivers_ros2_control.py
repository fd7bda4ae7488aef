"""ros2_control bridge: cable_driver against a stand-in forward position controller over DDS."""
import math
import threading
import time

from nodes_helpers import (
    RELIABLE,
    Collector,
    publish_until,
    wait_matched,
    wait_until,
)
import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy')
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rclpy.qos import qos_profile_sensor_data  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

from continuum_statics.drivers import ConnectionLost  # noqa: E402
from continuum_statics.drivers.ros2_control import Ros2ControlCableBackend  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402

pytestmark = pytest.mark.ros
JOINTS = ['spool_a', 'spool_b', 'spool_c', 'spool_d']
RADIUS = 0.02
NAMES = ('cable_0', 'cable_1', 'cable_2', 'cable_3')


class FakeController:
    """Joint positions follow the last command at once; joint_states at 100 Hz while on."""

    def __init__(self, node):
        self.positions = [0.5, 0.5, 0.5, 0.5]
        self.efforts = [-0.2, 0.0, 0.0, 0.0]
        self.commands = []
        self.publishing = threading.Event()
        self.publishing.set()
        self.node = node
        node.create_subscription(Float64MultiArray, 'forward_position_controller/commands',
                                 self._on_command, RELIABLE)
        self.states = node.create_publisher(JointState, 'joint_states', 10)
        node.create_timer(0.01, self._publish)

    def _on_command(self, msg):
        self.commands.append(list(msg.data))
        self.positions = list(msg.data)

    def _publish(self):
        if self.publishing.is_set():
            msg = JointState(name=JOINTS + ['unrelated'], position=self.positions + [9.0],
                             velocity=[0.0] * 5, effort=self.efforts + [0.0])
            msg.header.stamp = self.node.get_clock().now().to_msg()
            self.states.publish(msg)


def test_backend_without_ros_names_silent_joints_and_converts():
    backend = Ros2ControlCableBackend(NAMES, [[0.27, 0.33]] * 4, [0.3] * 4, joints=JOINTS,
                                      spool_radius=RADIUS, zero_positions=[0.5])
    sent = []
    backend.attach_ros(sent.append)
    with pytest.raises(ConnectionLost, match='spool_a .cable_0.'):
        backend.start(0.0)
    backend.on_joint_state(JOINTS, [0.5, 0.6, 0.5, 0.5], [0.0, 1.0, 0.0, 0.0],
                           [-0.2, 0.0, 0.1, 0.0], time.monotonic())
    backend.start(0.0)
    reading = backend.read(0.0)
    np.testing.assert_allclose(reading.lengths, [0.3, 0.3 + 0.1 * RADIUS, 0.3, 0.3])
    np.testing.assert_allclose(reading.velocities, [0.0, RADIUS, 0.0, 0.0])
    np.testing.assert_allclose(reading.tensions, [0.2 / RADIUS, 0.0, 0.0, 0.0])
    backend.command([0.31, 0.3, 0.3, 0.29], 0.0)
    np.testing.assert_allclose(sent[-1], [0.5 + 0.01 / RADIUS, 0.5, 0.5, 0.5 - 0.01 / RADIUS],
                               atol=1e-12)


def test_cable_driver_drives_the_controller_and_survives_silence(harness):
    fake = harness.client('fake_controller')
    controller = FakeController(fake)
    driver = harness.add(CableDriverNode, backend='ros2_control', command_timeout=0.0,
                         reconnect_max_interval=0.2, **{
                             'ros2_control.joints': JOINTS, 'ros2_control.spool_radius': RADIUS,
                             'ros2_control.zero_positions': [0.5]})
    client = harness.client()
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    commands = client.create_publisher(JointState, 'cable_commands', RELIABLE)
    wait_until(lambda: len(states) >= 5, 10.0, 'cable_states')
    np.testing.assert_allclose(states.last.position, [0.3] * 4, atol=1e-12)
    np.testing.assert_allclose(states.last.effort[0], 0.2 / RADIUS)
    wait_matched(commands, driver)
    publish_until(commands, JointState(name=['cable_1'], position=[0.32]),
                  lambda: abs(states.last.position[1] - 0.32) < 1e-9, 10.0, 'cable_1 at 0.32')
    assert math.isclose(controller.commands[-1][1], 0.5 + 0.02 / RADIUS)
    seen = len(diagnostics)
    controller.publishing.clear()

    def error_after(index):
        for array in diagnostics.messages[index:]:
            for status in array.status:
                if status.name.endswith('cable_driver') and status.level == b'\x02':
                    return status
        return None

    wait_until(lambda: error_after(seen) is not None, 10.0, 'ERROR when joint_states stop')
    message = error_after(seen).message
    assert 'no joint_states for joint(s) spool_a (cable_0)' in message, message
    count = len(states)
    seen = len(diagnostics)
    wait_until(lambda: len(diagnostics) > seen + 5, 10.0, 'more diagnostics')
    assert len(states) <= count + 1
    controller.publishing.set()
    wait_until(lambda: len(states) > count + 10, 10.0, 'cable_states again')
    np.testing.assert_allclose(states.last.position[1], 0.32, atol=1e-9)
