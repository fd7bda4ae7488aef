"""``python -m continuum_statics solve``: the boundary-value problem from the command line."""
import argparse
import json
import sys
import time

from continuum_statics import ConvergenceError, load_robot
from continuum_statics.core.rotations import rotation_to_quaternion


def solve_main(argv=None):
    """Solve the BVP for a robot file and print the tip pose (the whole shape with --json)."""
    parser = argparse.ArgumentParser(
        prog='python -m continuum_statics solve',
        description='Shape of a continuum robot under a tip force and moment (Cosserat BVP).')
    parser.add_argument('--robot', required=True, help='robot file (YAML)')
    parser.add_argument('--tip-force', nargs=3, type=float, default=[0.0, 0.0, 0.0],
                        metavar=('FX', 'FY', 'FZ'), help='tip force, base frame (N)')
    parser.add_argument('--tip-moment', nargs=3, type=float, default=[0.0, 0.0, 0.0],
                        metavar=('MX', 'MY', 'MZ'), help='tip moment, base frame (N m)')
    parser.add_argument('--json', action='store_true', help='print the whole shape as JSON')
    args = parser.parse_args(argv)
    try:
        robot = load_robot(args.robot)
        start = time.perf_counter()
        shape = robot.solve_bvp(tip_force=args.tip_force, tip_moment=args.tip_moment)
        elapsed = time.perf_counter() - start
    except (ValueError, ConvergenceError) as error:
        print('error: %s' % error, file=sys.stderr)
        return 1
    quaternion = rotation_to_quaternion(shape.tip_rotation)
    if args.json:
        print(json.dumps({'robot': robot.name, 'frame_id': robot.base_frame_id,
                          'tip_position': shape.tip_position.tolist(),
                          'tip_quaternion_xyzw': quaternion.tolist(),
                          'shape': shape.to_dict()}))
        return 0
    x, y, z = shape.tip_position
    print('robot %s, frame %s, tip force %s N, tip moment %s N m'
          % (robot.name, robot.base_frame_id, args.tip_force, args.tip_moment))
    print('tip position    [m]  x=%+.6f y=%+.6f z=%+.6f' % (x, y, z))
    print('tip orientation xyzw %+.6f %+.6f %+.6f %+.6f' % tuple(quaternion))
    print('base bending u(0) [1/m] %+.5f %+.5f %+.5f   solved in %.2f ms'
          % (*shape.u0, elapsed * 1e3))
    return 0
