"""Start statics, tip_controller and cable_driver on a robot computer (ROS 2 Jazzy or Kilted).

``ros2 launch continuum_statics continuum_robot.launch.py [robot_file:=FILE] [driver:=sim]
[namespace:=continuum] [params_file:=FILE]``

Each node runs as its own process from the package's executables; all read ``params_file``
(default: the package's ``config/continuum_robot.params.yaml``), then ``robot_file`` and, for the
driver, ``driver`` override the file. Without ROS installed, ``python -m continuum_statics
bringup`` starts the same nodes in one process.
"""
from launch.actions import DeclareLaunchArgument
from launch.launch_description import LaunchDescription
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'continuum_statics'
EXECUTABLES = ('statics', 'tip_controller', 'cable_driver')
CONFIG_FILES = ('tendon_robot.yaml', 'continuum_robot.params.yaml')


def generate_launch_description():
    """Return the launch description: three nodes in one namespace."""
    config = PathJoinSubstitution([FindPackageShare(PACKAGE), 'config'])
    robot_file = LaunchConfiguration('robot_file')
    driver = LaunchConfiguration('driver')
    namespace = LaunchConfiguration('namespace')
    params_file = LaunchConfiguration('params_file')
    arguments = [
        DeclareLaunchArgument('robot_file',
                              default_value=PathJoinSubstitution([config, CONFIG_FILES[0]]),
                              description='robot description YAML (rod, cables, guides)'),
        DeclareLaunchArgument('driver', default_value='sim',
                              description='cable backend: sim, an entry point or module:Class'),
        DeclareLaunchArgument('namespace', default_value='continuum',
                              description='namespace of the three nodes'),
        DeclareLaunchArgument('params_file',
                              default_value=PathJoinSubstitution([config, CONFIG_FILES[1]]),
                              description='node parameters (ros__parameters layout)'),
    ]
    nodes = []
    for executable in EXECUTABLES:
        overrides = {'robot_file': robot_file}
        if executable == 'cable_driver':
            overrides['backend'] = driver
        nodes.append(Node(package=PACKAGE, executable=executable, name=executable,
                          namespace=namespace, parameters=[params_file, overrides],
                          output='screen', emulate_tty=True))
    return LaunchDescription(arguments + nodes)
