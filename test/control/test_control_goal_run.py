"""The tip-goal run without DDS: the controller's decisions against a simulated robot.

The plant: cables follow the command with a first-order lag (as the sim driver), and the tip is
the shape the model gives for the measured lengths (as statics), optionally biased (a model
error the closed loop must correct). Time is simulated: every tick is one control period.
"""
import dataclasses

from conftest import REPO
import numpy as np
import pytest

from continuum_statics import Robot, load_robot
from continuum_statics.control.goal_run import Goal, GoalRun, Phase, RunSettings
from continuum_statics.control.records import Measurement, TipSample
from continuum_statics.core.description.obstacles import parse_obstacles

ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
DT = 0.02
ZERO = np.zeros(6)


class Plant:
    """Cables with a lag of ``tau`` s; the tip from the shape of the measured lengths.

    ``robot``: the real robot, when it differs from the controller's model.
    """

    def __init__(self, lengths, tau=0.02, robot=ROBOT, stamp_ns=None):
        self.lengths = np.array(lengths, dtype=float)
        self.tau = tau
        self.robot = robot
        self.stamp_ns = stamp_ns  # None: stamped with the time; 0: unstamped
        self.estimate = None
        self.tips = []

    def step(self, command, now):
        if command is not None:
            self.lengths += (command - self.lengths) * (1.0 - np.exp(-DT / self.tau))
        stamp = int(now * 1e9) if self.stamp_ns is None else self.stamp_ns
        self.estimate = self.robot.estimate_shape(self.lengths, warm_start=self.estimate)
        tip = TipSample(self.estimate.shape.tip_position, stamp, now)
        self.tips.append(tip)
        return Measurement(self.lengths.copy(), stamp, now), tip


def start(run, plant, goal_position, now=0.0, tolerance=1e-3, timeout=10.0):
    measurement, tip = plant.step(None, now)
    plan = run.plan(np.asarray(goal_position), tolerance, None, measurement.lengths, ZERO, True,
                    run.snapshot())
    goal = Goal(position=np.asarray(goal_position, dtype=float), tolerance=tolerance,
                source='test', started=now, deadline=now + timeout)
    previous = run.begin(goal, plan, now)
    return goal, plan, previous


def drive(run, plant, goal, now=0.0, ticks=2000, commands=None, phases=None):
    """Tick until the goal is done; return the time."""
    measurement, tip = plant.step(None, now)
    command = None
    for _ in range(ticks):
        now += DT
        measurement, tip = plant.step(command, now)
        command = run.tick(now, DT, measurement, tip, plant.tips[-200:], ZERO)
        if commands is not None and command is not None:
            commands.append(command.copy())
        if phases is not None and (not phases or phases[-1] is not run.phase):
            phases.append(run.phase)
        if goal.done.is_set():
            return now
    raise AssertionError('goal not done after %d ticks: phase %s' % (ticks, run.phase))


def test_a_reachable_goal_goes_through_the_phases_and_is_reached_within_the_speed_limit():
    settings = RunSettings(max_cable_speed=0.02)
    run = GoalRun(ROBOT, settings)
    plant = Plant(ROBOT.straight_cable_lengths)
    target = ROBOT.solve_ivp([2.0, -1.0, 0.0]).tip_position
    goal, plan, _ = start(run, plant, target)
    assert plan.recover is None or run.phase is Phase.RECOVER
    commands, phases = [np.array(ROBOT.straight_cable_lengths)], []
    drive(run, plant, goal, commands=commands, phases=phases)
    assert goal.reached, goal.reason
    assert goal.error <= 1e-3
    assert [p for p in phases if p is not Phase.IDLE][-2:] == [Phase.SETTLE, Phase.JUDGE]
    steps = np.abs(np.diff(np.array(commands), axis=0)).max(axis=1)
    assert steps.max() <= settings.max_cable_speed * DT * 1.05 + 1e-12
    limits = ROBOT.cable_length_limits
    assert np.all(np.array(commands) >= limits[:, 0]) and np.all(
        np.array(commands) <= limits[:, 1])
    assert run.phase is Phase.IDLE and run.goal is None


