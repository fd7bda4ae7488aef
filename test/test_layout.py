"""The kernel contracts are stated once (core/layout.py) and the kernels follow them."""
import inspect

from conftest import REPO
import numpy as np

from continuum_statics import load_robot
from continuum_statics.core import kernel, tracking
from continuum_statics.core.layout import (
    BENDING,
    MOMENT,
    POSITION,
    STATE_SIZE,
    STRETCH,
    ProbeRows,
    SectionArrays,
)


def parameters(dispatcher):
    return list(inspect.signature(dispatcher.py_func).parameters)


def test_the_kernels_take_the_section_arrays_in_the_record_order():
    fields = list(SectionArrays._fields)
    assert parameters(kernel.probe)[-len(fields):] == fields
    track = parameters(tracking.track)
    start = track.index(fields[0])
    assert track[start:start + len(fields)] == fields
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    for name, array in zip(fields, robot.arrays):
        assert array is getattr(robot, name)


def test_node_state_and_probe_rows_match_what_the_kernel_computes():
    robot = load_robot(REPO / 'config' / 'tendon_robot.yaml')
    shape = robot.solve_ivp([2.0, -1.0, 0.0], tip_force=(0.0, 0.0, -0.1))
    states = shape.states
    assert states.shape[1] == STATE_SIZE
    np.testing.assert_allclose(states[-1, POSITION], shape.tip_position)
    np.testing.assert_allclose(states[0, BENDING], [2.0, -1.0, 0.0])  # u(0) as given
    assert abs(states[0, STRETCH][2]) < 1e-4  # v - e3: small axial strain, not v
    rows = ProbeRows(len(robot.cable_names))
    values, jacobian, _ = robot.probe(shape.state, 0, np.array([0.0, 0.0, -0.1]), np.zeros(3))
    assert values.shape == (rows.size,) and jacobian.shape == (rows.size, 0)
    np.testing.assert_allclose(values[rows.tip], shape.tip_position, atol=1e-12)
    np.testing.assert_allclose(values[rows.axis], shape.tip_rotation[:, 2], atol=1e-12)
    np.testing.assert_allclose(values[rows.lengths], robot.cable_lengths(shape), atol=1e-12)
    # an IVP is no equilibrium: the balance row is the tip moment M(L) (no tip moment) / (EI/L)
    np.testing.assert_allclose(values[rows.balance],
                               states[-1, MOMENT] * robot.length / robot.c[0], atol=1e-12)
    assert np.linalg.norm(values[rows.balance]) > 1e-3
