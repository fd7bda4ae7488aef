"""Teleoperation without DDS: resolved-rate motion through the model's equilibria."""
from conftest import REPO
import numpy as np

from continuum_statics import load_robot
from continuum_statics.control.teleop import TeleopRun, TeleopSettings, Twist

ROBOT = load_robot(REPO / 'config' / 'two_section_robot.yaml')
DT = 0.02
ZERO = np.zeros(6)


def bent_start(ux=2.0, uy=1.0):
    """Return an equilibrium inside the workspace (its tip can move any way from there)."""
    return ROBOT.solve_tip_goal(ROBOT.solve_ivp([ux, uy, 0.0]).tip_position)


def drive(run, velocity, seconds, start_time=0.0, angular=(0.0, 0.0, 0.0)):
    t, commands = start_time, []
    for _ in range(int(round(seconds / DT))):
        t += DT
        command = run.tick(t, DT, Twist(np.asarray(velocity, dtype=float),
                                        np.asarray(angular, dtype=float), t), ZERO)
        if command is not None:
            commands.append(command.copy())
    return t, commands


def test_a_constant_twist_moves_the_tip_at_that_velocity_through_equilibria():
    start = bent_start()
    run = TeleopRun(ROBOT, TeleopSettings(max_tip_speed=0.05, max_cable_speed=0.02))
    run.start(start, start.cable_lengths)
    velocity = np.array([0.0, 0.01, -0.005])
    _, commands = drive(run, velocity, 1.0)
    moved = run.state.tip_position - start.shape.tip_position
    np.testing.assert_allclose(moved, velocity * 1.0, atol=2e-4)
    assert not run.stopped
    # every command is an equilibrium of the robot: the model's own lengths at its state
    np.testing.assert_allclose(ROBOT.cable_lengths(run.state), commands[-1], atol=1e-9)
    steps = np.abs(np.diff(np.array(commands), axis=0)).max(axis=1)
    assert steps.max() <= 0.02 * DT * 1.05


def test_the_speed_is_capped_and_the_dead_man_stops_it():
    start = bent_start()
    run = TeleopRun(ROBOT, TeleopSettings(max_tip_speed=0.005, twist_timeout=0.3))
    run.start(start, start.cable_lengths)
    t, _ = drive(run, [0.05, 0.0, 0.0], 0.5)  # ten times the cap
    moved = np.linalg.norm(run.state.tip_position - start.shape.tip_position)
    assert abs(moved - 0.005 * 0.5) < 2e-4, moved
    old = Twist(np.array([0.05, 0.0, 0.0]), np.zeros(3), t)
    assert run.tick(t + 0.2, DT, old, ZERO) is not None  # within the dead-man time
    assert run.tick(t + 0.4, DT, old, ZERO) is None and not run.active
    assert 'dead-man' in run.reason


def test_the_tip_stops_at_the_edge_of_the_workspace_inside_the_length_limits():
    start = bent_start(3.0, 0.0)
    run = TeleopRun(ROBOT, TeleopSettings(max_tip_speed=0.05))
    run.start(start, start.cable_lengths)
    _, commands = drive(run, [0.05, 0.0, 0.05], 4.0)  # outwards and up: out of reach
    assert run.stopped and 'stopped at' in run.stopped
    limits = ROBOT.cable_length_limits
    commands = np.array(commands)
    assert np.all(commands >= limits[:, 0] - 1e-12) and np.all(commands <= limits[:, 1] + 1e-12)
    # still an equilibrium, and still following a twist back inwards
    _, _ = drive(run, [-0.01, 0.0, 0.0], 0.2, start_time=10.0)
    assert not run.stopped


def test_the_keyboard_tool_maps_keys_to_velocities():
    from continuum_statics.tools.teleop import velocity_for

    direction, speed = velocity_for('w', np.zeros(3), 0.01)
    assert direction.tolist() == [1.0, 0.0, 0.0] and speed == 0.01
    assert velocity_for('f', direction, speed)[0].tolist() == [0.0, 0.0, -1.0]
    assert velocity_for('+', direction, speed)[1] > speed
    assert not velocity_for(' ', direction, speed)[0].any()
    assert velocity_for('q', direction, speed)[0] is None


def test_a_start_from_slack_cables_moves_on_top_of_their_tensions():
    # the estimate of lengths with a paid-out cable is the tendon model's: for the distributed
    # model its shape carries the cables' tensions, which the twist must keep
    start = bent_start()
    lengths = ROBOT.cable_lengths(start.shape)
    lengths[4] += 0.002
    estimate = ROBOT.estimate_shape(lengths, warm_start=start)
    assert estimate.tendons is not None and np.any(estimate.shape.fixed_tensions)
    run = TeleopRun(ROBOT, TeleopSettings(max_tip_speed=0.05, max_cable_speed=0.02))
    run.start(estimate, ROBOT.cable_lengths(estimate.shape))  # as tip_controller starts it
    velocity = np.array([0.0, 0.01, -0.005])
    drive(run, velocity, 0.5)
    assert not run.stopped
    moved = run.state.tip_position - estimate.shape.tip_position
    np.testing.assert_allclose(moved, velocity * 0.5, atol=2e-4)
