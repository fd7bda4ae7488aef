"""The simulated driver's rod in motion without ROS (``sim.dynamics``), on a clock of its own."""
from conftest import REPO
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.drivers.sim import SimulatedCableBackend
from continuum_statics.drivers.sim_dynamics import MAX_CATCH_UP

ROBOT = load_robot(REPO / 'config' / 'tendon_robot_dynamic.yaml')


def backend(robot=ROBOT, **options):
    return SimulatedCableBackend(robot.cable_names, robot.cable_length_limits,
                                 robot.straight_cable_lengths, robot=robot, dynamics=True,
                                 **options)


def test_the_rod_follows_the_motors_and_comes_to_rest_in_their_statics():
    sim = backend()
    sim.start(0.0)
    target = ROBOT.straight_cable_lengths + np.array([-0.004, 0.0, 0.004, 0.0])
    sim.command(target, 0.0)
    tips, now = [], 0.0
    while now < 3.0:  # the clock in 5 ms readings, as the node's 200 Hz
        now += 0.005
        reading = sim.read(now)
        tips.append(sim.true_tip_pose[0])
    tips = np.array(tips)
    static = ROBOT.solve_lengths(reading.lengths, warm_start=ROBOT.solve_lengths(
        ROBOT.straight_cable_lengths))
    np.testing.assert_allclose(reading.lengths, target, atol=1e-9)  # the motors arrived
    moved = np.linalg.norm(static.shape.tip_position - tips[0])
    swing = np.max(np.linalg.norm(tips - tips[0], axis=1)) - moved
    print('moved %.2f mm, past the end by %.2f mm, at rest %.2g m from the statics'
          % (1e3 * moved, 1e3 * swing, np.linalg.norm(tips[-1] - static.shape.tip_position)))
    assert moved > 0.01
    assert np.linalg.norm(tips[-1] - static.shape.tip_position) < 1e-5
    np.testing.assert_allclose(reading.tensions, static.tensions, atol=1e-3)
    assert sim.status().values['failed_steps'] == '0'


def test_a_tip_mass_weighs_and_the_hidden_load_pushes():
    plain, loaded = backend(), backend(tip_mass=0.02)
    pushed = backend()
    pushed.set_tip_wrench([0.1, 0.0, 0.0, 0.0, 0.0, 0.0])
    for sim in (plain, loaded, pushed):
        sim.start(0.0)
        for now in np.arange(1, 401) * 0.005:
            sim.read(now)
    drop = plain.true_tip_pose[0][2] - loaded.true_tip_pose[0][2]
    static = ROBOT.solve_lengths(ROBOT.straight_cable_lengths, [0.1, 0.0, 0.0])
    assert drop > 0.0  # 20 g on an upright rod: it sinks (and buckles a little)
    np.testing.assert_allclose(pushed.true_tip_pose[0], static.shape.tip_position, atol=1e-4)


def test_slower_than_the_clock_drops_the_backlog_and_says_so():
    sim = backend()
    sim.start(0.0)
    sim.read(0.001)
    sim.read(10.0)  # the clock jumped 10 s: no 10,000-step catch-up in one reading
    status = sim.status()
    assert float(status.values['dropped_time_s']) == pytest.approx(10.0 - 0.001 - MAX_CATCH_UP,
                                                                   abs=2e-3)
    assert status.level == 1 and 'slower than real time' in status.message
    sim.read(10.005)
    assert sim.status().level == 0  # keeping up again: no warning for what is past


def test_ideal_cables_are_refused_by_name():
    with pytest.raises(ValueError, match='real tendons'):
        backend(load_robot(REPO / 'config' / 'tendon_robot.yaml'))


def test_a_payload_beyond_the_rod_is_refused_as_a_hidden_wrench_is():
    """The same bound, 10 E I / L^2 = 5.06 N here: 1 kg (9.81 N) is refused by name."""
    # before: sim.tip_mass 1.0 was accepted; the rod collapsed with status OK
    with pytest.raises(ValueError, match='tip_mass: payload 1 kg .* beyond what the rod can '
                       'carry'):
        backend(tip_mass=1.0)
    sim = backend(tip_mass=0.4)  # 3.92 N: within the bound
    # before: only the wrench was checked, so 2 N more downwards was accepted (5.9 N in all)
    with pytest.raises(ValueError, match='payload 0.4 kg .* with the hidden tip load'):
        sim.set_tip_wrench([0.0, 0.0, -2.0, 0.0, 0.0, 0.0])
    sim.set_tip_wrench([0.0, 0.0, 0.5, 0.0, 0.0, 0.0])  # within: taken


def test_the_driver_warns_when_the_true_tip_leaves_the_models():
    """A 0.2 kg payload buckles the bent rod away from the statics of the motors' lengths."""
    target = ROBOT.straight_cable_lengths + np.array([-0.004, 0.0, 0.004, 0.0])
    reports = {}
    for mass in (0.0, 0.2):
        sim = backend(tip_mass=mass)
        sim.start(0.0)
        sim.command(target, 0.0)
        now = 0.0
        for _ in range(4):  # a report every 0.5 s, as /diagnostics at 2 Hz
            while now < 0.5 * (len(reports.get(mass, [])) + 1):
                now += 0.005
                sim.read(now)
            status = sim.status()
            reports.setdefault(mass, []).append(
                (status.level, float(status.values['true_tip_from_model_m']), status.message))
    print(reports)
    # the rod without payload follows its model (the 4 mm step's swing filtered out)
    assert all(level == 0 and gap < 2e-3 for level, gap, _ in reports[0.0])
    # before: the 0.2 kg rod reported OK throughout, its true tip 30-70 mm from the model's
    level, gap, message = reports[0.2][-1]
    assert level == 1 and gap > 0.005 and "from the model's" in message
