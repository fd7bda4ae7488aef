"""cable_driver with the simulated backend, over DDS in one process (private context)."""
import math

from conftest import REPO
from nodes_helpers import (
    RELIABLE,
    Collector,
    diagnostic_values,
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

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.nodes.cable_driver_node import CableDriverNode  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')


def start(harness, **overrides):
    driver = harness.add(CableDriverNode, **overrides)
    client = harness.client()
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    commands = client.create_publisher(JointState, 'cable_commands', RELIABLE)
    wait_until(lambda: len(states) >= 5, 10.0, 'cable_states')
    wait_matched(commands, driver)
    return driver, states, diagnostics, commands


def lengths_of(msg):
    return dict(zip(msg.name, msg.position))


def test_starts_at_the_straight_rod_lengths(harness):
    _, states, _, _ = start(harness)
    msg = states.last
    assert list(msg.name) == list(ROBOT.cable_names)
    np.testing.assert_allclose(msg.position, ROBOT.straight_cable_lengths, atol=1e-12)
    assert msg.header.stamp.sec > 0


def test_follows_commands_and_clamps_within_the_margin(harness):
    _, states, diagnostics, commands = start(harness, length_margin=0.002,
                                             **{'sim.max_speed': 0.5})
    high = float(ROBOT.cable_length_limits[1][1])
    command = JointState(name=['cable_0', 'cable_1'], position=[0.305, high + 0.0015])
    publish_until(commands, command,
                  lambda: abs(lengths_of(states.last)['cable_0'] - 0.305) < 1e-6
                  and abs(lengths_of(states.last)['cable_1'] - high) < 1e-6, 10.0,
                  'cable_0 at 0.305 m and cable_1 clamped at its maximum')
    assert max(max(m.position) for m in states.messages) <= high + 1e-12
    np.testing.assert_allclose(lengths_of(states.last)['cable_2'],
                               ROBOT.straight_cable_lengths[2], atol=1e-12)
    wait_until(lambda: (diagnostic_values(diagnostics, 'cable_driver') or ({},))[0].get(
        'commands_clamped', '0') != '0', 5.0, 'the clamp on diagnostics')


def test_commands_beyond_the_margin_are_rejected_and_a_correct_one_recovers(harness):
    _, states, diagnostics, commands = start(harness, length_margin=0.002, command_timeout=0.2,
                                             **{'sim.max_speed': 0.5})
    high = float(ROBOT.cable_length_limits[1][1])
    commands.publish(JointState(name=['cable_0', 'cable_1'], position=[0.29, high + 0.05]))
    wait_until(lambda: 'outside the length limits' in (diagnostic_values(
        diagnostics, 'cable_driver') or ({},))[0].get('last_rejection', ''), 5.0,
        'the rejection on diagnostics')
    values, status = diagnostic_values(diagnostics, 'cable_driver')
    assert 'cable_1 0.3800 m not in [0.2700, 0.3300]' in values['last_rejection']
    assert status.level == b'\x01'
    # Nothing of the rejected command was carried out, not even the valid cable_0.
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)
    # The watchdog holds (no valid command for 0.2 s); a correct command moves again.
    wait_until(lambda: (diagnostic_values(diagnostics, 'cable_driver') or ({},))[0].get(
        'holding') == 'True', 5.0, 'holding')
    publish_until(commands, JointState(name=['cable_0'], position=[0.29]),
                  lambda: abs(lengths_of(states.last)['cable_0'] - 0.29) < 1e-6, 10.0,
                  'cable_0 at 0.29 m after the rejection and the hold')


BAD_COMMANDS = [
    (JointState(name=['cable_0'], position=[math.nan]), 'non-finite'),
    (JointState(name=['cable_9'], position=[0.3]), 'unknown cable name'),
    (JointState(name=['cable_0', 'cable_1'], position=[0.3]), '2 names but 1 positions'),
    (JointState(name=['cable_0', 'cable_0'], position=[0.3, 0.3]), 'repeated'),
    (JointState(name=['cable_0', 'cable_1'], position=[0.3, 0.3], velocity=[1.0]),
     '2 names but 1 velocity'),
    (JointState(name=['cable_0'], position=[0.3], effort=[math.nan]), 'non-finite effort'),
]


def test_bad_commands_are_rejected_and_the_driver_keeps_publishing(harness):
    _, states, diagnostics, commands = start(harness)
    for count, (command, reason) in enumerate(BAD_COMMANDS, 1):
        commands.publish(command)
        wait_until(lambda: (diagnostic_values(diagnostics, 'cable_driver') or ({},))[0].get(
            'rejected_cable_commands') == str(count), 5.0, 'rejection %d on diagnostics' % count)
        values = diagnostic_values(diagnostics, 'cable_driver')[0]
        assert reason in values['last_rejection']
    count = len(states)
    wait_until(lambda: len(states) > count + 5, 5.0, 'cable_states after the bad commands')
    assert all(np.all(np.isfinite(m.position)) for m in states.messages)
    np.testing.assert_allclose(states.last.position, ROBOT.straight_cable_lengths, atol=1e-12)


