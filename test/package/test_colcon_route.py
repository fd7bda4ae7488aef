"""Issue 37: the robot-computer route, built by colcon as a lab builds it.

A colcon workspace with a copy of the repository's tracked files as ``src/continuum_statics``;
``colcon build`` (colcon-core, colcon-ros, colcon-cmake from pip) builds both packages against the
venv's ROS wheels. Then the install space has what the documentation says (console scripts under
``lib/continuum_statics/``, launch, config and package.xml under ``share/``, the ament index
entries, the interfaces' Python package and type support), and ``statics``, ``tip_controller``
and ``cable_driver`` start from it, each a process, and reach a tip goal over DDS. The launch file
is read from the install space and its node parameters checked against the nodes' tables
(``launch_ros`` is not installable here, so it is not run).

colcon does not descend into a package's directory, and this repository's root *is* the
continuum_statics package: the interfaces package beside it is found only when its path is given
too (``--base-paths src src/continuum_statics/continuum_statics_interfaces``, as doc/install.md
says). The first test shows that.
"""
import ast
import hashlib
import os
from pathlib import Path
import shutil
import subprocess
import sys
import time
import uuid

from conftest import REPO
from nodes_helpers import client_node, pose_xyz, stop_process
import numpy as np
import pytest

from continuum_statics import load_robot

pytestmark = pytest.mark.ros  # starts DDS or a process

pytest.importorskip('colcon_core')
pytest.importorskip('colcon_ros')
pytest.importorskip('colcon_cmake')
rclpy = pytest.importorskip('rclpy')
if shutil.which('cmake') is None:
    pytest.skip('cmake is not on the PATH', allow_module_level=True)

VENV = Path(sys.prefix)
PACKAGE = 'continuum_statics'
INTERFACES = 'continuum_statics_interfaces'
SCRIPTS = ('statics', 'tip_controller', 'cable_driver', 'tip_load_estimator', 'bringup')
BASE_PATHS = ['src', 'src/continuum_statics/continuum_statics_interfaces']


def colcon(workspace, *base_paths):
    env = dict(os.environ, CMAKE_PREFIX_PATH=str(VENV), AMENT_PREFIX_PATH=str(VENV),
               PATH='%s:%s' % (VENV / 'bin', os.environ.get('PATH', '')))
    return subprocess.run(
        [str(VENV / 'bin' / 'colcon'), 'build', '--base-paths', *base_paths,
         '--event-handlers', 'console_direct-', '--cmake-args',
         '-DPython3_EXECUTABLE=%s' % sys.executable, '-DBUILD_TESTING=OFF'],
        cwd=workspace, env=env, capture_output=True, text=True, timeout=900)


def clone(workspace):
    """Copy the repository's tracked files (what a fresh clone has) into src/continuum_statics."""
    names = subprocess.run(['git', 'ls-files', '-z'], cwd=REPO, capture_output=True,
                           check=True).stdout.decode().split('\0')
    target = workspace / 'src' / PACKAGE
    for name in filter(None, names):
        source = REPO / name
        if source.is_file():
            (target / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target / name)
    return target


def kernel_cache(directory, root):
    """Return where numba caches the kernels of the modules in ``directory``.

    numba.core.caching: ``__pycache__`` beside the sources, or under ``NUMBA_CACHE_DIR``
    (``root``) the sources' directory name and the SHA-1 of its absolute path.
    """
    if not root:
        return directory / '__pycache__'
    path = os.path.abspath(directory)
    return Path(root) / '_'.join((os.path.basename(path), hashlib.sha1(path.encode()).hexdigest()))


def sourced_environment(install):
    """Return the environment after ``. install/setup.sh`` (what ``ros2 run`` sees)."""
    output = subprocess.run(['sh', '-c', '. "%s/setup.sh" && env -0' % install],
                            capture_output=True, check=True,
                            env=dict(os.environ, COLCON_CURRENT_PREFIX=str(install))).stdout
    return dict(line.split('=', 1) for line in output.decode().split('\0') if '=' in line)


@pytest.fixture(scope='module')
def workspace(tmp_path_factory):
    workspace = tmp_path_factory.mktemp('colcon_ws')
    clone(workspace)
    started = time.monotonic()
    build = colcon(workspace, *BASE_PATHS)
    assert build.returncode == 0, build.stdout[-4000:] + build.stderr[-4000:]
    print('colcon build of both packages: %.1f s' % (time.monotonic() - started))
    return workspace


