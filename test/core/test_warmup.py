"""The start-up warm-up covers every kernel the nodes call: nothing compiles at first use.

numba compiles per argument types, in whatever thread first calls a kernel; a node that compiled
while serving once published nothing for seconds and crashed when two threads compiled at once.
These tests run the nodes' real work after the warm-up (other robots than the one it used: other
section counts, cable models, a passive rod) and require that no kernel gained a signature.
"""
from conftest import REPO
from nodes_helpers import LATCHED, Collector, call, pose_xyz, wait_until
import numpy as np
import pytest

from continuum_statics import load_robot
from continuum_statics.core.warmup import (
    SPECIALISATIONS,
    compile_report,
    kernel_signatures,
    record_compiles,
    warm_up,
    warm_up_dynamics,
)

ROBOTS = ('tendon_robot.yaml', 'two_section_robot.yaml', 'three_section_robot.yaml',
          'jones2009_nitinol_rod.yaml')


def test_every_kernel_python_calls_is_compiled_by_the_warm_up():
    from continuum_statics.core.warmup import ENTRY_POINTS

    warm_up()
    counts = kernel_signatures()
    assert set(ENTRY_POINTS) <= set(counts), set(ENTRY_POINTS) - set(counts)
    assert all(counts[name] >= 1 for name in ENTRY_POINTS), counts


def _specialisations():
    """{kernel: signatures} of every compiled kernel, and the kernels with more than expected."""
    counts = {name: count for name, count in kernel_signatures().items() if count}
    return counts, {name: count for name, count in counts.items()
                    if count > SPECIALISATIONS.get(name, 1)}


def test_each_kernel_has_one_type_specialisation_after_the_warm_ups_and_the_core_calls():
    """A call site passing other types compiles the kernel again: seconds of cold start each.

    (A Literal constant, an 'A' or read-only array, an int for a float; and a compile at first
    use in a node.) Only the kernels of SPECIALISATIONS may have more, at most as many as it
    says (a callee's own specialisation exists only where its caller was compiled, not loaded).
    """
    from numba.core.registry import CPUDispatcher

    warm_up()
    warm_up_dynamics()
    for robot_file in ROBOTS:  # the nodes' calls on other robots compile nothing new either
        robot = load_robot(REPO / 'config' / robot_file)
        if robot.cable_names:
            shape = robot.solve_ivp([1.0, -0.5, 0.0])
            robot.estimate_shape(robot.cable_lengths(shape))
            robot.solve_tip_goal(shape.tip_position)
    counts, wrong = _specialisations()
    assert not wrong, '\n'.join('%s: %d specialisations, at most %d expected:\n  %s' % (
        name, count, SPECIALISATIONS.get(name, 1), '\n  '.join(
            str(sig) for sig in _dispatcher(name).signatures)) for name, count in wrong.items())
    assert all(isinstance(_dispatcher(name), CPUDispatcher) for name in SPECIALISATIONS)
    assert all(counts.get(name, 0) >= 1 for name in SPECIALISATIONS), counts


def _dispatcher(name):
    import importlib

    module, attribute = name.rsplit('.', 1)
    return getattr(importlib.import_module(module), attribute)


def test_the_compile_report_names_each_compiled_kernel_with_its_times():
    report = {'kernels': {'continuum_statics.core.rod.kernel.probe': (2.5, 2.0)}, 'job': 'chain',
              'wall': 3.0, 'cpu': 2.9}
    lines = compile_report([report, {'kernels': {}}])
    assert 'rod.kernel.probe' in lines[0] and '2.50 s wall' in lines[0], lines
    assert '2.00 s CPU' in lines[0] and '(chain)' in lines[0], lines
    assert lines[-1].startswith('compiled 1 kernels: 2.00 s CPU'), lines
    assert compile_report([{'kernels': {}}]) == []
    with record_compiles() as nothing:  # a warm process compiles nothing
        warm_up()
    assert nothing['kernels'] == {}


@pytest.mark.parametrize('robot_file', ROBOTS)
def test_core_calls_of_any_robot_compile_nothing_after_the_warm_up(robot_file):
    warm_up()
    robot = load_robot(REPO / 'config' / robot_file)
    before = kernel_signatures()
    load = np.zeros(6)
    robot.solve_bvp(tip_force=load[:3], tip_moment=load[3:])
    if robot.cable_names:
        shape = robot.solve_ivp([1.0, -0.5, 0.0])
        lengths = robot.cable_lengths(shape)
        estimate = robot.estimate_shape(lengths)
        estimate = robot.estimate_shape(lengths + 2e-5, warm_start=estimate)
        robot.estimate_shape(lengths, tensions=np.ones(len(lengths)), warm_start=estimate)
        goal = robot.solve_tip_goal(shape.tip_position, warm_start=estimate)
        robot.equilibrium_between(estimate, goal, 0.3, warm_start=estimate)
    assert kernel_signatures() == before


rclpy = pytest.importorskip('rclpy')


@pytest.mark.ros
def test_the_nodes_compile_nothing_while_they_serve(harness):
    from geometry_msgs.msg import PoseStamped
    from nav_msgs.srv import GetPlan

    from continuum_statics.nodes.cable_driver_node import CableDriverNode
    from continuum_statics.nodes.statics_node import StaticsNode
    from continuum_statics.nodes.tip_controller_node import TipControllerNode

    robot_file = str(REPO / 'config' / 'two_section_robot.yaml')
    robot = load_robot(robot_file)
    warm_up()
    before = kernel_signatures()
    for node_class in (StaticsNode, CableDriverNode, TipControllerNode):
        harness.add(node_class, robot_file=robot_file)
    client = harness.client()
    tip = Collector(client, PoseStamped, 'tip_pose', LATCHED)
    service = client.create_client(GetPlan, 'tip_goal')
    assert service.wait_for_service(timeout_sec=10.0)
    wait_until(lambda: tip.last is not None, 10.0, 'the first tip pose')
    goal = robot.solve_ivp([2.0, 1.0, 0.0]).tip_position
    request = GetPlan.Request(tolerance=1e-3)
    request.goal.header.frame_id = robot.base_frame_id
    request.goal.pose.position.x, request.goal.pose.position.y, request.goal.pose.position.z = (
        float(v) for v in goal)
    plan = call(service, request, 30.0).plan
    assert plan.poses and np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    assert kernel_signatures() == before
