"""Commands with real tendons, the tendon robot file and the simulated tendons (no DDS).

Truths: the robot's own equilibrium for motor-held lengths (solve_lengths) must put the tip where
the plan said, with the tensions the plan asked for; an antagonist commanded at min_tension
carries it; a goal needing more than tension_limits is refused by name; the loop reaches goals on
a plant whose tip comes from solve_lengths (the real robot of this model) with friction.
"""
import dataclasses

from conftest import REPO
import numpy as np
import pytest
from test_control_goal_run import Plant, drive, start
import yaml

from continuum_statics import Robot, load_robot
from continuum_statics.control.goal_run import GoalRun, RunSettings
from continuum_statics.control.teleop import TeleopRun, TeleopSettings, Twist
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.statics.tendon_commands import command_for, shape_tensions
from continuum_statics.drivers.sim import SimulatedCableBackend

REAL = REPO / 'config' / 'tendon_robot_real_tendons.yaml'


def real_robot(**tendons):
    data = yaml.safe_load(REAL.read_text())
    data['tendons'].update(tendons)
    return Robot(parse_robot_description(data))


def test_commanded_lengths_hold_the_planned_shape_with_the_planned_tensions():
    robot = real_robot(friction=0.0)
    plan = robot.solve_tip_goal(robot.solve_ivp([2.0, -1.0, 0.0]).tip_position)
    assert plan.converged, plan.message
    command = command_for(robot, plan.shape, min_tension=1.5)
    held = robot.solve_lengths(command.lengths)
    assert held.converged, held.message
    assert np.linalg.norm(held.shape.tip_position - plan.shape.tip_position) < 1e-7
    assert np.allclose(held.tensions, command.tensions, rtol=1e-6, atol=1e-7)
    # the antagonists carry min_tension, none is slack; ideal cables would command the paths
    assert np.min(held.tensions) == pytest.approx(1.5, rel=1e-6) and not held.slack.any()


def test_min_tension_zero_on_ideal_cables_commands_the_paths():
    robot = load_robot(REPO / 'config' / 'tendon_robot.yaml')
    plan = robot.solve_tip_goal(robot.solve_ivp([2.0, -1.0, 0.0]).tip_position)
    assert np.array_equal(command_for(robot, plan.shape).lengths,
                          robot.cable_lengths(plan.shape))


def test_section_tensions_balance_the_section_moment():
    robot = load_robot(REPO / 'config' / 'three_section_robot.yaml')
    truth = robot.solve_tensions([0.0, 0.0, 3.0, 1.0, 0.0, 0.0, 0.0, 2.0, 0.0])
    estimate = robot.estimate_shape(robot.cable_lengths(truth))
    tensions = shape_tensions(robot, estimate.shape, min_tension=0.5)
    assert np.all(tensions >= 0.5 - 1e-12)
    # the same shape again from those tensions (forward statics, another solver)
    again = robot.solve_tensions(tensions)
    assert np.linalg.norm(again.tip_position - truth.tip_position) < 1e-7


def test_a_goal_over_the_tension_limit_is_rejected_naming_the_cable():
    robot = real_robot(tension_limits=[0.0, 3.0])
    run = GoalRun(robot, RunSettings())
    plant = Plant(robot.straight_cable_lengths, robot=robot)
    goal_position = robot.solve_ivp([3.0, 0.0, 0.0]).tip_position
    with pytest.raises(ValueError, match=r'tension_limits allow: cable_\d .* > 3 N'):
        start(run, plant, goal_position)


@pytest.mark.parametrize('friction', [0.0, 0.1])
def test_goals_are_reached_on_a_plant_with_stretch_pretension_and_friction(friction):
    robot = real_robot(friction=friction)
    run = GoalRun(robot, RunSettings(min_tension=1.0))
    plant = Plant(robot.straight_cable_lengths, robot=robot)
    for bending in ([2.0, 0.5, 0.0], [-1.0, 2.0, 0.0]):
        target = robot.solve_ivp(bending).tip_position
        goal, _, _ = start(run, plant, target)
        drive(run, plant, goal)
        assert goal.reached, goal.reason
        assert np.linalg.norm(plant.tips[-1].position - target) <= 1e-3
        tensions = plant.estimate.tensions
        assert tensions is not None and np.min(tensions) > 0.5  # antagonists kept taut


