"""The two test routes (Kilted: requirements.txt, Jazzy: requirements-jazzy.txt) stay in step."""
from conftest import REPO


def requirement_lines(name):
    lines = (REPO / name).read_text().splitlines()
    return [line.split('#')[0].strip() for line in lines if line.split('#')[0].strip()]


def split(name):
    lines = requirement_lines(name)
    ros = {line.split('==')[0]: line.split('==')[1] for line in lines if line.startswith('ros-')}
    return ros, [line for line in lines if not line.startswith('ros-')]


KILTED_ONLY = {'ros-ament-cmake-ros-core'}


def test_jazzy_route_differs_only_in_the_ros_pins():
    kilted_ros, kilted_other = split('requirements.txt')
    jazzy_ros, jazzy_other = split('requirements-jazzy.txt')
    assert jazzy_other == kilted_other
    # Kilted split ament_cmake_ros_core out of ament_cmake_ros (the interfaces' build needs it)
    assert set(jazzy_ros) == set(kilted_ros) - KILTED_ONLY
    assert jazzy_ros['ros-rclpy'] == '7.1.6' and jazzy_ros['ros-rmw-fastrtps-cpp'] == '8.4.3'
    # common_interfaces (action_msgs belongs to rcl_interfaces, versioned apart)
    messages = {name: version for name, version in jazzy_ros.items() if (
        name.endswith('-msgs') and name != 'ros-action-msgs') or name.endswith('-srvs')}
    assert messages and set(messages.values()) == {'5.3.6'}


def test_ci_runs_both_routes():
    ci = (REPO / '.ci' / 'run').read_text()
    assert 'make test\n' in ci and 'make test-jazzy' in ci
    makefile = (REPO / 'Makefile').read_text()
    assert 'REQUIREMENTS=requirements-jazzy.txt' in makefile and '.venv-jazzy' in makefile
