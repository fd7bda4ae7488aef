"""package.xml and the pip requirements agree, with rosdep keys that exist in rosdistro.

``rosdep install --from-paths src`` on a robot computer resolves package.xml; the pip route
installs requirements.txt. Every runtime requirement must be declared with its rosdep key, and
every key must be one rosdistro has (``python3-canopen`` is not: ``canopen-pip`` is).
"""
import re
import xml.etree.ElementTree as ElementTree

from conftest import REPO

#: pip requirement -> rosdep key (rosdistro rosdep/python.yaml and base.yaml; ROS packages by name)
ROSDEP_KEYS = {
    'numpy': 'python3-numpy',
    'scipy': 'python3-scipy',
    'numba': 'python3-numba',
    'PyYAML': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'rosbags': 'python3-rosbags-pip',
    'dynamixel-sdk': 'dynamixel_sdk',
    'canopen': 'canopen-pip',
    'python-can': 'python3-can',
    'pytest': 'python3-pytest',
}
#: Development tools of the pip route only (lint, fuzzing, bag tests, the dynamics benchmark's
#: PyElastica baseline): not needed on a robot.
DEVELOPMENT_ONLY = {'hypothesis', 'ruff', 'mcap', 'mcap-ros2-support', 'playwright', 'sphinx',
                    'myst-parser', 'sphinx-rtd-theme', 'sphinx-mathjax-offline', 'colcon-core',
                    'colcon-ros', 'colcon-cmake', 'colcon-python-setup-py', 'urdf-parser-py',
                    'pyelastica', 'pytest-xdist'}
#: Optional on a robot computer (no rosdep key exists): `pip install viser` for `view`.
OPTIONAL_PIP = {'viser'}
#: ROS wheels that are the middleware, not a package dependency.
MIDDLEWARE = {'rmw-fastrtps-cpp'}
#: Keys that are no rosdep key (seen failing `rosdep install`).
NOT_KEYS = {'python3-canopen', 'python3-rosbags', 'python3-dynamixel-sdk'}


def requirements(name='requirements.txt'):
    names = []
    for line in (REPO / name).read_text().splitlines():
        line = line.split('#')[0].strip()
        if line:
            names.append(re.split(r'[<>=!~ ;\[]', line, maxsplit=1)[0])
    return names


def manifest_keys(path=REPO / 'package.xml'):
    root = ElementTree.parse(path).getroot()
    return {element.text.strip() for tag in ('depend', 'exec_depend', 'test_depend',
                                             'build_depend', 'buildtool_depend')
            for element in root.iter(tag)}


#: The interfaces package: its build tools come as wheels on the pip route too.
INTERFACES = REPO / 'continuum_statics_interfaces' / 'package.xml'
#: Wheels its build needs that its package.xml reaches through ament_cmake / the generators.
INTERFACES_BUILD = {'ament-cmake-include-directories', 'ament-cmake-ros', 'python-cmake-module',
                    'ament-package', 'rosidl-core-generators', 'ament-cmake-gmock',
                    'ament-cmake-ros-core',
                    'ament-cmake-gtest', 'ament-cmake-pytest'}


def test_every_requirement_is_declared_in_package_xml_with_its_rosdep_key():
    keys = manifest_keys() | manifest_keys(INTERFACES)
    missing = []
    for name in requirements():
        if name.startswith('ros-'):
            package = name[4:].replace('-', '_')
            if name[4:] not in MIDDLEWARE | INTERFACES_BUILD and package not in keys:
                missing.append('%s (ROS package %s)' % (name, package))
        elif name in DEVELOPMENT_ONLY | OPTIONAL_PIP or name == 'catkin_pkg':
            continue
        elif ROSDEP_KEYS.get(name) not in keys:
            missing.append('%s (rosdep key %s)' % (name, ROSDEP_KEYS.get(name, 'unknown')))
    assert not missing, 'requirements.txt lines without a package.xml dependency: %s' % missing


def test_package_xml_declares_no_key_the_requirements_do_not_have():
    keys = manifest_keys()
    assert not keys & NOT_KEYS, keys & NOT_KEYS
    python_keys = {key for key in keys if key.startswith('python3-') or key.endswith('-pip')
                   or key == 'dynamixel_sdk'}
    assert python_keys <= set(ROSDEP_KEYS.values()), python_keys - set(ROSDEP_KEYS.values())
    declared = {ROSDEP_KEYS[name] for name in requirements() if name in ROSDEP_KEYS}
    assert python_keys <= declared, python_keys - declared


def test_the_interfaces_package_is_an_ament_cmake_interface_package_the_node_depends_on():
    root = ElementTree.parse(INTERFACES).getroot()
    assert root.findtext('name') == 'continuum_statics_interfaces'
    assert root.findtext('export/build_type') == 'ament_cmake'
    assert root.findtext('member_of_group') == 'rosidl_interface_packages'
    assert 'continuum_statics_interfaces' in manifest_keys()
    action = (REPO / 'continuum_statics_interfaces' / 'action' / 'MoveTip.action').read_text()
    assert [part.split('#')[0].split() for part in action.split('---')[0].splitlines()
            if part.split('#')[0].strip()] == [
        ['geometry_msgs/PoseStamped', 'target'], ['bool', 'use_direction'],
        ['float64', 'tolerance']]
    message = (REPO / 'continuum_statics_interfaces' / 'msg' / 'BackboneEstimate.msg').read_text()
    assert [line.split('#')[0].split() for line in message.splitlines()
            if line.split('#')[0].strip()] == [
        ['std_msgs/Header', 'header'], ['float64[]', 's'], ['geometry_msgs/Pose[]', 'poses'],
        ['float64[]', 'position_covariance']]
    assert {'std_msgs', 'geometry_msgs'} <= {
        d.text for d in root.findall('depend')}


def test_tf2_msgs_is_declared_and_the_vendored_copy_is_the_upstream_message():
    """The manifest brings tf2_msgs and tf2_ros; the vendored TFMessage is never colcon-built."""
    assert {'tf2_msgs', 'tf2_ros'} <= manifest_keys()
    vendor = REPO / 'vendor'
    assert (vendor / 'COLCON_IGNORE').is_file()
    root = ElementTree.parse(vendor / 'tf2_msgs' / 'package.xml').getroot()
    assert root.findtext('name') == 'tf2_msgs'
    assert (vendor / 'tf2_msgs' / 'msg' / 'TFMessage.msg').read_text().split() == [
        'geometry_msgs/TransformStamped[]', 'transforms']
