"""State estimation (issue 35): sensors fused into the shape, with an honest covariance.

Truths: the model's own estimate (no readings: the fused estimate is it), simulated truth
with loads the estimator does not know and sensors with noise (errors along the rod, the
normalised estimation error squared of the 95 % ellipsoid over 500 seeded cases), truth with
physics the robot file leaves out (guide-disk masses), the Ornstein-Uhlenbeck decay in closed
form, a recorded real run (ftdcr_v6, calibrated on train.csv, replayed on held-out val.csv),
and synthetic runs with a known hidden offset process and a known smooth drift that
``calibrate --model-uncertainty`` must recover; the drift's transition against its SDE.
"""
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from recorded_v6 import V6_COLUMNS
import yaml

from continuum_statics import load_robot
from continuum_statics.calibration import model_uncertainty
from continuum_statics.calibration.occlusion import occlusion_replay
from continuum_statics.calibration.recorded_run import RecordedRun
from continuum_statics.calibration.runs import read_run
from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.description.sensors import (
    ModelUncertainty,
    SensorReading,
    default_model_uncertainty,
)
from continuum_statics.core.estimation.state_estimation import _evolved, point_covariance
from continuum_statics.core.robot import Robot
from continuum_statics.tools.fusion import mismatched_truth, simulated_truth, smooth_path

REPO = Path(__file__).resolve().parents[2]
SENSOR_ROBOT = REPO / 'config' / 'tendon_robot_sensors.yaml'
PAYLOAD_ROBOT = REPO / 'config' / 'tendon_robot_payload.yaml'
V6_FUSED = REPO / 'config' / 'ftdcr_v6_fused.yaml'
V6_VAL = REPO / 'test' / 'data' / 'ftdcr_v6' / 'val.csv'


def _document(path=SENSOR_ROBOT):
    with open(path, encoding='utf-8') as stream:
        return yaml.safe_load(stream)


def _pulled(robot, pull=0.004):
    lengths = np.array(robot.straight_cable_lengths)
    lengths[0] -= pull
    return lengths


@pytest.mark.parametrize('name', ['tendon_robot.yaml', 'tendon_robot_real_tendons.yaml',
                                  'three_section_robot_real_tendons.yaml'])
def test_without_readings_the_estimate_is_the_models(name):
    """No reading yet: the fused shape is the model's estimate (1e-9 m), with a covariance."""
    plain = load_robot(REPO / 'config' / name)
    fused = plain.with_model_uncertainty(ModelUncertainty(0.05, 0.005, 3e-4, 5e-4, 10.0))
    lengths = _pulled(plain)
    a, b = plain.estimate_shape(lengths), fused.estimate_shape(lengths)
    assert a.position_covariance is None
    assert np.max(np.abs(a.shape.positions - b.shape.positions)) < 1e-9
    if not plain.tendons.is_ideal:
        exact = plain.solve_lengths(lengths).shape
        assert np.max(np.abs(exact.positions - b.shape.positions)) < 1e-6
    covariance = b.position_covariance
    assert covariance.shape == (len(b.shape.s), 3, 3)
    assert np.all(np.linalg.eigvalsh(covariance[1:]) >= -1e-15)
    # the base is clamped: only the base offset's variance there
    assert np.allclose(covariance[0], 5e-4 ** 2 * np.eye(3), rtol=1e-6)


@pytest.mark.parametrize('change, field', [
    ({'sensors': [{'name': 'x', 'at': {'disk': 99}}]}, 'sensors[0].at'),
    ({'sensors': [{'name': 'x', 'at': 0.9}]}, 'sensors[0].at'),
    ({'sensors': [{'name': 'x', 'kind': 'velocity'}]}, 'sensors[0].kind'),
    ({'sensors': [{'name': 'x'}, {'name': 'x'}]}, 'used twice'),
    ({'sensors': [{'name': 'x', 'noise': {'position': -1}}]}, 'sensors[0].noise.position'),
    ({'sensors': [{'name': 'x', 'colour': 'red'}]}, 'unknown keys'),
    ({'sensors': [{'name': 'x', 'covariance': 'yes'}]}, 'sensors[0].covariance'),
    ({'model_uncertainty': {'tip_force': 'big'}}, 'model_uncertainty.tip_force'),
    ({'model_uncertainty': {'correlation_time': 0.0}}, 'model_uncertainty.correlation_time'),
    ({'model_uncertainty': {'wind': 1.0}}, 'unknown keys'),
])
def test_robot_file_mistakes_are_named(change, field):
    document = _document()
    document.update(change)
    with pytest.raises(ValueError, match=field.replace('[', r'\[').replace(']', r'\]')):
        parse_robot_description(document)


def test_an_unknown_sensor_or_a_bad_reading_is_named():
    robot = load_robot(SENSOR_ROBOT)
    lengths = _pulled(robot)
    with pytest.raises(ValueError, match="'camera' is not in the robot file"):
        robot.estimate_shape(lengths, sensors={'camera': np.zeros(3)})
    with pytest.raises(ValueError, match='tip_tracker: position must be 3 finite'):
        robot.estimate_shape(lengths, sensors={'tip_tracker': [0.0, np.nan, 0.3]})


def test_a_nan_stamp_is_refused_and_the_next_call_from_the_last_good_estimate_is_finite():
    # issue 43 item 7, before: estimate_shape(..., stamp=nan) returned a NaN shape and every
    # later warm-started call stayed NaN
    robot = load_robot(SENSOR_ROBOT)
    lengths = _pulled(robot)
    good = robot.estimate_shape(lengths, stamp=10.0)
    tip = good.shape.tip_position + good.shape.tip_rotation @ robot.sensors[0].offset
    with pytest.raises(ValueError, match='stamp must be a finite time'):
        robot.estimate_shape(lengths, warm_start=good, stamp=math.nan)
    with pytest.raises(ValueError, match="sensor 'tip_tracker': reading stamp must be a finite"):
        robot.estimate_shape(lengths, warm_start=good, stamp=10.5, sensors={
            'tip_tracker': SensorReading(tip, stamp=math.inf)})
    later = robot.estimate_shape(lengths, warm_start=good, stamp=11.0, sensors={
        'tip_tracker': SensorReading(tip, stamp=10.9)})
    assert np.all(np.isfinite(later.shape.positions)) and np.all(np.isfinite(
        later.tip_covariance))


