"""solve_tensions from a cold start: large tensions, tip loads, gravity in any direction."""
import dataclasses

from conftest import REPO
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.core.robot import Robot

FILES = ('tendon_robot.yaml', 'two_section_robot.yaml', 'three_section_robot.yaml')


@pytest.mark.parametrize('name', FILES)
def test_cold_tension_solves_up_to_three_times_a_quarter_turn(name):
    base = load_robot(REPO / 'config' / name)
    rng = np.random.default_rng(11)
    section_length = base.length / len(base.sections)
    for _ in range(8):
        gravity = rng.normal(size=3)
        robot = Robot(dataclasses.replace(
            base.description, gravity=9.81 * gravity / np.linalg.norm(gravity)))
        tensions = np.zeros(len(robot.cable_names))
        for section in robot.sections:
            j = rng.choice(section.cable_indices)
            radius = np.hypot(*robot.cable_offsets[j, :2])
            # the tension whose moment bends one section by 90 degrees, times up to 3
            quarter_turn = robot.c[0] * (np.pi / 2) / section_length / radius
            tensions[j] = rng.uniform(0.5, 3.0) * quarter_turn
        tip_force = rng.normal(size=3) * 0.3
        shape = robot.solve_tensions(tensions, tip_force=tip_force)
        assert np.all(np.isfinite(shape.positions))
        # equilibrium, checked outside the solver: the rod's moment at the tip carries the
        # cables' point moment (point_moment) or vanishes up to the cables' own (distributed);
        # either way the tip balance row of the model is zero
        values, _, _ = robot.probe(shape.state, 0, tip_force, np.zeros(3),
                                   shape.fixed_tensions)
        assert np.linalg.norm(values[-3:]) < 1e-8
        # the cable pulled hardest ends shorter than straight: the rod bends toward it
        hardest = np.argmax(tensions * np.hypot(*robot.cable_offsets[:, :2].T))
        only = np.zeros_like(tensions)
        only[hardest] = tensions[hardest]
        alone = robot.cable_lengths(robot.solve_tensions(only, tip_force=tip_force))
        assert alone[hardest] < robot.straight_cable_lengths[hardest]


def test_negative_or_non_finite_tensions_are_refused():
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    for bad in (-1.0, np.nan, np.inf):
        tensions = np.ones(len(robot.cable_names))
        tensions[2] = bad
        with pytest.raises(ValueError, match='tensions'):
            robot.solve_tensions(tensions)
