"""The cable_driver's decisions without DDS: CommandGate, Actuators, and the health objects."""
from types import SimpleNamespace

import numpy as np
import pytest

from continuum_statics.control.actuators import Actuators
from continuum_statics.control.command_gate import CommandGate, CommandRefused
from continuum_statics.control.health import (
    ERROR,
    OK,
    STARTING,
    WARN,
    DriverHealth,
    Problems,
    StaticsHealth,
)
from continuum_statics.drivers.base import BackendStatus, ConnectionLost
from continuum_statics.drivers.sim import SimulatedCableBackend

NAMES = ('c0', 'c1', 'c2')
LIMITS = np.array([[0.25, 0.35]] * 3)
STRAIGHT = np.array([0.30, 0.30, 0.30])


def open_gate():
    gate = CommandGate(NAMES, LIMITS, STRAIGHT)
    gate.configured = gate.active = gate.connected = True
    return gate


# -- CommandGate ------------------------------------------------------------------------------
def test_a_length_just_outside_the_limits_is_clamped_and_counted():
    gate = open_gate()
    targets = gate.admit(np.array([0, 2]), [0.3505, 0.26], margin=1e-3)
    np.testing.assert_array_equal(targets, [0.35, 0.30, 0.26])
    assert gate.clamped == 1 and gate.refused == 0


def test_a_length_further_out_refuses_the_whole_command_naming_the_cable():
    gate = open_gate()
    with pytest.raises(CommandRefused, match=r'c1 0\.3600 m not in \[0\.2500, 0\.3500\]'):
        gate.admit(np.array([0, 1]), [0.30, 0.36], margin=1e-3)
    assert gate.accepted == 0
    np.testing.assert_array_equal(gate.targets, STRAIGHT)  # nothing stored


@pytest.mark.parametrize('state, reason', [
    (dict(active=False), 'inactive (lifecycle): activate it'),
    (dict(finalized=True), 'shut down (lifecycle finalized)'),
    (dict(connected=False, connection_error='port gone'), 'actuators not connected (port gone)'),
    (dict(backend_error='read failed: boom'), 'backend failed (read failed: boom)'),
    (dict(status=BackendStatus(ERROR, 'servo 3 overload')), 'actuator fault: servo 3 overload'),
])
def test_commands_are_refused_with_the_reason_while_the_driver_cannot_carry_them_out(state,
                                                                                        reason):
    gate = open_gate()
    for key, value in state.items():
        setattr(gate, key, value)
    assert reason in gate.refusal()
    with pytest.raises(CommandRefused, match='refused: '):
        gate.admit(np.array([0]), [0.30], margin=0.0)
    assert gate.refused == 1


def test_after_a_hold_unnamed_cables_stay_where_they_were_read_else_where_commanded():
    gate = open_gate()
    gate.read([0.31, 0.29, 0.305])
    targets = gate.admit(np.array([0]), [0.32], margin=0.0)  # holding since start: the reading
    np.testing.assert_array_equal(targets, [0.32, 0.29, 0.305])
    gate.taken(targets, now=1.0)
    assert not gate.holding and gate.accepted == 1
    gate.read([0.315, 0.2905, 0.3049])  # moving towards the command
    targets = gate.admit(np.array([1]), [0.28], margin=0.0)  # not holding: the last targets
    np.testing.assert_array_equal(targets, [0.32, 0.28, 0.305])
    gate.taken(targets, now=1.1)
    assert not gate.timed_out(1.2, timeout=0.5)
    assert gate.timed_out(1.7, timeout=0.5) and gate.holding  # the watchdog: once
    assert not gate.timed_out(5.0, timeout=0.5)
    gate.read([0.318, 0.282, 0.305])
    targets = gate.admit(np.array([2]), [0.31], margin=0.0)  # after the hold: the reading
    np.testing.assert_array_equal(targets, [0.318, 0.282, 0.31])