@pytest.mark.parametrize('drift', [0.0, 3e-3], ids=['loads', 'loads and a drift'])
def test_simulated_truth_each_sensor_helps_and_the_ellipsoid_is_honest(drift):
    """500 seeded cases: hidden loads from the prior, sensors with their noise (NEES).

    With a drift in the prior the truth is shifted by it too (before: not, and the model
    alone's ellipsoid held 99.8 %).
    """
    robot = load_robot(SENSOR_ROBOT)
    robot = robot.with_model_uncertainty(dataclasses.replace(
        robot.model_uncertainty, drift=drift, drift_time=2.0))
    rows = simulated_truth(robot, 500, seed=35)
    alone, tip, both = (row['rms'] for row in rows)
    # the tip tracker pins the tip; the EM coil the middle of the rod
    assert tip[-1] < 0.25 * alone[-1]
    assert both[1] < 0.85 * tip[1] and both[1] < 0.5 * alone[1]
    assert np.all(both <= tip * 1.05)
    for row in rows:
        assert 0.90 <= row['coverage'] <= 0.98, row


def test_simulated_truth_draws_the_white_error_the_file_states():
    """The truth has the file's ``point_noise`` too: every row's ellipsoid holds 85-99 %.

    Without it drawn (before) the model alone's held 98.7 %: the covariance had an error the
    truth did not. The tracked rows held 100 % while the published covariance added the whole
    white variance at the tip after a reading that had seen it (:func:`_tip_white`).
    """
    robot = load_robot(SENSOR_ROBOT)
    robot = robot.with_model_uncertainty(dataclasses.replace(robot.model_uncertainty,
                                                             point_noise=1e-3))
    rows = simulated_truth(robot, 300, seed=36)
    assert 0.90 <= rows[0]['coverage'] <= 0.98, rows[0]
    for row in rows[1:]:
        assert 0.85 <= row['coverage'] <= 0.99, row


def test_truth_with_disk_masses_the_file_leaves_out():
    """Physics the estimator does not have: 10 g per guide disk under gravity, bent robots."""
    document = _document()
    robot = load_robot(SENSOR_ROBOT)
    heavy = dict(document, guides=None)
    heavy.pop('guides')
    heavy['sections'] = [{'name': 'all', 'guides': document['guides'],
                          'cables': document['cables'], 'disk_mass': 0.01}]
    heavy.pop('cables')
    heavy.pop('sensors')
    heavy.pop('model_uncertainty')
    truth_robot = Robot(parse_robot_description(heavy))
    rng = np.random.default_rng(1)
    alone, fused = [], []
    tracker = robot.sensors[0]
    for _ in range(20):
        lengths = robot.straight_cable_lengths - rng.uniform(0.0, 0.012, 4)
        truth = truth_robot.solve_lengths(lengths).shape
        marker = truth.tip_position + truth.tip_rotation @ tracker.offset
        reading = SensorReading(marker + rng.normal(0.0, tracker.position_sigma, 3))
        model = robot.estimate_shape(lengths, exact=True)
        estimate = robot.estimate_shape(lengths, exact=True, sensors={'tip_tracker': reading})
        assert estimate.sensors['tip_tracker'].used
        alone.append(model.shape.positions - truth.positions)
        fused.append(estimate.shape.positions - truth.positions)
    rms = [np.sqrt(np.mean(np.sum(np.array(e) ** 2, axis=2), axis=0)) for e in (alone, fused)]
    print('disk masses: model alone %s mm, with the tip tracker %s mm (base to tip)'
          % (np.round(1e3 * rms[0][::6], 2), np.round(1e3 * rms[1][::6], 2)))
    assert rms[0][-1] > 2e-3  # the masses matter
    assert rms[1][-1] < 0.4 * rms[0][-1]
    middle = len(rms[0]) // 2
    assert rms[1][middle] < 0.7 * rms[0][middle]


def test_a_biased_reading_is_set_aside_and_changes_nothing():
    robot = load_robot(SENSOR_ROBOT)
    lengths = _pulled(robot)
    model = robot.estimate_shape(lengths, exact=True)
    tip = model.shape.tip_position + model.shape.tip_rotation @ robot.sensors[0].offset
    biased = robot.estimate_shape(lengths, exact=True, sensors={
        'tip_tracker': SensorReading(tip + np.array([0.03, 0.0, 0.0]))})
    verdict = biased.sensors['tip_tracker']
    assert not verdict.used and verdict.chi2 > 30.0
    assert 'gate' in verdict.reason and '30.0 mm' in verdict.reason
    assert np.array_equal(biased.shape.positions, model.shape.positions)
    good = robot.estimate_shape(lengths, exact=True, sensors={
        'tip_tracker': SensorReading(tip + np.array([0.002, 0.0, 0.0]))})
    assert good.sensors['tip_tracker'].used
    assert good.shape.tip_position[0] - model.shape.tip_position[0] > 1e-3


def test_a_reading_that_reports_its_own_noise_is_weighed_by_it():
    robot = load_robot(SENSOR_ROBOT)
    lengths = _pulled(robot)
    model = robot.estimate_shape(lengths, exact=True)
    tip = model.shape.tip_position + model.shape.tip_rotation @ robot.sensors[0].offset

    def shift(offset, **sigma):
        estimate = robot.estimate_shape(lengths, exact=True, sensors={
            'tip_tracker': SensorReading(tip + np.array([offset, 0.0, 0.0]), **sigma)})
        verdict = estimate.sensors['tip_tracker']
        return estimate.shape.tip_position[0] - model.shape.tip_position[0], verdict.used

    configured = shift(0.002)
    assert shift(0.002, sigma=None) == configured  # no figure of its own: the file's noise
    assert shift(0.002, sigma=robot.sensors[0].position_sigma) == configured
    # a noisier device pulls less, a more precise one more
    assert 0.0 < shift(0.002, sigma=0.005)[0] < configured[0] < shift(0.002, sigma=1e-4)[0]
    # 30 mm off is beyond the gate at the file's 0.5 mm, and a plausible reading at its own 30 mm
    assert not shift(0.03)[1] and shift(0.03, sigma=0.03)[1]
    with pytest.raises(ValueError, match='sigma must be a finite standard deviation'):
        shift(0.002, sigma=0.0)