def test_watchdog_holds_position_when_commands_stop(harness):
    _, states, diagnostics, commands = start(harness, command_timeout=0.2,
                                             **{'sim.max_speed': 0.002})
    publish_until(commands, JointState(name=['cable_0'], position=[0.32]),
                  lambda: lengths_of(states.last)['cable_0'] > 0.3002, 5.0, 'cable_0 moving')

    def frozen():  # the last 20 states (0.1 s at 200 Hz) all equal
        recent = [lengths_of(m)['cable_0'] for m in states.messages[-20:]]
        return len(recent) == 20 and max(recent) == min(recent) > 0.3002

    wait_until(frozen, 5.0, 'cable_0 to stop after the commands stopped')
    held = lengths_of(states.last)['cable_0']
    assert held < 0.31, 'held well short of the 0.32 m target'
    wait_until(lambda: (diagnostic_values(diagnostics, 'cable_driver') or ({},))[0].get(
        'holding') == 'True', 5.0, 'holding on diagnostics')
    count = len(states)
    wait_until(lambda: len(states) > count + 20, 5.0, 'more cable_states')
    assert lengths_of(states.last)['cable_0'] == held


INVALID_PARAMETERS = [
    ('publish_rate', 0.0, 'publish_rate'),
    ('publish_rate', math.nan, 'publish_rate'),
    ('publish_rate', 'fast', 'type'),
    ('backend', 'other', 'read-only'),
    ('robot_file', '/tmp/robot.yaml', 'read-only'),
    ('sim.max_speed', -1.0, 'max_speed'),
    ('sim.seed', 3, 'read-only'),
    ('command_timeout', -0.1, 'command_timeout'),
]


def test_invalid_parameter_sets_are_rejected_with_a_reason(harness):
    from rclpy.parameter import Parameter

    driver, states, _, _ = start(harness)
    for name, value, reason in INVALID_PARAMETERS:
        result = driver.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful, (name, value)
        assert reason.lower() in result.reason.lower(), (name, value, result.reason)
    assert driver.get_parameter('publish_rate').value == 200.0
    count = len(states)
    wait_until(lambda: len(states) > count + 3, 5.0, 'cable_states after the rejected sets')


def test_valid_parameter_sets_apply(harness):
    from rclpy.parameter import Parameter

    driver, _, _, _ = start(harness)
    results = driver.set_parameters([Parameter('publish_rate', value=50.0),
                                     Parameter('sim.noise_std', value=1e-5)])
    assert all(result.successful for result in results)
    assert driver.backend.noise_std == 1e-5


def test_a_robot_without_cables_is_said_once_and_the_driver_stays_quiet(harness):
    from rcl_interfaces.msg import Log

    client = harness.client()
    logs = Collector(client, Log, '/rosout', RELIABLE)
    diagnostics = Collector(client, DiagnosticArray, '/diagnostics', 10)
    states = Collector(client, JointState, 'cable_states', qos_profile_sensor_data)
    wait_until(lambda: client.count_publishers('/rosout') >= 1, 10.0, 'rosout')
    harness.add(CableDriverNode, robot_file=str(REPO / 'config' / 'jones2009_nitinol_rod.yaml'))
    wait_until(lambda: sum(1 for a in diagnostics.messages for s in a.status
                           if s.name.endswith('cable_driver')) >= 20, 10.0, '20 diagnostics')
    _, status = diagnostic_values(diagnostics, 'cable_driver')
    assert status.level == b'\x00' and 'no cables' in status.message
    said = [m.msg for m in logs.messages if 'nothing to drive' in m.msg]
    assert len(said) == 1, [m.msg for m in logs.messages]
    assert 'no cables' in said[0]
    assert len(states) == 0


def test_empty_and_malformed_raw_commands_are_counted(harness):
    _, states, diagnostics, commands = start(harness)

    def values():
        return (diagnostic_values(diagnostics, 'cable_driver') or ({},))[0]

    cases = [(b'', 'empty payload'),
             (b'\x00\x01\x00\x00' + b'\xff' * 40, 'malformed JointState')]
    for count, (payload, reason) in enumerate(cases, 1):
        commands.publish(payload)  # serialized bytes, as a raw publisher sends them
        wait_until(lambda: values().get('rejected_cable_commands') == str(count), 5.0,
                   'raw rejection %d on diagnostics' % count)
        assert reason in values()['last_rejection']
    assert values()['empty_payloads_total'] == '1'
    # a correct command still moves the cables
    target = ROBOT.straight_cable_lengths - 0.001
    commands.publish(JointState(name=list(ROBOT.cable_names), position=target.tolist()))
    wait_until(lambda: np.allclose(states.last.position, target, atol=1e-4), 5.0,
               'the cables at the commanded lengths')