def test_the_tick_that_ends_a_goal_commands_nothing():
    # The service answers as the goal ends; a command published after that would overwrite the
    # client's next one (a hand-made command lost behind the goal's last, seen across processes).
    run = GoalRun(ROBOT)
    plant = Plant(ROBOT.straight_cable_lengths)
    goal, _, _ = start(run, plant, ROBOT.solve_ivp([1.0, 0.5, 0.0]).tip_position)
    now, command, returned = 0.0, None, []
    while not goal.done.is_set() and now < 20.0:
        now += DT
        measurement, tip = plant.step(command, now)
        command = run.tick(now, DT, measurement, tip, plant.tips[-200:], ZERO)
        returned.append(command)
    assert goal.reached, goal.reason
    assert returned[-1] is None and returned[-2] is not None


def test_a_model_error_is_corrected_in_closed_loop():
    # the real robot's holes sit 0.5 mm further out than the robot file says: it bends less
    # for the same lengths, and the tip misses by millimetres until corrected
    real = Robot(dataclasses.replace(ROBOT.description,
                                     cable_offsets=ROBOT.description.cable_offsets * 1.05))
    run = GoalRun(ROBOT, RunSettings())
    plant = Plant(ROBOT.straight_cable_lengths, robot=real)
    target = ROBOT.solve_ivp([1.0, 1.5, 0.0]).tip_position
    goal, _, _ = start(run, plant, target)
    drive(run, plant, goal)
    assert goal.reached, goal.reason
    assert run.corrections >= 1
    assert np.linalg.norm(plant.tips[-1].position - target) <= 1e-3


def test_cables_still_closing_on_their_command_are_waited_for():
    # motors lagging 0.5 s (a simulated rod behind real time, a slow drive): settle_time (0.2 s)
    # alone ended the wait, the tip of the moving cables was judged and "corrected" past the
    # goal; the cables' gap must stop closing first
    run = GoalRun(ROBOT, RunSettings())
    plant = Plant(ROBOT.straight_cable_lengths, tau=0.5)
    target = ROBOT.solve_ivp([2.0, 1.0, 0.0]).tip_position
    goal, _, _ = start(run, plant, target)
    drive(run, plant, goal)
    assert goal.reached and run.corrections == 0, goal.reason
    assert np.linalg.norm(plant.tips[-1].position - target) <= 1e-3


def test_noisy_cables_that_never_reach_their_command_are_judged():
    # the gap to the command stops closing at the noise: the tip is judged, not waited on
    rng = np.random.default_rng(3)

    class Noisy(Plant):
        def step(self, command, now):
            measurement, tip = super().step(command, now)
            return Measurement(measurement.lengths + rng.normal(0.0, 2e-6, 4)[:len(
                measurement.lengths)], measurement.stamp_ns, now), tip

    run = GoalRun(ROBOT, RunSettings())
    plant = Noisy(ROBOT.straight_cable_lengths)
    target = ROBOT.solve_ivp([-1.0, 2.0, 0.0]).tip_position
    goal, _, _ = start(run, plant, target)
    drive(run, plant, goal)
    assert goal.reached, goal.reason


def test_unstamped_tips_are_judged_by_arrival_time():
    # every sample stamped 0: a judgement by stamp would average the poses of the move in
    run = GoalRun(ROBOT, RunSettings())
    plant = Plant(ROBOT.straight_cable_lengths, stamp_ns=0)
    target = ROBOT.solve_ivp([-2.0, 0.5, 0.0]).tip_position
    goal, _, _ = start(run, plant, target)
    drive(run, plant, goal)
    assert goal.reached and run.corrections == 0, goal.reason
    assert np.linalg.norm(plant.tips[-1].position - target) <= 1e-3


def test_cables_off_the_last_command_are_moved_onto_the_model_first():
    run = GoalRun(ROBOT, RunSettings())
    lengths = ROBOT.straight_cable_lengths.copy()
    lengths[0] += 0.004  # one cable paid out by hand: no shape has these lengths
    plant = Plant(lengths)
    goal, plan, _ = start(run, plant, ROBOT.solve_ivp([0.0, 2.0, 0.0]).tip_position)
    assert plan.recover is not None and run.phase is Phase.RECOVER
    assert run.moved_onto_model == 1
    phases = []
    drive(run, plant, goal, phases=phases)
    assert phases[0] is Phase.RECOVER and Phase.RAMP in phases
    assert goal.reached, goal.reason


def test_a_new_goal_preempts_the_running_one():
    run = GoalRun(ROBOT, RunSettings())
    plant = Plant(ROBOT.straight_cable_lengths)
    first, _, _ = start(run, plant, ROBOT.solve_ivp([2.0, 0.0, 0.0]).tip_position)
    second, _, previous = start(run, plant, ROBOT.solve_ivp([0.0, -2.0, 0.0]).tip_position)
    assert previous is first and first.done.is_set() and first.outcome == 'preempted'
    assert run.goal is second