def test_a_file_whose_model_uncertainty_is_all_zero_names_each_reading_it_cannot_use():
    """Nothing to correct: each reading gets its verdict by the sensor's name (was a KeyError)."""
    with open(SENSOR_ROBOT, encoding='utf-8') as stream:
        document = yaml.safe_load(stream)
    document['model_uncertainty'] = {key: 0.0 for key in (
        'tip_force', 'section_moment', 'cable_length', 'base_position')}
    robot = Robot(parse_robot_description(document, SENSOR_ROBOT))
    lengths = _pulled(robot)
    estimate = robot.estimate_shape(lengths, exact=True, sensors={
        'tip_tracker': SensorReading(robot.estimate_shape(lengths).shape.tip_position)})
    verdict = estimate.sensors['tip_tracker']
    assert not verdict.used and 'no model_uncertainty to correct' in verdict.reason


def test_a_correction_fades_with_the_correlation_time():
    """Ornstein-Uhlenbeck: the mean decays as exp(-t / tau), the variance grows back to P0."""
    robot = load_robot(SENSOR_ROBOT)
    tau = robot.model_uncertainty.correlation_time
    lengths = _pulled(robot)
    model = robot.estimate_shape(lengths, exact=True)
    tip = model.shape.tip_position + model.shape.tip_rotation @ robot.sensors[0].offset
    seen = robot.estimate_shape(lengths, exact=True, stamp=100.0, sensors={
        'tip_tracker': SensorReading(tip + np.array([0.002, -0.001, 0.0]))})
    later = robot.estimate_shape(lengths, warm_start=seen, exact=True, stamp=100.0 + tau)
    np.testing.assert_allclose(later.unmodelled.mean, seen.unmodelled.mean * math.exp(-1.0),
                               atol=1e-15)
    variance = [np.trace(e.tip_covariance[:3, :3]) for e in (seen, later, model)]
    assert variance[0] < 0.1 * variance[2]
    assert variance[0] < variance[1] < variance[2]
    much_later = robot.estimate_shape(lengths, warm_start=later, exact=True,
                                      stamp=100.0 + 20 * tau)
    np.testing.assert_allclose(much_later.shape.positions, model.shape.positions, atol=1e-9)
    np.testing.assert_allclose(np.trace(much_later.tip_covariance[:3, :3]), variance[2],
                               rtol=1e-6)


def test_a_copied_estimate_computes_its_covariances_again():
    """``_evolved`` copies fields only: a covariance cached on the original is not carried."""
    robot = load_robot(SENSOR_ROBOT)
    lengths = _pulled(robot)
    model = robot.estimate_shape(lengths, exact=True, stamp=0.0)
    tip = model.shape.tip_position + model.shape.tip_rotation @ robot.sensors[0].offset
    seen = robot.estimate_shape(lengths, exact=True, stamp=0.0, sensors={
        'tip_tracker': SensorReading(tip + np.array([0.002, -0.001, 0.0]))})
    for estimate in (seen, model):
        assert estimate.tip_covariance is not None  # cached on both
    for cached in (True, False):
        original = seen if cached else dataclasses.replace(seen)  # the latter caches nothing
        copy = _evolved(original, unmodelled=model.unmodelled)
        expected = dataclasses.replace(seen, unmodelled=model.unmodelled)
        np.testing.assert_allclose(copy.tip_covariance, expected.tip_covariance, rtol=1e-12)
        np.testing.assert_allclose(copy.position_covariance, expected.position_covariance,
                                   rtol=1e-12)
        assert copy.unmodelled is model.unmodelled and copy.shape is seen.shape
    with pytest.raises(TypeError, match='no field'):
        _evolved(seen, unknown=1)


def test_v6_held_out_rows_with_the_tracker_occluded():
    """The real robot: calibrated on train.csv (with model_uncertainty), replayed on val.csv.

    Before the drift (a smooth offset) was in the model: blocks of 5 held 73.3 % in their 95 %
    ellipsoids, every other row 3.23 mm against the last-residual baseline's 3.02.
    """
    robot = load_robot(V6_FUSED)
    run = read_run(V6_VAL, robot, V6_COLUMNS)
    every_other = occlusion_replay(robot, run, 1, 1)
    blocks = occlusion_replay(robot, run, 5, 5)
    assert every_other.fused < 0.35 * every_other.model
    assert blocks.fused < 0.6 * blocks.model
    assert every_other.fused < 1.01 * every_other.baseline
    assert blocks.fused < 0.9 * blocks.baseline
    for replayed in (every_other, blocks):
        assert 0.85 <= replayed.coverage <= 0.99, replayed