def test_sim_backend_reports_the_tendon_models_tensions():
    robot = real_robot()
    sim = SimulatedCableBackend(robot.cable_names, robot.cable_length_limits,
                                robot.straight_cable_lengths, robot=robot, time_constant=0.0,
                                max_speed=1.0)
    sim.start(0.0)
    reading = sim.read(0.0)
    assert np.allclose(reading.tensions, 2.0, atol=0.01)  # the pretension at home
    lengths = robot.straight_cable_lengths.copy()
    lengths[2] += 0.005  # pay cable_2 out: slack
    lengths[0] -= 0.002  # pull cable_0
    sim.command(lengths, 0.0)
    reading = sim.read(0.1)
    assert reading.tensions[2] == 0.0 and reading.tensions[0] > 2.0
    ideal = load_robot(REPO / 'config' / 'tendon_robot.yaml')
    plain = SimulatedCableBackend(ideal.cable_names, ideal.cable_length_limits,
                                  ideal.straight_cable_lengths, robot=ideal)
    plain.start(0.0)
    assert plain.read(0.0).tensions is None  # ideal cables: nothing measured, as before


def test_tendon_keys_are_validated_naming_the_field():
    data = yaml.safe_load(REAL.read_text())
    for key, value, words in (('stiffness', -1.0, 'tendons.stiffness must be > 0'),
                              ('friction', -0.1, 'tendons.friction must be >= 0'),
                              ('tension_limits', [5.0, 1.0], 'tendons.tension_limits must'),
                              ('colour', 1.0, 'unknown keys')):
        bad = dict(data, tendons=dict(data['tendons'], **{key: value}))
        with pytest.raises(ValueError, match=words):
            parse_robot_description(bad)
    bad = dict(data)
    bad['cables'] = [dict(c) for c in data['cables']]
    bad['cables'][1]['stiffness'] = 'stiff'
    with pytest.raises(ValueError, match=r'cables\[1\]\.stiffness must be a number'):
        parse_robot_description(bad)
    # a cable entry overrides the file's defaults
    good = dict(data)
    good['cables'] = [dict(c) for c in data['cables']]
    good['cables'][3]['stiffness'] = 500.0
    robot = Robot(parse_robot_description(good))
    assert robot.tendons.stiffness.tolist() == [2000.0, 2000.0, 2000.0, 500.0]
    assert dataclasses.replace(robot.tendons).pretension.tolist() == [2.0] * 4


def test_teleoperation_commands_the_stretch_its_equilibria_need():
    data = yaml.safe_load((REPO / 'config' / 'two_section_robot.yaml').read_text())
    data['tendons'] = {'stiffness': 1500.0, 'pretension': 1.0}
    robot = Robot(parse_robot_description(data))  # 4 bending freedoms: the tip can go anywhere
    start = robot.solve_tip_goal(robot.solve_ivp([2.0, 1.0, 0.0]).tip_position)
    run = TeleopRun(robot, TeleopSettings(max_tip_speed=0.05, max_cable_speed=0.02))
    run.start(start, command_for(robot, start.shape).lengths)
    t, command = 0.0, None
    for _ in range(25):
        t += 0.02
        command = run.tick(t, 0.02, Twist(np.array([0.0, 0.01, -0.005]), np.zeros(3), t),
                           np.zeros(6))
    assert not run.stopped
    # the robot holding the last command is where teleoperation's own state says the tip is
    held = robot.solve_lengths(command)
    assert held.converged, held.message
    assert np.linalg.norm(held.shape.tip_position - run.state.tip_position) < 1e-7
    # paths (what ideal cables would command) would be millimetres off with this stretch
    assert np.max(np.abs(robot.cable_lengths(run.state) - command)) > 1e-4


def test_pulled_in_cables_fit_no_shape_even_after_slack_ones():
    # inextensible cables pulled in against the rod's axial stiffness "balance" with ~1.6 kN of
    # tension; after an estimate with slack cables (the warm start tries the tendon model first)
    # that must still be no shape: once it was taken and statics never dropped such lengths
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    plan = robot.solve_tip_goal(robot.solve_ivp([2.0, 1.0, 0.0]).tip_position)
    paid_out = plan.cable_lengths.copy()
    paid_out[4] += 0.003
    previous = robot.estimate_shape(paid_out)
    assert previous.slack is not None and previous.slack[4]
    pulled_in = plan.cable_lengths.copy()
    pulled_in[:3] -= 0.004
    estimate = robot.estimate_shape(pulled_in, warm_start=previous)
    assert estimate.tendons is None and estimate.residual > 2e-3
    assert 'fit no shape' in estimate.message
