"""Command line: ``python -m continuum_statics COMMAND ...`` (tools and nodes)."""
import sys

NODES = ('statics', 'tip_controller', 'cable_driver', 'tip_load_estimator')

USAGE = """usage: python -m continuum_statics COMMAND [options]

commands:
  solve     solve the boundary-value problem for a robot file and print the tip pose
  bench     benchmark the numeric core (--nodes: the ROS nodes over DDS)
  bringup   start the statics, tip_controller and cable_driver nodes in one process
            (and tip_load_estimator for a robot with a tendon model)
  statics | tip_controller | cable_driver | tip_load_estimator
            run one node alone, like `ros2 run` (options: --ros-args ...)
  view      the live robot in a web browser (3-D, with a draggable tip goal)
  teleop    drive the tip from the keyboard (tip_twist, in a terminal)
  warmup    compile the kernels into the numba cache (the venv setup does it once)
  demo      bringup with the simulated driver plus a client sending tip goals
  record    record the robot's topics into a rosbag2 directory (MCAP; Ctrl-C to stop)
  plot      PNG figures of a recording (backbone, tip path, cable lengths, solver)
  calibrate fit robot-file parameters (E, base orientation, ...) to measured tip positions
  fusion    what each sensor buys: simulated truth, or a recorded run with the tracker occluded
  simulate  the robot in motion (Cosserat dynamics): a release, a motor step or a recording's
            commands; settling time, overshoot, frequencies
  doctor    check the set-up (domain, nodes, driver, rates, /tf, sensors): what is wrong and
            what to do (--namespace NS)
"""


def main(argv=None):
    """Dispatch to the sub-command's own ``main(argv)``; imports stay lazy (no rclpy for solve)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ('-h', '--help'):
        print(USAGE)
        return 0 if argv else 2
    command, rest = argv[0], argv[1:]
    if command == 'solve':
        from continuum_statics.tools.solve import solve_main as run
    elif command == 'bench':
        if '--nodes' in rest:
            rest.remove('--nodes')
            from continuum_statics.tools.node_bench import main as run
        else:
            from continuum_statics.tools.bench import main as run
    elif command == 'bringup':
        from continuum_statics.nodes.bringup import main as run
    elif command in NODES:  # one node alone, like `ros2 run continuum_statics <node>`
        import importlib
        node_main = importlib.import_module('continuum_statics.nodes.%s_node' % command).main
        return node_main([command] + rest)
    elif command == 'view':
        from continuum_statics.tools.view import main as run
    elif command == 'teleop':
        from continuum_statics.tools.teleop import main as run
    elif command == 'warmup':
        from continuum_statics.tools.warmup import main as run
    elif command == 'demo':
        from continuum_statics.tools.demo import main as run
    elif command == 'record':
        from continuum_statics.tools.record import main as run
    elif command == 'plot':
        from continuum_statics.tools.plot import main as run
    elif command == 'simulate':
        from continuum_statics.tools.simulate import main as run
    elif command == 'calibrate':
        from continuum_statics.tools.calibrate import main as run
    elif command == 'fusion':
        from continuum_statics.tools.fusion import main as run
    elif command == 'doctor':
        from continuum_statics.tools.doctor import main as run
    else:
        print('unknown command %r\n\n%s' % (command, USAGE), file=sys.stderr)
        return 2
    return run(rest)


if __name__ == '__main__':
    sys.exit(main())