def test_the_reconnection_backoff_doubles_up_to_its_limit_and_a_reconnection_holds():
    gate = open_gate()
    assert gate.lose('bus off', now=0.0, max_interval=0.3) is None  # a new loss
    assert gate.next_attempt == pytest.approx(0.1)
    assert gate.lose('bus off', now=0.1, max_interval=0.3) == pytest.approx(0.2)
    assert gate.lose('bus off', now=0.3, max_interval=0.3) == pytest.approx(0.3)
    assert gate.next_attempt == pytest.approx(0.6)
    gate.read(STRAIGHT)
    assert gate.connect() is True  # a reconnection
    assert gate.connected and gate.holding and gate.last_reading is None
    assert gate.retry_delay == pytest.approx(0.1)
    assert gate.connect() is False  # already connected: no reconnection


def test_home_is_refused_away_from_the_straight_pose_unless_forced():
    gate = open_gate()
    assert 'no reading yet' in gate.home_refusal(1e-3)
    gate.read(STRAIGHT + [0.0, 0.004, 0.0])
    assert 'c1 reads +4.00 mm' in gate.home_refusal(1e-3)
    assert gate.home_refusal(1e-3, force=True) == ''
    assert gate.home_refusal(5e-3) == ''


# -- Actuators --------------------------------------------------------------------------------
class Log:
    def __init__(self):
        self.lines = []

    def __getattr__(self, level):
        return lambda text: self.lines.append((level, text))


class Flaky(SimulatedCableBackend):
    """The simulated actuators, with a port that can vanish."""

    name = 'flaky'
    gone = False

    def start(self, now):
        if self.gone:
            raise ConnectionLost('port gone')
        super().start(now)

    def read(self, now):
        if self.gone:
            raise ConnectionLost('port gone')
        return super().read(now)


def test_actuators_reconnect_after_a_loss_and_hold_where_the_cables_are():
    gate, clock = CommandGate(NAMES, LIMITS, STRAIGHT), SimpleNamespace(now=0.0)
    actuators = Actuators(gate, 'flaky', Log(), clock=lambda: clock.now)
    backend = Flaky(NAMES, LIMITS, STRAIGHT)
    actuators.configure(backend)
    assert gate.connected and not backend.power  # configured: connected, power off
    assert actuators.switch_power(True) and gate.active
    assert actuators.step(0.0) is not None
    actuators.command(np.array([0]), [0.31], margin=0.0)
    assert gate.accepted == 1
    Flaky.gone = True
    try:
        assert actuators.step(0.0) is None and not gate.connected
        assert 'actuators not connected (port gone)' in gate.refusal()
        with pytest.raises(CommandRefused):
            actuators.command(np.array([0]), [0.31], margin=0.0)
    finally:
        Flaky.gone = False
    clock.now = 0.05
    assert actuators.step(0.0) is None  # before the next attempt: no try
    clock.now = 0.2
    assert actuators.step(0.0) is not None and gate.connected and actuators.reconnects == 1
    assert gate.holding
    ok, message = actuators.reset()
    assert ok and gate.backend_error == ''
    actuators.release()
    assert actuators.backend is None and gate.lifecycle_state() == 'unconfigured'


# -- health -----------------------------------------------------------------------------------
def test_driver_health_levels():
    gate = open_gate()
    health = DriverHealth('sim')
    level, message, values = health.report(gate, BackendStatus())
    assert level == OK and message.startswith(STARTING)  # no reading published yet
    assert values['accepts_commands'] is True and values['refusal'] == ''
    health.rate.tick()
    gate.holding = False
    level, message, values = health.report(gate, BackendStatus(OK, 'ok'))
    assert (level, message, values['state']) == (OK, 'ok', 'ready')
    gate.connected, gate.connection_error = False, 'bus off'
    level, message, values = health.report(gate, BackendStatus(OK, 'ok'))
    assert level == ERROR and message == 'connection lost: bus off'
    assert values['accepts_commands'] is False and 'not connected' in values['refusal']
    gate.connected = True
    health.problems.add('cable_commands', 'unknown cable name')
    level, message, _ = health.report(gate, BackendStatus(OK, 'ok'))
    assert level == WARN and message == 'rejected cable_commands: unknown cable name'
    gate.active = False
    _, _, values = health.report(gate, None)
    assert values['lifecycle'] == 'inactive'
    assert DriverHealth('sim', has_cables=False).report(gate, None).message == (
        'robot has no cables: nothing to drive')


