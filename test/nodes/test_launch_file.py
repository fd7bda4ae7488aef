"""launch/continuum_robot.launch.py: valid Python naming existing executables and config files."""
import ast
import importlib.util
import re

from conftest import REPO
import pytest

LAUNCH_FILE = REPO / 'launch' / 'continuum_robot.launch.py'


def _constant(tree, name):
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == name for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError('%s is not defined in the launch file' % name)


def _console_scripts():
    text = (REPO / 'setup.py').read_text()
    return dict(re.findall(r"'(\w+) = (continuum_statics[.\w]+:main)'", text))


def test_launch_file_is_valid_python_with_the_four_executables():
    tree = ast.parse(LAUNCH_FILE.read_text(), filename=str(LAUNCH_FILE))
    executables = _constant(tree, 'EXECUTABLES')
    assert set(executables) == {'statics', 'tip_controller', 'cable_driver'}
    assert _constant(tree, 'ESTIMATOR') == 'tip_load_estimator'
    scripts = _console_scripts()
    for executable in executables + ('tip_load_estimator',):
        assert executable in scripts, '%s is not a console script in setup.py' % executable
        module = scripts[executable].split(':')[0]
        assert importlib.util.find_spec(module) is not None, module
    assert _constant(tree, 'PACKAGE') == 'continuum_statics'
    functions = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
    assert 'generate_launch_description' in functions


def test_launch_file_names_existing_config_files_and_its_arguments():
    tree = ast.parse(LAUNCH_FILE.read_text())
    for name in _constant(tree, 'CONFIG_FILES'):
        assert (REPO / 'config' / name).is_file(), name
    text = LAUNCH_FILE.read_text()
    for argument in ('robot_file', 'driver', 'namespace', 'params_file', 'load_estimator'):
        assert "DeclareLaunchArgument('%s'" % argument in text, argument


@pytest.mark.ros
def test_params_file_lists_every_declared_parameter():
    """Every parameter a node declares appears in the shipped params file with its type."""
    yaml = pytest.importorskip('yaml')
    pytest.importorskip('rclpy')
    import rclpy

    from continuum_statics.nodes.cable_driver_node import CableDriverNode
    from continuum_statics.nodes.statics_node import StaticsNode
    from continuum_statics.nodes.tip_controller_node import TipControllerNode
    from continuum_statics.nodes.tip_load_estimator_node import TipLoadEstimatorNode

    params = yaml.safe_load((REPO / 'config' / 'continuum_robot.params.yaml').read_text())
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        plain = rclpy.create_node('plain', context=context)
        builtin = set(plain.list_parameters([], 10).names)  # use_sim_time and friends
        plain.destroy_node()
        for name, node_class in [('statics', StaticsNode), ('tip_controller', TipControllerNode),
                                 ('cable_driver', CableDriverNode),
                                 ('tip_load_estimator', TipLoadEstimatorNode)]:
            node = node_class(context=context, namespace='/params_check')
            try:
                declared = {n: node.get_parameter(n).value
                            for n in node.list_parameters([], 10).names if n not in builtin}
            finally:
                node.destroy_node()
            listed = _flatten(params['/**/%s' % name]['ros__parameters'])
            assert set(listed) == set(declared), name
            for key, value in listed.items():
                assert type(value) is type(declared[key]), (name, key, value)
                if key != 'robot_file':
                    assert value == declared[key], (name, key, 'file and default differ')
    finally:
        rclpy.try_shutdown(context=context)


def _flatten(mapping, prefix=''):
    flat = {}
    for key, value in mapping.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, prefix + key + '.'))
        else:
            flat[prefix + key] = value
    return flat


def test_launch_description_builds_where_launch_ros_is_installed():
    pytest.importorskip('launch_ros')
    spec = importlib.util.spec_from_file_location('continuum_robot_launch', LAUNCH_FILE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    from launch_ros.actions import Node
    nodes = [e for e in description.entities if isinstance(e, Node)]
    assert len(nodes) == 3
