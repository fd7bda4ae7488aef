"""The kernel contracts are stated once (core/description/layout.py); the kernels follow them."""
import ast
import inspect
from pathlib import Path

from conftest import REPO
import numpy as np

from continuum_statics import load_robot
from continuum_statics.core.description.layout import (
    BENDING,
    MOMENT,
    POSITION,
    STATE_SIZE,
    STRETCH,
    KernelModel,
    ProbeRows,
)
from continuum_statics.core.rod import model as model_module
from continuum_statics.core.warmup import KERNEL_MODULES

PACKAGE = REPO / 'continuum_statics'
#: Modules of compiled code: their kernels call each other inside numba
COMPILED = {name.rsplit('.', 1)[1] for name in KERNEL_MODULES}
#: The rod model's kernels: Python calls each one through core/rod/model.py only
ROD_KERNELS = {
    'kernel': ('integrate_batch', 'cable_lengths_batch', 'loads_from_state', 'section_tensions',
               'probe', 'tip_jacobian'),
    'tracking': ('track',),
    'goal_tracking': ('goal_solve',),
    'length_tracking': ('evaluate_at', 'jacobian_pieces', 'chord'),
    'tendon_kernel': ('path_stretch',),
    'dynamics_kernel': ('solve_step', 'advance'),
}


def kernel_uses(tree):
    """Yield (module, kernel) of every import or attribute use of a rod kernel in a module."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            module = node.module.rsplit('.', 1)[-1]
            for alias in node.names:
                if alias.name in ROD_KERNELS.get(module, ()):
                    yield module, alias.name
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.attr in ROD_KERNELS.get(node.value.id, ()):
                yield node.value.id, node.attr


def test_python_calls_each_rod_kernel_from_the_model_object_only():
    outside = []
    for path in PACKAGE.rglob('*.py'):
        name = path.stem
        if path.parent.name == 'rod' and (name in COMPILED or name == 'model'):
            continue
        outside += ['%s: %s.%s' % (path.relative_to(REPO), *use)
                    for use in kernel_uses(ast.parse(path.read_text()))]
    assert not outside


def test_the_model_calls_every_kernel_with_its_whole_argument_list():
    tree = ast.parse(Path(model_module.__file__).read_text())
    calls = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and isinstance(node.func.value, ast.Name) \
                and node.func.attr in ROD_KERNELS.get(node.func.value.id, ()):
            calls.setdefault(node.func.attr, []).append(node)
    every = {kernel for names in ROD_KERNELS.values() for kernel in names}
    assert set(calls) == every
    for module, names in ROD_KERNELS.items():
        for name in names:
            assert len(calls[name]) == 1, name  # one call site
            dispatcher = getattr(getattr(model_module, module), name)
            expected = len(inspect.signature(dispatcher.py_func).parameters)
            call = calls[name][0]
            assert not call.keywords and len(call.args) == expected, name


def test_the_kernel_record_holds_the_robot_tables_of_its_names():
    robot = load_robot(REPO / 'config' / 'two_section_robot.yaml')
    record = robot.model.record
    assert record.code == robot.model_code and record.step == robot.bending_step()
    assert record.s_grid is robot.s_grid and record.params is robot.params
    for name in KernelModel._fields[4:]:
        assert getattr(record, name) is getattr(robot, name), name


def test_node_state_and_probe_rows_match_what_the_kernel_computes():
    robot = load_robot(REPO / 'config' / 'tendon_robot.yaml')
    shape = robot.solve_ivp([2.0, -1.0, 0.0], tip_force=(0.0, 0.0, -0.1))
    states = shape.states
    assert states.shape[1] == STATE_SIZE
    np.testing.assert_allclose(states[-1, POSITION], shape.tip_position)
    np.testing.assert_allclose(states[0, BENDING], [2.0, -1.0, 0.0])  # u(0) as given
    assert abs(states[0, STRETCH][2]) < 1e-4  # v - e3: small axial strain, not v
    rows = ProbeRows(len(robot.cable_names))
    probed = robot.probe(shape.state, 0, np.array([0.0, 0.0, -0.1]), np.zeros(3))
    values, jacobian = probed.values, probed.jacobian
    assert values.shape == (rows.size,) and jacobian.shape == (rows.size, 0)
    np.testing.assert_allclose(values[rows.tip], shape.tip_position, atol=1e-12)
    np.testing.assert_allclose(values[rows.axis], shape.tip_rotation[:, 2], atol=1e-12)
    np.testing.assert_allclose(values[rows.lengths], robot.cable_lengths(shape), atol=1e-12)
    # an IVP is no equilibrium: the balance row is the tip moment M(L) (no tip moment) / (EI/L)
    np.testing.assert_allclose(values[rows.balance],
                               states[-1, MOMENT] * robot.length / robot.c[0], atol=1e-12)
    assert np.linalg.norm(values[rows.balance]) > 1e-3