class Clock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def estimate_result(residual, rejection='', best_fit=False):
    estimate = SimpleNamespace(iterations=3, converged=True, tensions=None, slack=None)
    return SimpleNamespace(distrust='', capped=False, estimate=estimate, residual=residual,
                           converged=True, message='', tensions_used=False, rejection=rejection,
                           best_fit=best_fit)


def test_statics_health_levels():
    clock = Clock()
    health = StaticsHealth(NAMES, clock=clock)
    level, message, values = health.report(1e-4, 1e-3)
    assert level == OK and 'waiting for the first cable_states' in message
    health.received(b'x')
    health.estimated(estimate_result(2e-5), 1e-3)
    health.published(2e-3)
    level, message, values = health.report(1e-4, 1e-3)
    assert (level, message, values['state']) == (OK, 'estimating the shape', 'ready')
    assert values['residual_m'] == 2e-5 and values['published_total'] == 1
    health.estimated(estimate_result(5e-4, best_fit=True), 1e-3)
    level, message, values = health.report(1e-4, 1e-3)
    assert level == WARN and 'publishing best fits' in message and values['best_fits_total'] == 1
    health.estimated(estimate_result(5e-5), 1e-3)
    level, message, _ = health.report(1e-4, 1e-3, lost=3)
    assert level == WARN and message.startswith('3 cable_states lost since the last report')
    level, _, _ = health.report(1e-4, 1e-3, lost=3)  # none lost since
    clock.now += 2.0  # no estimate for 2 s
    level, message, _ = health.report(1e-4, 1e-3, lost=3)
    assert level == WARN and message == 'no cable_states for over 1 s'
    health.rejected('unknown cable name', outside_limits=True)
    level, message, values = health.report(1e-4, 1e-3)
    assert level == WARN and message == 'rejected cable_states: unknown cable name'
    assert values['outside_limits_total'] == 1 and values['iterations'] == 0


def test_a_matched_cable_states_publisher_never_heard_is_named():
    # a statics SIGKILLed and restarted heard no cable_states for 60 s while cable_driver
    # published them (Fast DDS shared memory, eProsima/Fast-DDS#5053); its status said "is
    # cable_driver running?", which it was
    clock = Clock()
    health = StaticsHealth(NAMES, clock=clock)
    clock.now = 6.0
    level, message, _ = health.report(1e-4, 1e-3)  # nobody publishes: the driver is not up
    assert level == OK and 'is cable_driver running?' in message
    level, message, values = health.report(1e-4, 1e-3, publishers=1)
    assert level == WARN and 'restart cable_driver' in message and values['state'] == 'starting'
    health.received(b'x')
    level, message, _ = health.report(1e-4, 1e-3, publishers=1)
    assert 'restart cable_driver' not in message


def test_a_rejection_is_logged_at_most_once_per_throttle_per_kind():
    clock, lines = Clock(), []
    problems = Problems(lines.append, throttle=2.0, clock=clock)
    problems.reject('cable_states', 'bad')
    problems.reject('cable_states', 'bad again')
    problems.reject('tip_wrench', 'other frame')
    clock.now = 2.5
    problems.reject('cable_states', 'bad later')
    assert lines == ['dropped cable_states: bad', 'dropped tip_wrench: other frame',
                     'dropped cable_states: bad later']
    assert problems.counts == {'cable_states': 3, 'tip_wrench': 1}
    assert problems.last_reason == 'cable_states: bad later'


def test_a_refused_activate_leaves_commands_refused_and_says_why():
    # review of issue 44: switch_power set gate.active before enable() raised, so after a failed
    # activate (lifecycle back to inactive) the gate accepted commands
    class Refusing(Flaky):
        def enable(self, now):
            raise RuntimeError('torque refused')

    gate = CommandGate(NAMES, LIMITS, STRAIGHT)
    actuators = Actuators(gate, 'refusing', Log())
    actuators.configure(Refusing(NAMES, LIMITS, STRAIGHT))
    assert not actuators.switch_power(True)
    assert not gate.active and actuators.failure == 'activate failed: torque refused'
    with pytest.raises(CommandRefused):
        actuators.command(np.array([0]), [0.31], margin=0.0)
