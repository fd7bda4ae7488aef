"""Start statics, tip_controller and cable_driver on a robot computer (ROS 2 Jazzy or Kilted).

``ros2 launch continuum_statics continuum_robot.launch.py [robot_file:=FILE] [driver:=sim]
[namespace:=continuum] [params_file:=FILE] [rviz:=true] [load_estimator:=true]``

Each node runs as its own process from the package's executables; all read ``params_file``
(default: the package's ``config/continuum_robot.params.yaml``), then ``robot_file`` and, for the
driver, ``driver`` override the file. ``rviz:=true`` also starts rviz2 (install
``ros-<distro>-rviz2``) in the same namespace with the package's ``config/continuum_robot.rviz``
(backbone Path, tip pose, markers; fixed frame base_link). ``load_estimator:=true`` also starts
tip_load_estimator (the tip load from cable tensions and a tracker; off by default: a robot
with ideal cables and no tracker gives it nothing that sees a load). Without ROS installed,
``python -m continuum_statics bringup`` starts the same nodes in one process.
"""
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.launch_description import LaunchDescription
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

PACKAGE = 'continuum_statics'
EXECUTABLES = ('statics', 'tip_controller', 'cable_driver')
ESTIMATOR = 'tip_load_estimator'
CONFIG_FILES = ('tendon_robot.yaml', 'continuum_robot.params.yaml', 'continuum_robot.rviz')


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
        DeclareLaunchArgument('rviz', default_value='false',
                              description='true: also start rviz2 (continuum_robot.rviz)'),
        DeclareLaunchArgument('load_estimator', default_value='false',
                              description='true: also start tip_load_estimator'),
    ]
    nodes = []
    for executable in EXECUTABLES:
        overrides = {'robot_file': robot_file}
        if executable == 'cable_driver':
            overrides['backend'] = driver
        nodes.append(Node(package=PACKAGE, executable=executable, name=executable,
                          namespace=namespace, parameters=[params_file, overrides],
                          output='screen', emulate_tty=True))
    nodes.append(Node(package=PACKAGE, executable=ESTIMATOR, name=ESTIMATOR,
                      namespace=namespace, parameters=[params_file, {'robot_file': robot_file}],
                      condition=IfCondition(LaunchConfiguration('load_estimator')),
                      output='screen', emulate_tty=True))
    nodes.append(Node(package='rviz2', executable='rviz2', name='rviz2', namespace=namespace,
                      arguments=['-d', PathJoinSubstitution([config, CONFIG_FILES[2]])],
                      condition=IfCondition(LaunchConfiguration('rviz')), output='screen'))
    return LaunchDescription(arguments + nodes)