def test_the_drift_moves_as_its_stochastic_differential_equation():
    """The Matern 3/2 drift's transition against the SDE solved another way.

    Truths: the mean and covariance from the SDE dx = F x dt + L dW by the matrix exponential
    and Van Loan's integral (C. F. Van Loan, IEEE TAC 1978), and the offset's autocovariance
    sigma^2 (1 + lambda t) exp(-lambda t) (Rasmussen & Williams 2006, eq. 4.17).
    """
    from scipy.linalg import expm

    from continuum_statics.core.estimation.state_estimation import decayed

    sigma, length, tau, dt = 2e-3, 3.0, 40.0, 0.7
    lam = math.sqrt(3.0) / length
    # one OU entry, then the drift's offsets (x, y, z) and their rates
    stationary = np.diag([0.01 ** 2] + [sigma ** 2] * 3 + [(lam * sigma) ** 2] * 3)
    drift = np.array([[0.0, 1.0], [-lam ** 2, -2.0 * lam]])
    spectral = 4.0 * lam ** 3 * sigma ** 2  # white-noise density that makes it stationary
    f, diffusion = np.zeros((7, 7)), np.zeros((7, 7))
    f[0, 0], diffusion[0, 0] = -1.0 / tau, 2.0 * 0.01 ** 2 / tau
    for axis in range(3):
        pair = np.ix_([1 + axis, 4 + axis], [1 + axis, 4 + axis])
        f[pair] = drift
        diffusion[1 + axis + 3, 1 + axis + 3] = spectral
    van_loan = expm(np.block([[-f, diffusion], [np.zeros((7, 7)), f.T]]) * dt)
    transition = van_loan[7:, 7:].T
    added = transition @ van_loan[:7, 7:]
    mean = np.array([0.02, 1e-3, -2e-3, 0.5e-3, 1e-4, 3e-4, -2e-4])
    moved, spread = decayed(mean, np.zeros((7, 7)), stationary, dt, tau, length)
    np.testing.assert_allclose(moved, transition @ mean, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(spread, added, rtol=1e-9, atol=1e-16)
    # stationary stays stationary; the offset's lag covariance is the Matern kernel
    np.testing.assert_allclose(decayed(np.zeros(7), stationary, stationary, dt, tau,
                                       length)[1], stationary, atol=1e-18)
    lagged = transition @ stationary
    assert lagged[1, 1] == pytest.approx(sigma ** 2 * (1 + lam * dt) * math.exp(-lam * dt),
                                         rel=1e-12)


def test_the_last_residual_baseline_is_the_model_with_an_offset_alone():
    """Issue 43 item 3: the last-residual baseline is a special case of the estimator.

    The baseline (model + last tracker residual, decayed over 10 s) is an offset of the whole
    backbone far wider than the tracker's noise, nothing else, correlation time 10 s: the
    model uncertainty's fit can always fall back to it.
    """
    from continuum_statics.calibration.occlusion import BASELINE_DECAY

    robot = load_robot(V6_FUSED).with_model_uncertainty(
        ModelUncertainty(base_position=0.1, correlation_time=BASELINE_DECAY))
    run = read_run(V6_VAL, robot, V6_COLUMNS)
    run = run.subset(np.arange(60))
    for seen, hidden in ((1, 1), (5, 5)):
        replayed = occlusion_replay(robot, run, seen, hidden)
        assert replayed.baseline < 0.9 * replayed.model  # the offset is not zero here
        assert abs(replayed.fused - replayed.baseline) < 2e-3 * replayed.baseline, replayed


def test_the_documented_call_on_a_recorded_run_is_the_exact_estimate():
    """Issue 43 item 2: warm-started plain calls on rows 0.59 s apart, the tracker every other row.

    before: from row 9 on each call was left unfinished and the next went on from it: the fused
    tip ran 5 -> 139 mm from the truth (16.6 mm RMS on the occluded rows against exact's 3.2).
    """
    from continuum_statics.calibration.occlusion import seen_mask, tip_sensor

    robot = load_robot(V6_FUSED)
    run = read_run(V6_VAL, robot, V6_COLUMNS)
    sensor = tip_sensor(robot)
    seen = seen_mask(len(run), 1, 1)
    plain = exact = None
    for i, lengths in enumerate(run.lengths[:60]):
        stamp = float(run.times[i])
        readings = {sensor.name: SensorReading(run.tips[i], stamp=stamp)} if seen[i] else None
        plain = robot.estimate_shape(lengths, warm_start=plain, sensors=readings, stamp=stamp)
        exact = robot.estimate_shape(lengths, warm_start=exact, exact=True, sensors=readings,
                                     stamp=stamp)
        assert not plain.capped
        # the solver's tolerance (measured: at most 1.4e-8 m over 120 rows)
        np.testing.assert_allclose(plain.shape.positions, exact.shape.positions, atol=1e-7)
        assert {k: v.used for k, v in plain.sensors.items()} == {
            k: v.used for k, v in exact.sensors.items()}


def _drifting_tracker(robot, rate, noise, seconds=40.0, hz=20.0, drift_until=30.0, seed=3):
    """Return (worst fused tip error, m; first set-aside time and reason; s back after)."""
    rng = np.random.default_rng(seed)
    lengths = _pulled(robot)
    sensor = robot.sensors[0]
    model = robot.estimate_shape(lengths, exact=True).shape
    truth = model.tip_position + model.tip_rotation @ sensor.offset
    estimate, worst, aside, back = None, 0.0, None, None
    for k in range(int(seconds * hz)):
        t = k / hz
        drift = np.array([rate * min(t, drift_until), 0.0, 0.0]) if t < drift_until else 0.0
        reading = SensorReading(truth + drift + rng.normal(0.0, noise, 3), stamp=t)
        estimate = robot.estimate_shape(lengths, warm_start=estimate, stamp=t,
                                        sensors={sensor.name: reading})
        shape = estimate.shape
        worst = max(worst, float(np.linalg.norm(
            shape.tip_position + shape.tip_rotation @ sensor.offset - truth)))
        verdict = estimate.sensors[sensor.name]
        if not verdict.used and aside is None and 'drifting' in verdict.reason:
            aside = (t, verdict.reason)
        if t >= drift_until and verdict.used and back is None:
            back = t - drift_until
    return worst, aside, back


@pytest.mark.parametrize('robot_file', [SENSOR_ROBOT, PAYLOAD_ROBOT], ids=lambda p: p.stem)
@pytest.mark.parametrize('rate', [5e-4, 1e-3, 5e-3], ids=['0.5 mm/s', '1 mm/s', '5 mm/s'])
def test_a_drifting_tracker_is_set_aside_before_it_walks_the_estimate_away(rate, robot_file):
    # issue 43 item 6, before: each reading passed the gate against an estimate the tracker had
    # already moved; 1 / 5 mm/s for 45 s walked the fused tip 45 / 224 mm, nothing named.
    # With a load model the load took the drift the guard did not judge: 0.5 mm/s walked the
    # fused tip 15.1 mm in 30 s, never named; 1 / 5 mm/s 17.4 / 16.2 mm before named
    robot = load_robot(robot_file)
    worst, aside, back = _drifting_tracker(robot, rate, 5e-4)
    assert aside is not None, 'never set aside'
    bound = float(aside[1].split('(')[1].split(' mm')[0]) * 1e-3  # 3 sigma there: 13.0 mm
    assert bound < 0.015
    assert worst <= bound + 2e-3, (worst, aside)  # + the reading noise's share
    assert back is not None and back <= 1.0  # the honest tracker is taken back


@pytest.mark.parametrize('robot_file', [SENSOR_ROBOT, PAYLOAD_ROBOT], ids=lambda p: p.stem)
def test_an_honest_noisy_tracker_is_never_set_aside_as_drifting(robot_file):
    robot = load_robot(robot_file)
    worst, aside, _ = _drifting_tracker(robot, 0.0, 5e-4, seconds=60.0)
    assert aside is None, aside
    assert worst < 2e-3


def _late_tracker(robot, rate, latency, seconds=2.5, seed=1):
    """Fused marker errors (m) of a 1 kHz estimate fed a tracker whose readings arrive late.

    Truth: the model's own equilibrium of cable lengths swept (tip up to ~90 mm/s) plus a
    hidden 2.2 mm offset the tracker is there to correct. The tracker samples the truth at
    ``rate`` and each reading arrives ``latency(rng)`` s later (out of order when that jitters
    more than the period). Returns (errors after the first second, readings given, used, how
    far the truth moves in a latency at most).
    """
    tracker = robot.sensors[0]
    rng = np.random.default_rng(seed)
    offset = np.array([0.002, -0.001, 0.0])

    def lengths_at(t):
        lengths = np.array(robot.straight_cable_lengths)
        lengths[0] -= 0.004 * (1.0 - math.cos(math.pi * t))
        lengths[1] -= 0.002 * (1.0 - math.cos(0.5 * math.pi * t))
        return lengths

    times = np.arange(0.0, seconds, 1e-3)
    truth, previous = [], None
    for t in times:
        previous = robot.solve_lengths(lengths_at(t), warm_start=previous)
        shape = previous.shape
        truth.append(shape.tip_position + shape.tip_rotation @ tracker.offset + offset)
    truth = np.array(truth)
    taken = np.arange(0.0, seconds, 1.0 / rate)
    arrivals = sorted((t + latency(rng), t, truth[int(round(t * 1e3))] + rng.normal(0, 3e-4, 3))
                      for t in taken)
    errors, given, used, at, last = [], 0, 0, 0, None
    for i, t in enumerate(times):
        sensors = None
        while at < len(arrivals) and arrivals[at][0] <= t:
            _, stamp, position = arrivals[at]
            sensors = {tracker.name: SensorReading(position, stamp=stamp)}
            at += 1
        last = robot.estimate_shape(lengths_at(t), warm_start=last, stamp=float(t),
                                    sensors=sensors)
        if sensors:
            given += 1
            used += last.sensors[tracker.name].used
        if t >= 1.0:
            shape = last.shape
            errors.append(shape.tip_position + shape.tip_rotation @ tracker.offset - truth[i])
    lag = max(np.linalg.norm(truth[i] - truth[i - 45]) for i in range(45, len(truth)))
    return np.linalg.norm(errors, axis=1), given, used, lag


@pytest.mark.parametrize('rate, latency', [
    (40.0, lambda rng: 0.030),                        # an EM tracker: 40 Hz, 30 ms late
    (120.0, lambda rng: rng.uniform(0.005, 0.045)),   # optical, jittered: out of order
], ids=['em-40Hz-30ms', 'optical-120Hz-5-45ms'])
def test_late_and_out_of_order_readings_are_fused_at_their_own_stamp(rate, latency):
    """Issue 43 item 6: a reading is compared with the model of its stamp, not of its arrival.

    Before: each reading was compared with the newest model; with the EM tracker the fused
    marker was 1.90 mm RMS (2.92 mm max) from the truth instead of 0.25 mm.
    """
    robot = load_robot(SENSOR_ROBOT)
    errors, given, used, lag = _late_tracker(robot, rate, latency)
    assert lag > 0.003  # the truth moves 4 mm in 45 ms: arrival time would not do
    assert used == given > 0.9 * rate * 2.5 - 5  # every reading used, none lost
    assert math.sqrt(np.mean(errors ** 2)) < 0.5e-3, np.sqrt(np.mean(errors ** 2))
    assert errors.max() < 1.0e-3


def _synthetic_run(robot, rng, times, hidden, noise):
    """Return a run: random pulls, the tracker at the model's marker + ``hidden`` + noise."""
    rows = len(times)
    lengths = robot.straight_cable_lengths - rng.uniform(0.0, 0.006, (rows, 4))
    tips, previous = np.empty((rows, 3)), None
    for i in range(rows):
        previous = robot.solve_lengths(lengths[i], warm_start=previous)
        shape = previous.shape
        tips[i] = (shape.tip_position + shape.tip_rotation @ robot.tip_marker + hidden[i]
                   + rng.normal(0.0, noise, 3))
    return RecordedRun(times=times, labels=('',) * rows, lengths=lengths, tips=tips,
                       source='synthetic')


def _ou_offset(rng, times, sigma, tau):
    """Return (n, 3) m: an Ornstein-Uhlenbeck offset (sigma m, tau s) drawn at ``times``."""
    offset = np.empty((len(times), 3))
    offset[0] = rng.normal(0.0, sigma, 3)
    for i in range(1, len(times)):
        a = math.exp(-(times[i] - times[i - 1]) / tau)
        offset[i] = a * offset[i - 1] + math.sqrt(1 - a * a) * rng.normal(0.0, sigma, 3)
    return offset


def _two_sensor_run(robot, rng, rows, sigma, tau, coil_every):
    """Return a run of random pulls seen by the tip tracker and the EM coil.

    Both at the model's points plus one offset (:func:`_ou_offset`) and their files' noise,
    the coil every ``coil_every`` rows.
    """
    tracker, coil = robot.sensors
    times = np.cumsum(rng.uniform(0.3, 0.7, rows))
    offset = _ou_offset(rng, times, sigma, tau)
    lengths = robot.straight_cable_lengths - rng.uniform(0.0, 0.006, (rows, 4))
    tips, coils, previous = np.empty((rows, 3)), np.full((rows, 3), np.nan), None
    for i in range(rows):
        previous = robot.solve_lengths(lengths[i], warm_start=previous)
        shape = previous.shape
        tips[i] = (shape.tip_position + shape.tip_rotation @ tracker.offset + offset[i]
                   + rng.normal(0.0, tracker.position_sigma, 3))
        if i % coil_every == 0:  # the coil's point by interpolation along the rod (offset 0)
            coils[i] = ([np.interp(coil.s, shape.s, shape.positions[:, k]) for k in range(3)]
                        + offset[i] + rng.normal(0.0, coil.position_sigma, 3))
    return RecordedRun(times=times, labels=('',) * rows, lengths=lengths, tips=tips,
                       source='synthetic', points={coil.name: coils})


def test_calibrate_recovers_a_known_hidden_offset():
    """A synthetic run: the tracker sees the model plus an offset process of known sigma, tau."""
    robot = load_robot(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
    rng = np.random.default_rng(7)
    sigma, tau, noise, rows = 2e-3, 8.0, 3e-4, 400
    times = np.cumsum(rng.uniform(0.3, 0.7, rows))
    run = _synthetic_run(robot, rng, times, _ou_offset(rng, times, sigma, tau), noise)
    measured, report = model_uncertainty.measure(robot, run, tracker_noise=noise)
    assert 0.7 * sigma < measured.base_position < 1.4 * sigma, report
    assert 0.5 * tau < measured.correlation_time < 2.0 * tau, report
    # what the run does not show stays small: the loads explain nothing here, and the white
    # error is within the tracker's noise (seen: 0.24 mm, the OU's row-to-row step that a
    # fitted tau of 14 s leaves to it)
    assert measured.tip_force < 0.3 * robot.c[0] / robot.length ** 2 * 0.1
    assert measured.point_noise < noise, report
    assert dataclasses.asdict(measured).keys() >= {'tip_force', 'cable_length'}


def test_calibrate_from_two_sensors_recovers_a_known_hidden_offset_seen_by_both():
    """A tip tracker and an EM coil both see the model plus one offset of known sigma and tau.

    The coil at s = 0.15 m with 0.7 mm of noise, a reading every third row.

    Both sensors' rows go into the likelihood, each at its own point with its own noise: the
    coil's residual taken at the tip's point carries the body's bend (seen: sigma 13.6 mm).
    """
    robot = load_robot(SENSOR_ROBOT)
    tracker, coil = robot.sensors
    rng = np.random.default_rng(11)
    sigma, tau, rows = 2e-3, 8.0, 300
    run = _two_sensor_run(robot, rng, rows, sigma, tau, coil_every=3)
    measured, report = model_uncertainty.measure(robot, run)
    assert report['sensors'] == [coil.name] and report['tracker_noise'] == 5e-4
    assert 0.7 * sigma < measured.base_position < 1.4 * sigma, report
    assert 0.5 * tau < measured.correlation_time < 2.0 * tau, report
    assert measured.point_noise < tracker.position_sigma, report


def test_the_occlusion_replay_reads_the_runs_other_sensors_with_the_tracker():
    """A run whose tracker and EM coil both see the model plus one offset (2 mm, 8 s).

    The coil is read on the rows the tracker sees and occluded with it. Its benefit hides in
    the protocol's yardstick here (the occluded rows' error is against the tracker's noisy
    readings, and the offset moves more in an occluded block than one reading's noise): seen,
    2.52 mm against 2.39 without it, coverage 88 and 92 %.
    """
    robot = load_robot(SENSOR_ROBOT)
    rng = np.random.default_rng(4)
    rows, sigma, tau = 120, 2e-3, 8.0
    run = _two_sensor_run(robot, rng, rows, sigma, tau, coil_every=1)
    robot = robot.with_model_uncertainty(ModelUncertainty(base_position=sigma,
                                                          correlation_time=tau))
    alone = occlusion_replay(robot, dataclasses.replace(run, points={}), 5, 5)
    both = occlusion_replay(robot, run, 5, 5)
    assert both.fused != alone.fused  # the coil's readings moved the estimate
    assert abs(both.fused - alone.fused) < 0.1 * alone.fused and both.coverage > 0.85
    assert both.model == alone.model and both.rows == alone.rows == 60


def _truth_points(truth, lengths, sensor):
    points, previous = [], None
    for row in lengths:
        previous = truth.solve_lengths(row, warm_start=previous)
        shape = previous.shape
        points.append(shape.tip_position + shape.tip_rotation @ sensor.offset)
    return np.array(points)


def test_on_truth_with_physics_the_file_lacks_a_tracked_runs_tip_ellipsoid_is_honest():
    """Calibrated on a training run of the truth, a held-out run tracked on every row.

    The truth: the rod 8 % stiffer, the cables' EA 400 N, homing errors, 10 g guide disks.

    ``bench_mismatch``'s case with the tip tracker: before ``point_noise`` (the model's white
    error, fitted on the rows a tracker sees) the tip's 95 % ellipsoid held 74.7 % of the rows.
    """
    nominal, truth = mismatched_truth(SENSOR_ROBOT)
    tracker = nominal.sensors[0]
    rng = np.random.default_rng(3)
    period, train, held_out = 0.5, 400, 300
    lengths = smooth_path(nominal, train, seed=1)
    tips = _truth_points(truth, lengths, tracker) + rng.normal(0.0, tracker.position_sigma,
                                                               (train, 3))
    run = RecordedRun(times=period * np.arange(train), labels=('',) * train, lengths=lengths,
                      tips=tips, source='simulated truth')
    measured, report = model_uncertainty.measure(
        nominal.with_model_uncertainty(ModelUncertainty()), run)
    assert measured.point_noise > 0.0, report
    robot = nominal.with_model_uncertainty(measured)
    lengths = smooth_path(nominal, held_out, seed=2)
    errors, nees, previous = [], [], None
    for i, (row, point) in enumerate(zip(lengths, _truth_points(truth, lengths, tracker))):
        seen = point + rng.normal(0.0, tracker.position_sigma, 3)
        previous = robot.estimate_shape(row, warm_start=previous, stamp=period * i, sensors={
            tracker.name: SensorReading(seen, stamp=period * i)})
        shape = previous.shape
        error = shape.tip_position + shape.tip_rotation @ tracker.offset - point
        errors.append(error)
        nees.append(float(error @ np.linalg.solve(point_covariance(previous, tracker), error)))
    held = float(np.mean(np.array(nees) <= 7.81))
    assert 0.85 <= held <= 0.99, (held, measured)
    # the model alone is 13.7 mm off at the tip here (bench_mismatch); the tracker 0.5 mm
    assert math.sqrt(np.mean(np.sum(np.square(errors), axis=1))) < 1e-3


def test_point_noise_widens_each_point_as_it_grows_along_the_rod_and_weighs_a_reading_less():
    base = load_robot(SENSOR_ROBOT)
    noisy = base.with_model_uncertainty(dataclasses.replace(base.model_uncertainty,
                                                            point_noise=1e-3))
    lengths = _pulled(base)
    tracker = base.sensors[0]
    model = base.estimate_shape(lengths, exact=True)
    seen = model.shape.tip_position + model.shape.tip_rotation @ tracker.offset + [3e-3, 0, 0]
    estimates = [robot.estimate_shape(lengths, exact=True, stamp=1.0, sensors={
        tracker.name: SensorReading(seen, stamp=1.0)}) for robot in (base, noisy)]
    cold = [robot.estimate_shape(lengths, exact=True, stamp=1.0) for robot in (base, noisy)]
    s, length = cold[0].shape.s, cold[0].shape.s[-1]
    added = cold[1].position_covariance - cold[0].position_covariance
    expected = (1e-3 * s / length) ** 2
    np.testing.assert_allclose(added, expected[:, None, None] * np.eye(3), atol=1e-15)
    np.testing.assert_allclose(cold[1].tip_covariance[:3, :3] - cold[0].tip_covariance[:3, :3],
                               1e-6 * np.eye(3), atol=1e-15)
    # the same reading, judged against a wider prediction, moves the loads less (the middle of
    # the rod), and the tip, whose own white error it saw too, further towards it
    middle = len(s) // 2
    body = [e.shape.positions[middle, 0] - model.shape.positions[middle, 0] for e in estimates]
    assert 0.0 < body[1] < body[0]
    moved = [e.shape.tip_position[0] - model.shape.tip_position[0] for e in estimates]
    assert 0.0 < moved[0] < moved[1] < 3e-3
    chi2 = [e.sensors[tracker.name].chi2 for e in estimates]
    assert chi2[1] < chi2[0]


def test_a_reading_at_the_tip_updates_the_tips_white_error_as_an_augmented_state_would():
    """The tip's mean and covariance against a Kalman update of [d; w_tip] written out here.

    Before, the published tip covariance added the whole white variance after a reading that
    had seen it: a tracked row's ellipsoid held 100 % (fusion --simulate, point_noise 1 mm).
    """
    base = load_robot(SENSOR_ROBOT)
    white = 1e-3
    robot = base.with_model_uncertainty(dataclasses.replace(base.model_uncertainty,
                                                            point_noise=white))
    lengths = _pulled(base)
    tracker = robot.sensors[0]
    cold = robot.estimate_shape(lengths, exact=True, stamp=1.0)
    reading = cold.shape.tip_position + cold.shape.tip_rotation @ tracker.offset + [2e-3, -1e-3, 0]
    fused_estimate = robot.estimate_shape(lengths, exact=True, stamp=1.0, sensors={
        tracker.name: SensorReading(reading, stamp=1.0)})
    # the reference: the state [d; w], the tracker's rows [H, I], its device noise alone
    g = fused_estimate.sensitivity.positions[-1]
    k = g.shape[1]
    assert not np.any(tracker.offset)  # the tracker's point is the tip: its rows are g
    h = g
    prior = np.zeros((k + 3, k + 3))
    prior[:k, :k] = cold.unmodelled.covariance
    prior[k:, k:] = white ** 2 * np.eye(3)
    rows = np.hstack([h, np.eye(3)])
    spread = rows @ prior @ rows.T + tracker.position_sigma ** 2 * np.eye(3)
    gain = prior @ rows.T @ np.linalg.inv(spread)
    innovation = reading - (cold.shape.tip_position + cold.shape.tip_rotation @ tracker.offset)
    mean = gain @ innovation
    covariance = (np.eye(k + 3) - gain @ rows) @ prior
    tip = np.hstack([g, np.eye(3)])
    np.testing.assert_allclose(fused_estimate.shape.tip_position - cold.shape.tip_position,
                               tip @ mean, atol=1e-10)
    np.testing.assert_allclose(fused_estimate.tip_covariance[:3, :3],
                               tip @ covariance @ tip.T, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(fused_estimate.position_covariance[-1],
                               tip @ covariance @ tip.T, rtol=1e-6, atol=1e-14)
    # the tip's pose: its rotation moves with d alone, and its correlation with the position
    # carries the white error's share too
    pose = np.vstack([tip, np.hstack([fused_estimate.sensitivity.angles[-1], np.zeros((3, 3))])])
    np.testing.assert_allclose(fused_estimate.tip_covariance, pose @ covariance @ pose.T,
                               rtol=1e-6, atol=1e-14)
    # a reading of another stamp (another configuration's white error): the whole variance
    later = robot.estimate_shape(lengths, exact=True, stamp=1.0, sensors={
        tracker.name: SensorReading(reading, stamp=0.99)})
    assert later.unmodelled.tip_white is None
    assert np.trace(later.tip_covariance[:3, :3]) > 2.0 * np.trace(
        fused_estimate.tip_covariance[:3, :3])


def test_two_tip_sensors_with_a_white_error_give_covariances_a_covariance_can_be():
    """A second tip sensor (a marker 8 mm off the tip) read at the same stamp as the tracker.

    Before, both were taken to share one white error while their noise counted two: the tip's
    covariance had an eigenvalue of -5.4e-7 m^2 (point_noise 1 mm), -2.4e-5 at 5 mm.
    """
    document = _document()
    document['sensors'].append({'name': 'marker', 'at': 'tip', 'offset': [0.0, 0.008, 0.0],
                                'kind': 'position', 'noise': {'position': 5e-4}})
    for white in (1e-3, 5e-3):
        document['model_uncertainty'] = dict(document['model_uncertainty'], point_noise=white)
        robot = Robot(parse_robot_description(document))
        lengths = _pulled(robot)
        cold = robot.estimate_shape(lengths, exact=True, stamp=1.0)
        shape = cold.shape
        readings = {sensor.name: SensorReading(
            shape.tip_position + shape.tip_rotation @ sensor.offset + [1e-3, 2e-3, 0.0],
            stamp=1.0) for sensor in robot.sensors if sensor.at_tip}
        estimate = robot.estimate_shape(lengths, exact=True, stamp=1.0, sensors=readings)
        assert all(verdict.used for verdict in estimate.sensors.values())
        scale = np.trace(estimate.tip_covariance[:3, :3])
        for matrix in (estimate.tip_covariance, estimate.position_covariance[-1],
                       *(point_covariance(estimate, sensor) for sensor in robot.sensors)):
            assert np.linalg.eigvalsh(matrix)[0] > -1e-9 * scale, matrix


def test_calibrate_recovers_a_known_hidden_drift():
    """A synthetic run: the tracker sees the model plus a smooth drift of known sigma and time.

    The drift is drawn from its covariance, sigma^2 (1 + lambda t) exp(-lambda t) (Rasmussen &
    Williams eq. 4.17), not by the estimator's transition. Before the drift was fitted beside
    the offset, the offset took it (2.1 mm over 7.8 s) and the drift got 0.83 mm.
    """
    robot = load_robot(REPO / 'config' / 'tendon_robot_real_tendons.yaml')
    rng = np.random.default_rng(7)
    sigma, length, noise, rows = 2e-3, 3.0, 3e-4, 400
    times = np.cumsum(rng.uniform(0.3, 0.7, rows))
    lag = np.abs(times[:, None] - times[None, :]) * math.sqrt(3.0) / length
    kernel = sigma ** 2 * (1.0 + lag) * np.exp(-lag)
    drift = np.linalg.cholesky(kernel + 1e-14 * np.eye(rows)) @ rng.normal(size=(rows, 3))
    run = _synthetic_run(robot, rng, times, drift, noise)
    measured, report = model_uncertainty.measure(robot, run, tracker_noise=noise)
    assert 0.7 * sigma < measured.drift < 1.3 * sigma, report
    assert 0.5 * length < measured.drift_time < 2.0 * length, report
    assert measured.base_position < 0.6 * sigma, report


def test_an_older_reading_counts_for_less():
    """Fused by stamp: a reading taken 5 s before the estimate's stamp moves it less.

    The estimate of 5 s before is the model of its time (a client at 0.2 Hz); without it the
    reading is set aside (no shape of its time).
    """
    robot = load_robot(SENSOR_ROBOT)
    lengths = _pulled(robot)
    model = robot.estimate_shape(lengths, exact=True)
    tip = model.shape.tip_position + model.shape.tip_rotation @ robot.sensors[0].offset
    seen = tip + np.array([0.002, 0.0, 0.0])
    fresh = robot.estimate_shape(lengths, exact=True, stamp=10.0, sensors={
        'tip_tracker': SensorReading(seen, stamp=10.0)})
    before = robot.estimate_shape(lengths, exact=True, stamp=5.0)
    old = robot.estimate_shape(lengths, exact=True, stamp=10.0, warm_start=before, sensors={
        'tip_tracker': SensorReading(seen, stamp=5.0)})
    moved = [e.shape.tip_position[0] - model.shape.tip_position[0] for e in (fresh, old)]
    assert 0.0 < moved[1] < moved[0]
    assert np.trace(old.tip_covariance[:3, :3]) > np.trace(fresh.tip_covariance[:3, :3])
    alone = robot.estimate_shape(lengths, exact=True, stamp=10.0, sensors={
        'tip_tracker': SensorReading(seen, stamp=5.0)})
    assert not alone.sensors['tip_tracker'].used
    assert 'no shape of its time' in alone.sensors['tip_tracker'].reason
    assert np.allclose(alone.shape.tip_position, model.shape.tip_position, atol=1e-9)


@pytest.mark.parametrize('name', ['tendon_robot_sensors.yaml',
                                  'three_section_robot_real_tendons.yaml'])
def test_the_friction_state_moves_the_tip_far_less_than_the_covariance_allows(name):
    """Issue 43 item 3: which way each cable last slid is left out of the covariance; this holds.

    A cable's friction state is unknown after a cold start (0) and may have turned within the
    encoders' deadband. Every cable pulled (+1) against every cable paid out (-1), the capstan
    mu 0.05 of these files: the tip moves at most 0.034 / 0.13 mm, at most 7 % / 3 % of the
    smallest standard deviation of the tip the model alone publishes (the file's uncertainty or
    the stand-in). A file with enough friction for it to matter fails here (mu 0.4: 55 %).
    """
    robot = load_robot(REPO / 'config' / name)
    if robot.model_uncertainty is None:
        robot = robot.with_model_uncertainty(
            default_model_uncertainty(robot.c[0], robot.length))
    rng = np.random.default_rng(0)
    straight = np.array(robot.straight_cable_lengths)
    shares, moves = [], []
    for _ in range(6):
        pulled = rng.random(len(straight)) < 0.5
        lengths = straight - pulled * np.abs(rng.normal(0.0, 0.01 * robot.length, len(straight)))
        nominal = robot.solve_lengths(lengths)
        tips = [robot.solve_lengths(lengths, warm_start=dataclasses.replace(
            nominal, motion=np.full(len(straight), state))).shape.tip_position
            for state in (1.0, -1.0)]
        covariance = robot.estimate_shape(lengths, exact=True).tip_covariance[:3, :3]
        moves.append(np.linalg.norm(tips[0] - tips[1]))
        shares.append(moves[-1] / math.sqrt(np.linalg.eigvalsh(covariance)[0]))
    assert max(moves) > 1e-5  # friction is there to move it
    assert max(shares) < 0.1, shares


@pytest.mark.parametrize('name', ['tendon_robot.yaml', 'tendon_robot_payload.yaml'])
def test_a_nodes_remade_load_columns_are_a_full_solves(name):
    """A node's bounded call remakes a load column now and then (one in COLUMN_EVERY calls).

    Each side of its central difference is solved to the solver's tolerance, not to a tenth
    of the encoders' noise (1 um here), where the payload's mass column came out 170 % off;
    an ideal cable's column steps 1e-3 of its sigma (0.3 um) and is solved to the end: bounded
    (1 % of the misfit), both sides stopped where they started and the column came out zero
    (e745b54). Every column that moves the tip more than 0.1 mm over its sigma is checked.
    """
    from reference_motion import motion

    from continuum_statics.core.estimation.shape_estimation import Tracking
    from continuum_statics.core.estimation.state_estimation import prior_scales

    document = _document(REPO / 'config' / name)
    document.setdefault('model_uncertainty', {
        'tip_force': 0.05, 'section_moment': 0.005, 'cable_length': 3e-4,
        'base_position': 5e-4, 'correlation_time': 10.0})
    robot = Robot(parse_robot_description(document, 'test'))
    noise = 10e-6
    lengths = motion(robot, 2000, seed=5)
    lengths = lengths + np.random.default_rng(6).normal(0.0, noise, lengths.shape)
    tracking = Tracking(length_noise=noise, motion_threshold=3 * noise)
    # every column made at a bent pose the motion never comes back to: each is remade in turn
    estimate = robot.estimate_shape(_pulled(robot, 0.01), stamp=0.0)
    first = estimate.sensitivity.tips.copy()
    for k, each in enumerate(lengths[1:], 1):
        estimate = robot.estimate_shape(each, warm_start=estimate, tracking=tracking,
                                        stamp=k * 1e-3)
    full = robot.estimate_shape(lengths[-1], exact=True).sensitivity.positions[-1]
    names, sigma = prior_scales(robot)
    remade = [j for j, name in enumerate(names) if name.split('.')[0] != 'base_position'
              and not np.array_equal(estimate.sensitivity.tips[j], first[j])
              and np.linalg.norm(full[:, j]) * sigma[j] > 1e-4]
    assert any(names[j].startswith('cable_length') for j in remade)
    for j in remade:  # made up to a few mm of tip travel before: the size, not the digits
        size = np.linalg.norm(estimate.sensitivity.positions[-1][:, j])
        assert size == pytest.approx(np.linalg.norm(full[:, j]), rel=0.2), names[j]
