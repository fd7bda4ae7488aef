"""bringup: the statics, tip_controller and cable_driver nodes in one process.

``python -m continuum_statics bringup [--robot FILE] [--driver sim] [--namespace NS]
[--load-estimator auto|on|off] [--ros-args ...]`` (also the ``bringup`` console script).
Everything after ``--ros-args`` goes to rclpy (``--params-file``, remaps, ``-p`` parameters, log
levels). ``--robot`` and ``--driver`` override the ``robot_file`` and ``backend`` parameters of
every node; without them the nodes use their parameters (default: the tendon robot in
``config/`` and the simulated driver). Ctrl-C (SIGINT) or SIGTERM stops everything and exits
with code 0. ``--load-estimator`` adds the
tip_load_estimator node: ``auto`` (default) for a robot file with a tendon model, whose cable
tensions the simulated driver reports (ideal cables alone give it nothing that sees a load);
never for a robot file with ``load_model`` (statics estimates that load with the shape).

On a robot computer with ROS installed, ``launch/continuum_robot.launch.py`` starts the same
three nodes as separate processes.
"""
import argparse
import os
import sys

USAGE_EPILOG = ('Arguments after --ros-args go to ROS, e.g. --ros-args --params-file '
                'config/continuum_robot.params.yaml -r cable_states:=measured_lengths')


def parse_args(argv):
    """Split ``argv`` into bringup options and the ROS arguments (from ``--ros-args`` on)."""
    argv = list(argv)
    ros_args = []
    if '--ros-args' in argv:
        split = argv.index('--ros-args')
        argv, ros_args = argv[:split], argv[split:]
    parser = argparse.ArgumentParser(prog='python -m continuum_statics bringup',
                                     description=__doc__.splitlines()[0], epilog=USAGE_EPILOG)
    parser.add_argument('--robot', help='robot description YAML (default: the robot_file '
                        'parameter, i.e. config/tendon_robot.yaml)')
    parser.add_argument('--driver', help='cable backend (default: the backend parameter, sim)')
    parser.add_argument('--namespace', default='continuum',
                        help='namespace of the nodes (default: %(default)s)')
    parser.add_argument('--load-estimator', choices=('auto', 'on', 'off'), default='auto',
                        help='also run tip_load_estimator: auto = when the robot file has a '
                        'tendon model (default: %(default)s)')
    return parser.parse_args(argv), ros_args


def wants_load_estimator(choice, robot=None):
    """Whether bringup runs tip_load_estimator (``auto``: the robot has a tendon model).

    Never for a robot file with ``load_model``: statics estimates that load with the shape and
    publishes ``tip_wrench_estimate`` and ``tip_contact`` itself.
    """
    if choice == 'off':
        return False
    from continuum_statics.config_paths import default_robot_file, load_robot_file
    try:
        model = load_robot_file(robot or default_robot_file())
    except ValueError:
        return choice == 'on'  # the nodes report the bad file themselves
    if model.load_model is not None:
        if choice == 'on':
            print('bringup: the robot file names load_model: statics publishes '
                  'tip_wrench_estimate and tip_contact; tip_load_estimator is not started',
                  file=sys.stderr)
        return False
    return choice == 'on' or (bool(model.cable_names) and not model.tendons.is_ideal)


def node_factories(robot=None, driver=None, namespace='continuum', load_estimator=False):
    """Return callables creating the nodes with the bringup overrides applied."""
    from functools import partial

    from rclpy.parameter import Parameter

    from continuum_statics.nodes.cable_driver_node import CableDriverNode
    from continuum_statics.nodes.statics_node import StaticsNode
    from continuum_statics.nodes.tip_controller_node import TipControllerNode

    common = []
    if robot is not None:
        common.append(Parameter('robot_file', Parameter.Type.STRING, os.path.abspath(robot)))
    driver_overrides = list(common)
    if driver is not None:
        driver_overrides.append(Parameter('backend', Parameter.Type.STRING, driver))
    factories = [
        partial(StaticsNode, namespace=namespace, parameter_overrides=common),
        partial(TipControllerNode, namespace=namespace, parameter_overrides=common),
        partial(CableDriverNode, namespace=namespace, parameter_overrides=driver_overrides),
    ]
    if load_estimator:
        from continuum_statics.nodes.tip_load_estimator_node import TipLoadEstimatorNode
        factories.append(partial(TipLoadEstimatorNode, namespace=namespace,
                                 parameter_overrides=common))
    return factories


def main(argv=None):
    """Run bringup; returns the process exit code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    options, ros_args = parse_args(argv)
    if options.robot is not None and not os.path.isfile(options.robot):
        print('bringup: robot file %r does not exist' % options.robot, file=sys.stderr)
        return 2
    from continuum_statics.nodes.node_runner import run_nodes
    factories = node_factories(options.robot, options.driver, options.namespace.strip() or '/',
                               wants_load_estimator(options.load_estimator, options.robot))
    return run_nodes(factories, args=['bringup'] + ros_args)


if __name__ == '__main__':
    sys.exit(main())
