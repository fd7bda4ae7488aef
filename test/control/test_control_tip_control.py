"""TipControl without DDS: goal intake, the same-goal rule, pre-emption, teleoperation take-over.

Time is simulated (a settable clock); waiting for state is an awaitable that, when the
condition does not hold, lets the clock run to the deadline (nothing arrived meanwhile).
"""
import asyncio
import sys
import threading
import time

from conftest import REPO
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.control.goal_run import Goal, Outcome, Phase
from continuum_statics.control.health import OK, STARTING, WARN, ControllerHealth
from continuum_statics.control.tip_control import TipControl
from continuum_statics.core.statics.tendon_commands import command_for

ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
TENDONS = load_robot(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
PARAMS = dict(max_cable_speed=0.02, settle_time=0.2, settled_cable_error=1e-6,
              max_corrections=10, tip_average_time=1.0, max_state_age=0.5, min_tension=0.0,
              tracker_max_disagreement=0.0, max_tip_speed=0.05, max_tip_rate=0.5,
              twist_timeout=0.5, goal_timeout=10.0, state_wait=3.0, tip_wrench_timeout=1.0,
              tip_wrench_source='topic',
              stop_on_contact=False, use_measured_tip=True, goal_orientation='ignore',
              default_tolerance=1e-3, control_rate=50.0, clearance=None)
DT = 1.0 / PARAMS['control_rate']


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


class Log:
    def __init__(self):
        self.lines = []

    def info(self, text):
        self.lines.append(('info', text))

    def warning(self, text):
        self.lines.append(('warning', text))

    def error(self, text):
        self.lines.append(('error', text))


class Timer:
    def __init__(self):
        self.running = False

    def reset(self):
        self.running = True

    def cancel(self):
        self.running = False


def make(robot=ROBOT, **params):
    clock = Clock()

    async def wait_until(condition, deadline):
        if not condition():
            clock.now = max(clock.now, deadline)  # nothing arrived while waiting
        return condition()

    control = TipControl(robot, dict(PARAMS, **params), Log(), wait_until, clock)
    timer = Timer()
    control.set_timer(timer)
    return control, clock, timer


def feed(control, lengths, robot=ROBOT):
    """Fresh state: the lengths, and the tip statics would publish for them."""
    shape = robot.estimate_shape(lengths).shape
    stamp = int(control.clock() * 1e9)
    control.on_cable_states(np.array(lengths, dtype=float), stamp)
    control.on_tip_pose(shape.tip_position, shape.tip_rotation, stamp)


def start(control, position, tolerance=1e-3, source='test'):
    return asyncio.run(control.start_goal(np.asarray(position, dtype=float), tolerance, source))


TARGET = ROBOT.solve_ivp([2.0, -1.0, 0.0]).tip_position
OTHER = ROBOT.solve_ivp([-1.0, 1.5, 0.0]).tip_position


def test_the_same_goal_again_attaches_to_the_running_one_and_a_new_one_preempts_it():
    control, _, timer = make()
    feed(control, ROBOT.straight_cable_lengths)
    first = start(control, TARGET)
    assert control.run.goal is first and timer.running
    again = start(control, TARGET.copy(), source='tip_goal_pose')  # a stream repeats its goal
    assert again is first and not first.done.is_set()
    assert control.counts[Outcome.PREEMPTED] == 0
    # another tolerance is another goal
    second = start(control, TARGET, tolerance=2e-3)
    assert second is not first and control.run.goal is second
    assert first.done.is_set() and first.outcome is Outcome.PREEMPTED and not first.reached
    assert control.counts[Outcome.PREEMPTED] == 1 and control.counts[Outcome.FAILED] == 0
    assert control.last_outcome.startswith('preempted')


def test_the_outcome_is_the_enum_set_when_the_goal_ends_never_its_reason_text():
    control, _, _ = make()
    feed(control, ROBOT.straight_cable_lengths)
    goal = start(control, TARGET)
    # a failure whose reason happens to say "pre-empted" is still a failure
    control.finish_goal(goal, False, 'the driver was pre-empted by its watchdog')
    assert goal.outcome is Outcome.FAILED
    assert control.counts[Outcome.FAILED] == 1 and control.counts[Outcome.PREEMPTED] == 0
    # a pre-emption whose reason does not say so is still a pre-emption
    goal = start(control, OTHER)
    control.finish_goal(goal, False, 'cancelled by another client', Outcome.PREEMPTED)
    assert control.counts[Outcome.PREEMPTED] == 1 and control.counts[Outcome.FAILED] == 1
    assert control.run.phase is Phase.IDLE


def test_a_goal_overtaken_while_it_is_solved_comes_back_preempted_and_never_runs():
    control, _, timer = make()
    feed(control, ROBOT.straight_cable_lengths)
    plan = control.run.plan

    def overtaken_while_solving(*args):
        control.handover.take('teleoperation (tip_twist)')  # arrives during the solve
        return plan(*args)

    control.run.plan = overtaken_while_solving
    goal = start(control, TARGET)
    assert goal.done.is_set() and goal.outcome is Outcome.PREEMPTED
    assert 'before it started' in goal.reason and 'teleoperation' in goal.reason
    assert control.run.goal is None and not timer.running


def test_a_goal_that_arrived_before_a_twist_is_overtaken_by_it_when_it_starts_later():
    """The move_tip action's execute runs after the acceptance is sent; its place is its arrival.

    Under a CPU hog the twists that followed a goal were handled before its execute, which then
    took the newest ticket and ran after the operator's dead-man stop (a ros-tier run).
    """
    control, _, timer = make()
    feed(control, ROBOT.straight_cable_lengths)
    ticket = control.goal_arrived()  # the goal request is accepted
    control.handover.take('teleoperation (tip_twist)')  # a twist sent after it
    goal = asyncio.run(control.start_goal(np.asarray(TARGET), 1e-3, 'test', None, ticket))
    assert goal.outcome is Outcome.PREEMPTED and 'before it started' in goal.reason
    assert 'teleoperation' in goal.reason and control.run.goal is None and not timer.running
    goal = start(control, TARGET)  # arriving as it starts, after the twist: it runs
    assert control.run.goal is goal and goal.outcome is None


def test_without_cable_states_a_goal_waits_state_wait_then_is_rejected():
    control, clock, _ = make(state_wait=2.0)
    before = clock.now
    with pytest.raises(ValueError, match=r'no cable_states from cable_driver yet \(waited 2 s\)'):
        start(control, TARGET)
    assert clock.now == pytest.approx(before + 2.0)
    control.goal_rejected('no cable_states')
    assert control.counts[Outcome.REJECTED] == 1 and control.run.goal is None


def test_a_goal_is_rejected_while_the_driver_refuses_commands():
    control, _, _ = make(state_wait=0.5)
    feed(control, ROBOT.straight_cable_lengths)
    control.on_driver_status('cable_driver is inactive (lifecycle): activate it')
    with pytest.raises(ValueError, match='cable_driver refuses cable_commands: cable_driver is '
                                         'inactive'):
        start(control, TARGET)
    control.on_driver_status('')
    assert start(control, TARGET).outcome is None  # running


def test_a_goal_runs_to_reached_through_ticks_and_the_timer_stops_itself():
    control, clock, timer = make()
    lengths = np.array(ROBOT.straight_cable_lengths, dtype=float)
    feed(control, lengths)
    goal = start(control, TARGET)
    for _ in range(2000):
        clock.now += DT
        command = control.tick()
        if command is not None:
            limits = ROBOT.cable_length_limits
            assert np.all(command >= limits[:, 0]) and np.all(command <= limits[:, 1])
            lengths = lengths + (command - lengths) * (1.0 - np.exp(-1.0))  # a quick driver
        feed(control, lengths)
        if goal.done.is_set():
            break
    assert goal.reached and goal.outcome is Outcome.REACHED, goal.reason
    assert control.counts[Outcome.REACHED] == 1
    assert control.tick() is None and not timer.running  # idle: the timer stopped itself


def test_teleoperation_takes_over_a_goal_from_the_motor_side_lengths_of_the_estimate():
    control, clock, timer = make(TENDONS)
    bent = TENDONS.solve_ivp([2.0, 1.0, 0.0])
    measured = command_for(TENDONS, bent).lengths  # motor-side lengths of a bent shape
    feed(control, measured, TENDONS)
    goal = start(control, TENDONS.solve_ivp([-1.0, 1.0, 0.0]).tip_position)
    assert control.run.goal is goal
    control.twist([0.0, 0.01, 0.0], [0.0, 0.0, 0.0])
    assert goal.done.is_set() and goal.outcome is Outcome.PREEMPTED
    assert goal.reason == 'pre-empted by teleoperation'
    assert control.teleop.active and timer.running and control.phase() == 'teleoperation'
    # the goal had commanded nothing yet: the cables are off the (straight) last command, so
    # teleoperation starts from the estimate and commands its motor-side lengths, as a goal
    # would (the recovery rule of GoalRun), not the paths of its shape
    state = control.teleop.state
    limits = TENDONS.cable_length_limits
    expected = np.clip(command_for(TENDONS, state).lengths, limits[:, 0], limits[:, 1])
    np.testing.assert_allclose(control.teleop.commanded, expected, atol=1e-12)
    paths = TENDONS.cable_lengths(state)
    assert np.max(np.abs(paths - expected)) > 1e-4
    # the dead-man ends it; the goal run adopts where teleoperation left the cables
    clock.now += 2.0
    control.tick()
    assert not control.teleop.active and control.run.commanded is not None


def test_a_goal_that_waits_while_the_operator_drives_never_starts_after_the_twists():
    control, _, _ = make()
    feed(control, ROBOT.straight_cable_lengths)
    control.twist([0.0, 0.01, 0.0], [0.0, 0.0, 0.0])
    assert control.teleop.active
    wait = control.wait_until

    async def twists_while_waiting(*args):  # the goal waits for state; the twists go on
        control.twist([0.0, 0.01, 0.0], [0.0, 0.0, 0.0])
        return await wait(*args)

    control.wait_until = twists_while_waiting
    goal = start(control, TARGET)
    assert goal.done.is_set() and goal.outcome is Outcome.PREEMPTED, goal.reason
    assert 'teleoperation' in goal.reason and control.teleop.active


def test_a_twist_stamped_far_from_now_is_refused_and_an_unstamped_one_is_taken():
    control, _, _ = make()
    feed(control, ROBOT.straight_cable_lengths)
    with pytest.raises(ValueError, match='a replayed command'):
        control.twist([0.0, 0.01, 0.0], [0.0, 0.0, 0.0], stamp_ns=1, clock_ns=10 * 10**9)
    assert not control.teleop.active
    control.twist([0.0, 0.01, 0.0], [0.0, 0.0, 0.0], stamp_ns=0, clock_ns=10 * 10**9)
    assert control.teleop.active


def test_controller_health_levels():
    control, clock, _ = make()
    health = ControllerHealth(control)
    level, message, values = health.report()
    assert level == OK and message.startswith(STARTING) and values['state'] == 'starting'
    feed(control, ROBOT.straight_cable_lengths)
    level, message, values = health.report()
    assert (level, message, values['state']) == (OK, 'idle', 'ready')
    control.goal_rejected('unreachable goal')
    level, message, values = health.report()
    assert level == WARN and 'unreachable goal' in message
    assert values['goals_rejected'] == 1 and values['goals_reached'] == 0
    clock.now += 10.0  # the problem is old; two publishers of cable_commands is not
    level, message, _ = health.report({'cable_commands': 2}.get)
    assert level == WARN and 'two controllers' in message


def test_a_matched_input_never_heard_is_named():
    # a tip_controller SIGKILLed and restarted heard neither its state nor its goals while its
    # peers published them (Fast DDS shared memory, eProsima/Fast-DDS#5053); it said "waiting
    # for state", with no hint at the transport or what to restart
    control, clock, _ = make()
    health = ControllerHealth(control)
    published = {'cable_states': 1, 'tip_pose': 1}.get
    level, message, _ = health.report(published)
    assert level == OK and message.startswith(STARTING)  # just started: waiting is normal
    clock.now += 6.0
    level, message, _ = health.report({}.get)  # nobody publishes: the drivers are not up
    assert level == OK and message.startswith(STARTING)
    level, message, values = health.report(published)
    assert level == WARN and 'no cable_states in 6 s' in message
    assert 'restart cable_driver' in message and values['state'] == 'starting'
    control.on_cable_states(ROBOT.straight_cable_lengths, 0)  # statics is the one unheard
    level, message, _ = health.report(published)
    assert level == WARN and 'restart statics' in message
    feed(control, ROBOT.straight_cable_lengths)
    assert health.report(published)[:2] == (OK, 'idle')


def test_backbone_after_waits_for_the_backbone_of_the_reached_tip():
    control, clock, _ = make()
    control.on_backbone(5, b'old')
    assert asyncio.run(control.backbone_after(None)) == b'old'
    before = clock.now
    assert asyncio.run(control.backbone_after(10)) == b'old'  # the newer one never came
    assert clock.now == pytest.approx(before + 0.5)
    control.on_backbone(10, b'new')
    assert asyncio.run(control.backbone_after(10)) == b'new'


@pytest.mark.parametrize('source', ['topic', 'estimate'])
def test_a_tip_wrench_expires_to_zero_and_an_estimated_load_is_kept(source):
    """tip_wrench_timeout: zero load after it, but an estimate's load stays (statics' rule)."""
    control, clock, _ = make(tip_wrench_source=source)
    load = np.array([0.12, -0.08, 0.0, 0.0, 0.0, 0.0])
    control.on_tip_wrench(load)
    clock.now += 0.9
    np.testing.assert_array_equal(control.current_tip_load(), load)
    clock.now += 0.2  # past tip_wrench_timeout (1 s)
    np.testing.assert_array_equal(control.current_tip_load(),
                                  np.zeros(6) if source == 'topic' else load)


def test_shutdown_ends_the_running_goal():
    control, _, _ = make()
    feed(control, ROBOT.straight_cable_lengths)
    goal = start(control, TARGET)
    control.release()
    assert goal.done.is_set() and goal.reason == 'shutting down'
    assert goal.outcome is Outcome.FAILED and control.closing
    assert isinstance(goal, Goal)


def test_goals_are_judged_while_another_thread_takes_tip_poses_at_full_speed():
    """The intake thread appends tips while the loop judges a goal over them (the demo's race).

    The judge once iterated the deque the intake appends to: ``RuntimeError: deque mutated
    during iteration`` about one ``make demo`` in seven. Here, as in the node, one intake thread
    delivers every tip, in order: the newest the plant shows, again and again as fast as it can
    (far above a tracker's 2 kHz), while the loop ticks four goals, the threads switching every
    microsecond (the race then shows in every run). The loop ticks once its newest tip is in.
    """
    control, clock, _ = make(tip_average_time=0.2)
    lengths = np.array(ROBOT.straight_cable_lengths, dtype=float)
    stop, fed, newest, delivered = threading.Event(), [0], [None], [0]

    def intake():
        while not stop.is_set():
            if newest[0] is None:
                continue
            position, rotation, stamp, version = newest[0]
            control.on_tip_pose(position, rotation, stamp)
            control.on_tip_pose_measured(position, stamp)
            delivered[0], fed[0] = version, fed[0] + 1

    def plant(lengths, version):
        """Measure ``lengths``; hand the tip statics shows for them to the intake."""
        shape = ROBOT.estimate_shape(lengths).shape
        stamp = int(control.clock() * 1e9)
        control.on_cable_states(np.array(lengths, dtype=float), stamp)
        newest[0] = (shape.tip_position, shape.tip_rotation, stamp, version)
        while delivered[0] < version and feeder.is_alive():
            time.sleep(0)

    feeder = threading.Thread(target=intake, daemon=True)
    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # threads interleave as on a loaded machine
    feeder.start()
    version = 1
    try:
        plant(lengths, version)
        for target in (TARGET, OTHER, TARGET, OTHER):
            goal = start(control, target, tolerance=5e-3)
            for _ in range(3000):
                clock.now += DT
                command = control.tick()
                if command is not None:
                    lengths = lengths + (command - lengths) * (1.0 - np.exp(-1.0))
                version += 1
                plant(lengths, version)
                if goal.done.is_set():
                    break
            assert goal.outcome is Outcome.REACHED, goal.reason
    finally:
        stop.set()
        feeder.join()
        sys.setswitchinterval(interval)
    assert fed[0] > version  # the feeder ran throughout, more often than the plant moved
