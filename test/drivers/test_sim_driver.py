"""Simulated cable backend and the backend registry: pure logic, no ROS."""
import math

from conftest import REPO
import numpy as np
import pytest
import yaml

from continuum_statics import load_robot
from continuum_statics.drivers import CableBackend, backend_class
from continuum_statics.drivers.sim import SimulatedCableBackend

NAMES = ('cable_0', 'cable_1')
LIMITS = [[0.30, 0.50], [0.30, 0.50]]
START = [0.40, 0.40]


def make(**options):
    backend = SimulatedCableBackend(NAMES, LIMITS, START, **options)
    backend.start(0.0)
    return backend


def test_starts_at_the_initial_lengths_inside_the_limits():
    backend = SimulatedCableBackend(NAMES, LIMITS, [0.40, 0.60])
    backend.start(0.0)
    reading = backend.read(1.0)
    np.testing.assert_allclose(reading.lengths, [0.40, 0.50])
    np.testing.assert_allclose(reading.velocities, 0.0)
    assert reading.tensions is None


def test_first_order_lag_decays_by_one_e_per_time_constant():
    backend = make(time_constant=0.1, max_speed=100.0)
    backend.command([0.41, 0.39], 0.0)
    lengths = backend.read(0.1).lengths
    gap = np.array([0.41, 0.39]) - lengths
    np.testing.assert_allclose(gap, [0.01 / math.e, -0.01 / math.e], rtol=1e-9)


@pytest.mark.parametrize('time_constant, max_speed', [
    (0.02, 0.05), (0.0, 0.05), (0.05, 1e9), (0.0, math.inf), (0.1, 0.01)])
def test_result_does_not_depend_on_the_call_rate(time_constant, max_speed):
    coarse, fine = make(time_constant=time_constant, max_speed=max_speed), make(
        time_constant=time_constant, max_speed=max_speed)
    for backend in (coarse, fine):
        backend.command([0.45, 0.33], 0.0)
    for t in np.linspace(0.001, 0.5, 500):
        fine.read(t)
    np.testing.assert_allclose(coarse.read(0.5).lengths, fine.read(0.5).lengths, atol=1e-12)


def test_speed_limit_caps_large_steps():
    backend = make(time_constant=0.02, max_speed=0.05)
    backend.command([0.50, 0.30], 0.0)
    reading = backend.read(0.5)
    np.testing.assert_allclose(reading.lengths, [0.40 + 0.025, 0.40 - 0.025], atol=1e-12)
    np.testing.assert_allclose(reading.velocities, [0.05, -0.05], atol=1e-9)


def test_targets_outside_the_limits_are_clamped():
    backend = make(time_constant=0.0, max_speed=math.inf)
    backend.command([0.9, 0.1], 0.0)
    np.testing.assert_allclose(backend.read(1.0).lengths, [0.50, 0.30])


def test_hold_stops_where_the_cables_are():
    backend = make(time_constant=0.02, max_speed=0.05)
    backend.command([0.50, 0.40], 0.0)
    backend.hold(0.1)
    held = backend.read(0.1).lengths
    np.testing.assert_allclose(backend.read(5.0).lengths, held)
    np.testing.assert_allclose(held[0], 0.405, atol=1e-12)


def test_noise_is_reproducible_with_a_seed_and_has_the_requested_spread():
    first, second = make(noise_std=1e-4, seed=7), make(noise_std=1e-4, seed=7)
    a = np.array([first.read(0.001 * i).lengths for i in range(1, 2001)])
    b = np.array([second.read(0.001 * i).lengths for i in range(1, 2001)])
    np.testing.assert_array_equal(a, b)
    assert 0.9e-4 < np.std(a - 0.40) < 1.1e-4
    np.testing.assert_array_equal(make().read(1.0).lengths, START)


def test_time_going_backwards_changes_nothing():
    backend = make()
    backend.command([0.45, 0.35], 0.0)
    before = backend.read(0.2).lengths
    np.testing.assert_array_equal(backend.read(0.1).lengths, before)


@pytest.mark.parametrize('options, message', [
    ({'time_constant': -1.0}, 'time_constant'),
    ({'time_constant': math.nan}, 'time_constant'),
    ({'max_speed': 0.0}, 'max_speed'),
    ({'max_speed': math.nan}, 'max_speed'),
    ({'noise_std': -1e-3}, 'noise_std'),
    ({'speed': 1.0}, 'unknown option'),
])
def test_bad_options_are_rejected_with_the_name(options, message):
    with pytest.raises(ValueError, match=message):
        SimulatedCableBackend(NAMES, LIMITS, START, **options)


