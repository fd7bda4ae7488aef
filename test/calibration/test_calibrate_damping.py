"""``calibrate --fit damping``: a synthetic recovery (no recorded step or release is here).

A run is made by the rod in motion with a known damping (a 4 mm motor step through the
simulated driver's motor lag, the tip sampled at 250 Hz with 0.1 mm of tracker noise); the fit,
started from another damping, must find it again and write it into the robot file.
"""
import csv
import json
import math

from conftest import REPO
import numpy as np
import pytest
import yaml

from continuum_statics import load_robot
from continuum_statics.drivers.sim import SimulatedCableBackend
from continuum_statics.tools import calibrate

SOURCE = REPO / 'config' / 'tendon_robot_dynamic.yaml'
TRUE_BENDING = 7.8e-5  # N m^2 s, the file's
NOISE = 1e-4  # m


def recorded_step(path, duration=1.5, rate=250.0, seed=36):
    robot = load_robot(SOURCE)
    assert robot.description.rod.bending_damping == TRUE_BENDING
    sim = robot.dynamics()
    motors = robot.straight_cable_lengths.copy()
    sim.start(lengths=motors)
    target = motors + np.array([-0.004, 0.0, 0.0, 0.0])
    rng = np.random.default_rng(seed)
    every = int(round(1.0 / (rate * sim.dt)))
    rows = [[0.0, *motors, *(sim.state.tip_position + rng.normal(0.0, NOISE, 3))]]
    for i in range(1, int(round(duration / sim.dt)) + 1):
        moving = target if i * sim.dt > 0.05 else motors
        motors = SimulatedCableBackend.step(motors, moving, sim.dt, 0.02, 0.05)
        state = sim.step(lengths=motors)
        if i % every == 0:
            rows.append([i * sim.dt, *motors, *(state.tip_position + rng.normal(0.0, NOISE, 3))])
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream)
        writer.writerow(['timestamp', *robot.cable_names, 'tip_x', 'tip_y', 'tip_z'])
        writer.writerows(rows)


def test_the_damping_of_a_recorded_step_is_found_again_and_written(tmp_path, capsys):
    data = tmp_path / 'step.csv'
    recorded_step(data)
    document = yaml.safe_load(SOURCE.read_text())
    document['rod']['damping'] = {'bending': 1e-6, 'shear': 1e-2}  # 1/78 of the truth
    start = tmp_path / 'start.yaml'
    start.write_text(yaml.safe_dump(document))
    out = tmp_path / 'fitted.yaml'
    assert calibrate.main(['--robot', str(start), '--data', str(data), '--fit', 'damping',
                           '--output', str(out), '--json']) == 0
    summary = json.loads(capsys.readouterr().out)
    fitted = summary['fitted']['damping']['after']
    print('damping %.4g -> %.4g N m^2 s (true %.4g); tip rms %.3f -> %.3f mm (noise %.1f mm)'
          % (1e-6, fitted, TRUE_BENDING, 1e3 * summary['rms_before'],
             1e3 * summary['rms_after'], 1e3 * NOISE * math.sqrt(3)))
    # the tracker's noise leaves B this uncertain: over seeds 0-5 the fit was -0.3 % off on
    # average with a standard deviation of 2.0 % (this seed, 36: -5.9 %); 4 sigma
    assert abs(fitted / TRUE_BENDING - 1.0) < 0.08
    assert summary['rms_after'] < 1.2 * NOISE * math.sqrt(3)  # down to the tracker's noise
    assert summary['rms_before'] > 3.0 * summary['rms_after']
    assert load_robot(out).description.rod.bending_damping == pytest.approx(fitted, rel=1e-5)


def test_damping_is_fitted_alone(tmp_path, capsys):
    data = tmp_path / 'step.csv'
    recorded_step(data, duration=0.1)
    assert calibrate.main(['--robot', str(SOURCE), '--data', str(data), '--fit', 'damping',
                           'youngs_modulus']) == 1
    assert 'fitted alone' in capsys.readouterr().err
