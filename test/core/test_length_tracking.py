"""The compiled warm solve of the displacement-driven statics (core/rod/length_tracking.py).

Against independent references: the Jacobian pieces of one compiled batch equal plain forward
differences through the public probe, one column at a time in Python (the formulation the solver
used before); a warm solve handed a wrong Jacobian refreshes it and lands on Newton's
equilibrium (under the same friction history); a per-cycle bounded solve of a far jump is
finished by the calls after it.
"""
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.core.description.layout import ProbeRows
from continuum_statics.core.robot import Robot
from continuum_statics.core.statics import length_statics

CONFIG = Path(__file__).resolve().parents[2] / 'config'


def real_tendons(model):
    base = load_robot(CONFIG / 'three_section_robot_real_tendons.yaml')
    return Robot(dataclasses.replace(base.description, cable_model=model))


@pytest.mark.parametrize('model', ['point_moment', 'distributed'])
def test_jacobian_pieces_equal_column_by_column_differences(model):
    robot = real_tendons(model)
    n = len(robot.cable_names)
    solution = robot.solve_lengths(robot.straight_cable_lengths - 2e-3 * (np.arange(n) % 3 == 0))
    z = np.concatenate([solution.state[:3], solution.end_tensions])
    problem = length_statics._Problem(robot, solution.free_lengths, np.zeros(n), np.zeros(3),
                                      np.zeros(3))
    rows = ProbeRows(n)
    tension_step = 1e-7 * problem.t_ref

    def outputs(zz):  # balance rows and free length consumed, one probe per call
        x, fixed = problem.state_of(zz)
        probed = robot.probe(x, 0, np.zeros(3), np.zeros(3), fixed)
        consumed, _, _ = problem.consumed(probed.states, probed.values[rows.lengths], zz[3:])
        values = probed.values
        return values[rows.balance], consumed

    balance0, consumed0 = outputs(z)
    reference_balance = np.empty((3, 3 + n))
    reference_consumed = np.empty((n, 3 + n))
    for c in range(3 + n):
        h = robot.bending_step() if c < 3 else tension_step
        shifted = z.copy()
        shifted[c] += h
        balance, consumed = outputs(shifted)
        reference_balance[:, c] = (balance - balance0) / h
        reference_consumed[:, c] = (consumed - consumed0) / h
    pieces = robot.model.jacobian_pieces(np.zeros(3), np.zeros(3), z, problem.kernel_moment_map,
                                         problem.compliance, solution.end_tensions,
                                         tension_step)
    balance, d_consumed = pieces.balance, pieces.d_consumed
    # the pieces hold d(consumed)/dz with the stretch factor of the nominal tension: the
    # reference differentiates the stretch too, which differs by O(h) only
    scale = np.abs(reference_consumed).max()
    np.testing.assert_allclose(d_consumed, reference_consumed, atol=1e-6 * scale)
    np.testing.assert_allclose(balance, reference_balance,
                               atol=1e-6 * np.abs(reference_balance).max())


@pytest.mark.parametrize('model', ['point_moment', 'distributed'])
def test_a_warm_solve_on_a_wrong_jacobian_refreshes_it_and_lands_on_the_equilibrium(model):
    robot = real_tendons(model)
    n = len(robot.cable_names)
    first = robot.solve_lengths(robot.straight_cable_lengths - 1e-3)
    target = robot.straight_cable_lengths - 1e-3 + 1e-3 * (np.arange(n) % 3 == 1)
    balance, d_consumed = first.jacobian_parts
    wrong = dataclasses.replace(first, jacobian_parts=(0.3 * balance, -d_consumed))
    warm = robot.solve_lengths(target, warm_start=wrong)
    # the same motion history (friction acts against it) solved by Newton from nothing
    reference = robot.solve_lengths(target, warm_start=dataclasses.replace(
        first, jacobian_parts=None, model_at=None, shape=robot.solve_bvp()))
    assert warm.converged and reference.converged
    np.testing.assert_allclose(warm.shape.tip_position, reference.shape.tip_position,
                               atol=1e-8)
    np.testing.assert_allclose(warm.tensions, reference.tensions, atol=1e-6)


@pytest.mark.parametrize('model', ['point_moment', 'distributed'])
def test_a_warm_start_from_another_robot_solves_this_robot(model):
    # calibration warm-starts a candidate robot by another's solution of the same lengths: the
    # carried model (values at the solution) belongs to the other robot and must not be reused
    frictionless = real_tendons(model)  # friction would follow the two robots' free lengths
    tendons = dataclasses.replace(frictionless.tendons,
                                  friction=0.0 * frictionless.tendons.friction)
    robot = Robot(dataclasses.replace(frictionless.description, tendons=tendons))
    lengths = robot.straight_cable_lengths - 1e-3 * (np.arange(len(robot.cable_names)) % 3 == 0)
    other = robot.solve_lengths(lengths)
    for factor in (1.3, 1.001):  # a far robot, and a finite-difference step away
        stiffer = Robot(dataclasses.replace(robot.description, tendons=dataclasses.replace(
            tendons, stiffness=factor * tendons.stiffness)))
        warm = stiffer.solve_lengths(lengths, warm_start=other)
        cold = stiffer.solve_lengths(lengths)
        assert warm.converged and cold.converged
        moved = cold.shape.tip_position - other.shape.tip_position
        assert np.linalg.norm(moved) > 1e-5 * (factor - 1.0)
        # the same equilibrium to the solver's tolerance (1e-9 m of cable)
        np.testing.assert_allclose(warm.shape.tip_position - other.shape.tip_position, moved,
                                   atol=max(1e-8, 1e-2 * np.linalg.norm(moved)))


def test_a_bounded_solve_of_a_far_jump_is_finished_by_the_next_calls():
    robot = real_tendons('point_moment')
    n = len(robot.cable_names)
    # a start with no Jacobian to step on (as after a least-squares estimate): Newton's only
    start = dataclasses.replace(robot.solve_lengths(robot.straight_cable_lengths),
                                jacobian_parts=None)
    far = robot.straight_cable_lengths - 2e-2 * (np.arange(n) % 3 == 0)  # 20 mm pulls
    reference = robot.solve_lengths(far, warm_start=start)  # unbounded, the same history
    result, calls = start, 0
    while calls < 30:
        result = length_statics.solve_lengths(robot, far, warm_start=result, max_newton=1)
        calls += 1
        if result.converged:
            break
        assert 'unfinished' in result.message
    assert result.converged and calls > 1
    np.testing.assert_allclose(result.shape.tip_position, reference.shape.tip_position,
                               atol=1e-8)
