"""Measured tensions as a measurement of the fused state (the robot file's ``tension_noise``).

Independent truth: a real-tendon robot solved under errors drawn from the file's own prior
(a tip force, cable length errors, a backbone offset) and a hidden payload; its motor tensions
and tip are measured with noise. The estimator sees the commanded lengths only.
"""
from pathlib import Path

import numpy as np
import pytest
import yaml

from continuum_statics.core.description.robot_file import parse_robot_description
from continuum_statics.core.robot import Robot

REPO = Path(__file__).resolve().parents[2]
PAYLOAD_ROBOT = REPO / 'config' / 'tendon_robot_payload.yaml'
TENSION_NOISE = 0.05  # N
#: chi-square 0.95 quantiles of 1 and 3 degrees of freedom
GATE_1, GATE_3 = 3.841, 7.815


def _robot(**changes):
    document = yaml.safe_load(PAYLOAD_ROBOT.read_text())
    # the model's error as the truth below draws it: no section moment (the truth cannot
    # apply one), cable lengths known to 20 um (encoders homed well)
    document['model_uncertainty'].update(section_moment=0.0, cable_length=2e-5)
    document.update(changes)
    return Robot(parse_robot_description(document))


def _cases(robot, count, seed=4):
    """Yield (lengths, measured tensions, truth tip (3,) m, payload kg) drawn from the prior."""
    rng = np.random.default_rng(seed)
    prior = robot.model_uncertainty
    n = len(robot.cable_names)
    while count:
        lengths = robot.straight_cable_lengths - rng.uniform(0.0, 4e-3, n) * (rng.random(n) < 0.5)
        mass = rng.normal(0.0, robot.load_model.prior[0])
        force = rng.normal(0.0, prior.tip_force, 3) + mass * np.asarray(robot.gravity)
        truth = robot.solve_lengths(lengths - rng.normal(0.0, prior.cable_length, n),
                                    tip_force=force)
        if not truth.converged:
            continue
        count -= 1
        tensions = np.maximum(truth.tensions + rng.normal(0.0, TENSION_NOISE, n), 0.0)
        yield (lengths, tensions,
               truth.shape.tip_position + rng.normal(0.0, prior.base_position, 3), mass)


def test_measured_tensions_tell_the_shape_and_its_covariance_holds_the_truth():
    fused, plain = _robot(tension_noise=TENSION_NOISE), _robot()
    errors, nees, mass_z = {'plain': [], 'fused': []}, [], []
    for lengths, tensions, tip, mass in _cases(plain, 30):
        for name, robot in (('plain', plain), ('fused', fused)):
            estimate = robot.estimate_shape(lengths, tensions=tensions, exact=True)
            error = estimate.shape.tip_position - tip
            errors[name].append(np.linalg.norm(error))
        assert estimate.tensions_verdict.used, estimate.tensions_verdict
        nees.append(float(error @ np.linalg.solve(estimate.tip_covariance[:3, :3], error)))
        mass_z.append((estimate.unmodelled.mean[0] - mass) / estimate.unmodelled.sigma[0])
    rms = {name: float(np.sqrt(np.mean(np.square(e)))) for name, e in errors.items()}
    print('tip RMS %.2f mm without the tensions, %.2f mm with them; NEES mean %.2f, 95 %% '
          'ellipsoid holds %.0f %%; payload z^2 mean %.2f'
          % (1e3 * rms['plain'], 1e3 * rms['fused'], np.mean(nees),
             100 * np.mean(np.array(nees) < GATE_3), np.mean(np.square(mass_z))))
    assert rms['fused'] < 0.5 * rms['plain'], rms
    assert 0.85 <= np.mean(np.array(nees) < GATE_3) <= 1.0, nees
    assert 1.5 <= np.mean(nees) <= 4.5, nees  # 3 degrees of freedom
    assert 0.85 <= np.mean(np.square(mass_z) < GATE_1) and np.mean(np.square(mass_z)) < 1.6


def test_a_load_cell_off_by_newtons_is_set_aside_and_the_shape_is_the_lengths_alone():
    fused, plain = _robot(tension_noise=TENSION_NOISE), _robot()
    lengths, tensions, _, _ = next(_cases(plain, 1))
    tensions[0] += 5.0
    estimate = fused.estimate_shape(lengths, tensions=tensions, exact=True)
    verdict = estimate.tensions_verdict
    assert not verdict.used and 'N RMS from the estimate' in verdict.reason, verdict
    alone = plain.estimate_shape(lengths, tensions=tensions, exact=True)
    assert alone.tensions_verdict is None
    np.testing.assert_allclose(estimate.shape.positions, alone.shape.positions, atol=1e-9)


@pytest.mark.parametrize('value, expected', [(0.05, 0.05), ('5%', '5%'), ('2.5 %', '2.5%')])
def test_tension_noise_is_newtons_or_a_percentage(value, expected):
    assert _robot(tension_noise=value).tension_noise == expected


@pytest.mark.parametrize('value', [0.0, -0.1, '-5%', 'loud', float('nan')])
def test_a_tension_noise_that_is_no_sigma_is_named(value):
    with pytest.raises(ValueError, match='tension_noise'):
        _robot(tension_noise=value)