def test_stale_cable_states_fail_the_goal_with_the_reason():
    run = GoalRun(ROBOT, RunSettings(max_state_age=0.5))
    plant = Plant(ROBOT.straight_cable_lengths)
    goal, _, _ = start(run, plant, ROBOT.solve_ivp([1.0, 0.0, 0.0]).tip_position)
    measurement, tip = plant.step(None, 0.0)
    run.tick(1.0, DT, measurement, tip, plant.tips, ZERO)  # the last reading is 1 s old
    assert goal.done.is_set() and not goal.reached
    assert 'is cable_driver running?' in goal.reason


def test_a_goal_past_its_deadline_fails():
    run = GoalRun(ROBOT, RunSettings())
    plant = Plant(ROBOT.straight_cable_lengths, tau=1e3)  # cables that barely move
    goal, _, _ = start(run, plant, ROBOT.solve_ivp([2.5, 0.0, 0.0]).tip_position, timeout=0.5)
    drive(run, plant, goal, ticks=100)
    assert not goal.reached and 'not reached within 0.5 s' in goal.reason


@pytest.mark.parametrize('goal_position,reason', [
    ((2.0, 0.0, 0.3), 'nearest reachable tip is'),
])
def test_unreachable_goals_are_rejected_with_the_distance(goal_position, reason):
    run = GoalRun(ROBOT, RunSettings())
    with pytest.raises(ValueError, match=reason):
        run.plan(np.array(goal_position), 1e-3, None, ROBOT.straight_cable_lengths, ZERO, True,
                 run.snapshot())


def test_a_goal_under_a_shelf_goes_round_it_and_the_body_never_comes_closer_than_the_clearance():
    """The robot file's shelf and clearance, through the answer's waypoints.

    The way the plant moves (every tick's shape of the measured lengths) keeps the clearance;
    without the waypoints it went 14.7 mm into the shelf.
    """
    robot = load_robot(REPO / 'config' / 'two_section_shelf.yaml')
    run = GoalRun(robot, RunSettings(max_cable_speed=0.05))
    plant = Plant(robot.straight_cable_lengths, robot=robot)
    goal, plan, _ = start(run, plant, (0.1253, -0.0238, 0.1792), tolerance=2e-3)
    assert len(plan.solution.waypoints) >= 1  # the direct way sweeps through the shelf
    shelf = robot.obstacles[0]
    gaps = []
    step = plant.step

    def watched(command, now):
        result = step(command, now)
        gaps.append(float(np.min(shelf.distance(plant.estimate.shape.positions)[0])))
        return result

    plant.step = watched
    drive(run, plant, goal)
    assert goal.reached, goal.reason
    # nodes of the followed shapes; between checks the body moves 0.05 m/s x 20 ms at most
    assert min(gaps) - robot.body_radius >= robot.clearance - 1e-3


def test_an_obstacle_arriving_on_the_way_stops_the_goal_naming_it():
    """A ball published where the answer's body will be: the next tick stops the goal."""
    run = GoalRun(ROBOT, RunSettings(max_cable_speed=0.01))
    plant = Plant(ROBOT.straight_cable_lengths)
    goal, plan, _ = start(run, plant, ROBOT.solve_ivp([2.0, -1.0, 0.0]).tip_position)
    now, command = 0.0, None
    for _ in range(3):  # on its way
        now += DT
        measurement, tip = plant.step(command, now)
        command = run.tick(now, DT, measurement, tip, plant.tips[-200:], ZERO)
    # somewhere the way has not been yet: the far side of the answer's bend
    middle = plan.solution.shape.positions[len(ROBOT.s_grid) // 2]
    run.obstacles = ()  # an empty set changes nothing
    now += DT
    measurement, tip = plant.step(command, now)
    assert run.tick(now, DT, measurement, tip, plant.tips[-200:], ZERO) is not None
    run.obstacles = parse_obstacles([{'name': 'ball', 'sphere': {'radius': 0.005},
                                      'position': middle.tolist()}])
    now += DT
    measurement, tip = plant.step(command, now)
    assert run.tick(now, DT, measurement, tip, plant.tips[-200:], ZERO) is None
    assert goal.done.is_set() and not goal.reached
    assert 'obstacles changed' in goal.reason and "'ball'" in goal.reason