def test_colcon_finds_only_the_root_package_without_the_interfaces_path(tmp_path):
    for page in ('README.md', 'doc/install.md'):  # the commands a lab copies give both paths
        text = (REPO / page).read_text()
        assert 'colcon build --base-paths %s' % ' '.join(BASE_PATHS) in text, page
        assert 'rosdep install --from-paths %s --ignore-src' % ' '.join(BASE_PATHS) in text
    clone(tmp_path)
    build = colcon(tmp_path, 'src')
    assert build.returncode == 0, build.stderr[-2000:]
    assert sorted(p.name for p in (tmp_path / 'install').iterdir() if p.is_dir()) == [PACKAGE]


def test_install_space_has_what_the_documentation_says(workspace):
    install = workspace / 'install'
    prefix = install / PACKAGE
    for script in SCRIPTS:
        path = prefix / 'lib' / PACKAGE / script
        assert path.is_file() and os.access(path, os.X_OK), path
    share = prefix / 'share' / PACKAGE
    assert (share / 'package.xml').read_text() == (REPO / 'package.xml').read_text()
    assert (share / 'launch' / 'continuum_robot.launch.py').is_file()
    shipped = {p.name for p in (REPO / 'config').iterdir()
               if p.suffix in ('.yaml', '.xml', '.rviz', '.json')}
    assert shipped <= {p.name for p in (share / 'config').iterdir()}
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE).is_file()
    interfaces = install / INTERFACES
    index = interfaces / 'share' / 'ament_index' / 'resource_index'
    assert (index / 'packages' / INTERFACES).is_file()
    assert 'action/MoveTip.action' in (index / 'rosidl_interfaces' / INTERFACES).read_text()
    assert 'msg/BackboneEstimate.msg' in (index / 'rosidl_interfaces' / INTERFACES).read_text()
    assert list((interfaces / 'lib').glob('lib%s__rosidl_typesupport_*.so' % INTERFACES))
    assert list(interfaces.rglob('%s/action/_move_tip.py' % INTERFACES))


def test_sourced_install_space_imports_from_itself(workspace):
    install = workspace / 'install'
    env = sourced_environment(install)
    code = ('import continuum_statics, continuum_statics_interfaces\n'
            'from continuum_statics_interfaces.action import MoveTip\n'
            'from rclpy.serialization import serialize_message\n'
            'from continuum_statics.config_paths import share_dir\n'
            'serialize_message(MoveTip.Feedback(distance=1.5))\n'
            'print(continuum_statics.__file__)\n'
            'print(continuum_statics_interfaces.__file__)\n'
            'print(share_dir())\n')
    # cwd: not the repository, whose continuum_statics/ python -c would import first
    run = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True,
                         text=True, timeout=120, cwd=workspace)
    assert run.returncode == 0, run.stderr
    package, interfaces, share = run.stdout.split()
    assert package.startswith(str(install / PACKAGE)), package
    assert interfaces.startswith(str(install / INTERFACES)), interfaces
    assert share == str(install / PACKAGE / 'share' / PACKAGE)


def _launch_nodes(tree):
    """Yield (executable, parameter override keys) of each launch_ros Node of the package."""
    for call in ast.walk(tree):
        if isinstance(call, ast.Call) and getattr(call.func, 'id', '') == 'Node':
            keywords = {k.arg: k.value for k in call.keywords}
            if ast.unparse(keywords['package']) == 'PACKAGE':
                yield keywords['executable'], keywords['parameters']