def test_seed_cannot_change_while_running():
    with pytest.raises(ValueError, match='seed'):
        make().set_option('seed', 3)


def test_status_reports_tracking_error():
    backend = make()
    backend.command([0.45, 0.40], 0.0)
    status = backend.status()
    assert status.level == 0
    assert float(status.values['max_tracking_error_m']) == pytest.approx(0.05)


def test_registry_knows_sim_and_module_specs():
    assert backend_class('sim') is SimulatedCableBackend
    assert backend_class('continuum_statics.drivers.sim:SimulatedCableBackend') is \
        SimulatedCableBackend
    assert issubclass(backend_class(' sim '), CableBackend)


@pytest.mark.parametrize('spec, message', [
    ('stepper', 'unknown cable backend .*known: canopen, dynamixel, ros2_control, sim'),
    ('continuum_statics.drivers.sim:Nope', 'cannot load'),
    ('no_such_module_xyz:Backend', 'cannot load'),
    ('continuum_statics.drivers.base:BackendStatus', 'not a CableBackend'),
])
def test_registry_rejects_unknown_backends(spec, message):
    with pytest.raises(ValueError, match=message):
        backend_class(spec)


def test_a_hidden_load_beyond_the_rod_is_refused_and_the_last_one_kept():
    # issue 38: a 100 N hidden load made every reading run the slow last resort (200 -> 4 Hz)
    from conftest import REPO

    from continuum_statics import load_robot
    from continuum_statics.core.estimation.load_estimation import plausible_tip_load

    robot = load_robot(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
    backend = SimulatedCableBackend(robot.cable_names, robot.cable_length_limits,
                                    robot.straight_cable_lengths, robot=robot)
    backend.start(0.0)
    backend.set_tip_wrench([0.12, -0.08, 0.0, 0.0, 0.0, 0.0])
    assert plausible_tip_load(robot)[0] < 100.0
    with pytest.raises(ValueError, match='beyond what the rod can carry'):
        backend.set_tip_wrench([100.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(backend.tip_wrench, [0.12, -0.08, 0.0, 0.0, 0.0, 0.0])
    assert backend.read(0.1).tensions is not None


def test_real_tendons_rest_on_the_files_obstacle_and_report_that_true_tip(tmp_path):
    """The tendon statics at the motors' lengths with the file's ball: what statics must find."""
    data = yaml.safe_load((REPO / 'config' / 'tendon_robot_real_tendons.yaml').read_text())
    data['obstacles'] = [{'name': 'ball', 'sphere': {'radius': 0.02},
                          'position': [-0.03937, 0.0, 0.1994]}]
    (tmp_path / 'ball.yaml').write_text(yaml.safe_dump(data))
    robot, free_robot = load_robot(tmp_path / 'ball.yaml'), load_robot(
        REPO / 'config' / 'tendon_robot_real_tendons.yaml')
    # cable_2 (at -x) at its length under 3 N without the ball: the rod's s = 0.2 m is in it
    lengths = free_robot.cable_lengths(free_robot.solve_tensions([0.0, 0.0, 3.0, 0.0]))
    tips = {}
    for name, model in (('ball', robot), ('free', free_robot)):
        sim = SimulatedCableBackend(model.cable_names, model.cable_length_limits,
                                    model.straight_cable_lengths, robot=model,
                                    time_constant=0.0, max_speed=1.0)
        assert sim.knows_truth(model, sim.options) and sim.true_tip_pose is None  # no solve yet
        sim.start(0.0)
        sim.command(lengths, 0.0)
        tensions = sim.read(1.0).tensions
        tips[name], rotation = sim.true_tip_pose
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
        truth = model.solve_lengths(lengths)
        np.testing.assert_allclose(tips[name], truth.shape.tip_position, atol=1e-9)
        np.testing.assert_allclose(tensions, np.maximum(truth.tensions, 0.0), atol=1e-9)
    assert [c.obstacle for c in robot.solve_lengths(lengths).shape.contacts] == ['ball']
    # the ball holds the rod back towards the axis (+x) by millimetres
    assert tips['ball'][0] - tips['free'][0] > 2e-3, tips
    ideal = load_robot(REPO / 'config' / 'tendon_robot.yaml')
    assert not SimulatedCableBackend.knows_truth(ideal, {})  # ideal cables: no tendon statics