def test_installed_launch_file_arguments_match_the_nodes_parameters(workspace):
    from continuum_statics.nodes import parameter_tables

    launch = workspace / 'install' / PACKAGE / 'share' / PACKAGE / 'launch' / \
        'continuum_robot.launch.py'
    tree = ast.parse(launch.read_text())
    declared = {ast.literal_eval(call.args[0]) for call in ast.walk(tree)
                if isinstance(call, ast.Call)
                and getattr(call.func, 'id', '') == 'DeclareLaunchArgument'}
    assert declared == {'robot_file', 'driver', 'namespace', 'params_file', 'rviz',
                        'load_estimator'}
    # the overrides the launch file gives each node are parameters that node declares
    source = launch.read_text()
    assert "overrides = {'robot_file': robot_file}" in source
    assert "overrides['backend'] = driver" in source
    for node in ('statics', 'tip_controller', 'cable_driver', 'tip_load_estimator'):
        names = {spec.name for spec in getattr(parameter_tables, '%s_parameters' % node)()}
        assert 'robot_file' in names, node
    driver = {spec.name for spec in parameter_tables.cable_driver_parameters()}
    assert 'backend' in driver
    nodes = list(_launch_nodes(tree))
    assert len(nodes) == 2  # the three in a loop over EXECUTABLES, and the estimator
    # every executable it names is a console script in the install space
    executables = ast.literal_eval(next(
        n.value for n in ast.walk(tree) if isinstance(n, ast.Assign)
        and getattr(n.targets[0], 'id', '') == 'EXECUTABLES'))
    for executable in executables + ('tip_load_estimator',):
        assert (workspace / 'install' / PACKAGE / 'lib' / PACKAGE / executable).is_file()


def test_nodes_start_from_the_install_space_and_reach_a_goal(workspace):
    from nav_msgs.srv import GetPlan

    install = workspace / 'install'
    env = sourced_environment(install)
    lib = install / PACKAGE / 'lib' / PACKAGE
    # The kernels this tree compiled (make venv, conftest) serve the installed copies of the same
    # sources (numba keys a kernel by its source's content hash); without them the warm-up
    # compiles every kernel (100-150 s of a loaded CI worker).
    installed = next((install / PACKAGE / 'lib').glob('python*/site-packages')) / PACKAGE
    if os.environ.get('NUMBA_CACHE_DIR'):  # the installed copies' kernels in a cache of their own
        env['NUMBA_CACHE_DIR'] = str(workspace / 'numba_cache')
    for source in {path.parent for path in (REPO / PACKAGE).rglob('*.py')}:
        target = kernel_cache(installed / source.relative_to(REPO / PACKAGE),
                              env.get('NUMBA_CACHE_DIR'))
        for cached in kernel_cache(source, os.environ.get('NUMBA_CACHE_DIR')).glob('*.nb[ic]'):
            target.mkdir(parents=True, exist_ok=True)
            shutil.copy2(cached, target / cached.name)
    warm = subprocess.run([sys.executable, '-c', 'import continuum_statics as c; print(c.__file__)'
                           '; from continuum_statics.tools.warmup import main; main([])'],
                          env=env, capture_output=True, text=True, timeout=600, cwd=workspace)
    assert warm.stdout.startswith(str(install / PACKAGE)), warm.stdout
    assert warm.returncode == 0, warm.stdout + warm.stderr
    namespace = 'colcon_' + uuid.uuid4().hex[:8]
    processes = [subprocess.Popen([str(lib / name), '--ros-args', '-r', '__ns:=/' + namespace],
                                  env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  text=True, cwd=workspace)
                 for name in ('cable_driver', 'statics', 'tip_controller')]
    context, executor, client = client_node('colcon_route_client', namespace)
    try:
        service = client.create_client(GetPlan, 'tip_goal')

        def spin_until(predicate, timeout, what):
            deadline = time.monotonic() + timeout
            while not predicate():
                for process in processes:
                    assert process.poll() is None, 'a node exited: %s' % process.stdout.read()
                assert time.monotonic() < deadline, 'timed out after %g s: %s' % (timeout,
                                                                                 what)
                executor.spin_once(timeout_sec=0.05)

        spin_until(service.service_is_ready, 120.0, 'the tip_goal service')
        robot = load_robot(REPO / 'config' / 'tendon_robot.yaml')
        goal = robot.solve_ivp([-1.5, 2.0, 0.0]).tip_position
        request = GetPlan.Request(tolerance=1e-3)
        request.goal.header.frame_id = robot.base_frame_id
        position = request.goal.pose.position
        position.x, position.y, position.z = (float(v) for v in goal)
        future = service.call_async(request)
        spin_until(future.done, 120.0, 'the answer to a reachable goal')
        plan = future.result().plan
        assert len(plan.poses) > 0, 'goal not reached'
        assert np.linalg.norm(pose_xyz(plan.poses[-1].pose) - goal) <= 1e-3
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.try_shutdown(context=context)
        codes = [stop_process(process) for process in reversed(processes)]
    assert codes == [0, 0, 0], codes
