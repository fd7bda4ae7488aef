"""``python -m continuum_statics solve``: the shape of a robot from the command line.

Without cable inputs: the boundary-value problem of the rod under a tip load (cables slack).
``--tensions``: forward statics under cable tensions (N). ``--cable-lengths``: the shape
estimated from measured cable lengths (m), as the statics node does (with ``--tensions`` too when
the tensions are measured). ``--plot FILE.png`` draws the backbone in 3-D.
``--estimate-load``: the tip force (and with ``--moment`` the moment) that explains the measured
``--cable-lengths`` / ``--tensions`` / ``--tip-position`` (:meth:`Robot.estimate_tip_wrench`),
with its standard deviations and the directions the measurements do not see; ``--load`` the
load model (``weight``: a payload's mass along gravity, printed in g; ``force``; ``wrench``;
``direction DX DY DZ``: the force's size along a known direction).
``--obstacles FILE``: obstacles (a YAML list, or a mapping with an ``obstacles:`` list, as in a
robot file) instead of the robot file's; the body rests on them and the contacts are printed.
"""
import argparse
import json
import sys
import time

import yaml

from continuum_statics import ConvergenceError, load_robot
from continuum_statics.core.description.obstacles import parse_obstacles
from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.core.statics.contact import ContactError


def solve_main(argv=None):
    """Solve for a robot file and print the tip pose (the whole shape with --json)."""
    parser = argparse.ArgumentParser(
        prog='python -m continuum_statics solve',
        description='Shape of a continuum robot under a tip force and moment (Cosserat rod), '
                    'optionally with cable tensions or measured cable lengths.')
    parser.add_argument('--robot', required=True, help='robot file (YAML)')
    parser.add_argument('--tip-force', nargs=3, type=float, default=[0.0, 0.0, 0.0],
                        metavar=('FX', 'FY', 'FZ'), help='tip force, base frame (N)')
    parser.add_argument('--tip-moment', nargs=3, type=float, default=[0.0, 0.0, 0.0],
                        metavar=('MX', 'MY', 'MZ'), help='tip moment, base frame (N m)')
    parser.add_argument('--tensions', nargs='+', type=float, default=None, metavar='T',
                        help='cable tensions (N, >= 0), one per cable in robot-file order')
    parser.add_argument('--cable-lengths', nargs='+', type=float, default=None, metavar='L',
                        help='measured cable lengths (m), one per cable in robot-file order')
    parser.add_argument('--estimate-load', action='store_true',
                        help='estimate the tip load from the measurements given instead '
                        '(--cable-lengths, --tensions, --tip-position)')
    parser.add_argument('--tip-position', nargs=3, type=float, default=None,
                        metavar=('X', 'Y', 'Z'), help='measured tip position (the tracked '
                        'point, tip_marker), base frame (m); with --estimate-load')
    parser.add_argument('--moment', action='store_true',
                        help='with --estimate-load: estimate the tip moment too (= --load '
                        'wrench)')
    parser.add_argument('--load', nargs='+', default=None, metavar='MODEL',
                        help='with --estimate-load: the load model, weight (a payload: its '
                        'mass along gravity), force (default), wrench, or direction DX DY DZ '
                        '(the force along a known direction, base frame)')
    parser.add_argument('--noise', nargs=2, action='append', default=[],
                        metavar=('KIND', 'SIGMA'), help='with --estimate-load: a measurement '
                        'standard deviation, KIND one of length (m), tension (N, or P%%), '
                        'tip_position (m), tip_angle (rad); repeatable')
    parser.add_argument('--plot', default=None, metavar='FILE.png',
                        help='draw the backbone in 3-D into this PNG')
    parser.add_argument('--obstacles', default=None, metavar='FILE',
                        help="obstacles (YAML, the robot file's obstacles: form) the body rests "
                             "on, instead of the robot file's; the contacts are printed")
    parser.add_argument('--json', action='store_true', help='print the whole shape as JSON')
    args = parser.parse_args(argv)
    estimate = None
    try:
        robot = load_robot(args.robot)
        for warning in robot.description.warnings:
            print('warning: %s' % warning, file=sys.stderr)
        for name, values in (('--tensions', args.tensions),
                             ('--cable-lengths', args.cable_lengths)):
            if values is not None and len(values) != len(robot.cable_names):
                raise ValueError('%s needs %d values, one per cable (%s), got %d' % (
                    name, len(robot.cable_names), ', '.join(robot.cable_names) or 'none',
                    len(values)))
        if args.estimate_load:
            if any(args.tip_force) or any(args.tip_moment) or args.plot:
                raise ValueError('--tip-force, --tip-moment and --plot do not go with '
                                 '--estimate-load: the tip load is what it estimates')
            return _estimate_load(args, robot)
        if args.tip_position is not None or args.moment or args.noise or args.load:
            raise ValueError('--tip-position, --moment, --load and --noise go with '
                             '--estimate-load')
        obstacles = _obstacles(args.obstacles, robot)
        start = time.perf_counter()
        if args.cable_lengths is not None:
            extra = {} if args.tensions is None else {'tensions': args.tensions}
            estimate = robot.estimate_shape(args.cable_lengths, tip_force=args.tip_force,
                                            tip_moment=args.tip_moment, obstacles=obstacles,
                                            **extra)
            shape = estimate.shape
        elif args.tensions is not None or obstacles:
            tensions = args.tensions or [0.0] * len(robot.cable_names)  # slack: solve_bvp's
            shape = robot.solve_tensions(tensions, tip_force=args.tip_force,
                                         tip_moment=args.tip_moment, obstacles=obstacles)
        else:
            shape = robot.solve_bvp(tip_force=args.tip_force, tip_moment=args.tip_moment)
        elapsed = time.perf_counter() - start
    except (ValueError, ConvergenceError, ContactError) as error:
        print('error: %s' % error, file=sys.stderr)
        return 1
    if args.plot:
        _plot(args, robot, shape)
    contacts = [{'obstacle': c.obstacle, 's': c.s, 'point': c.point.tolist(),
                 'normal': c.normal.tolist(), 'force': c.force} for c in shape.contacts]
    quaternion = rotation_to_quaternion(shape.tip_rotation)
    if args.json:
        result = {'robot': robot.name, 'frame_id': robot.base_frame_id,
                  'tip_position': shape.tip_position.tolist(),
                  'tip_quaternion_xyzw': quaternion.tolist(),
                  'cable_lengths': robot.cable_lengths(shape).tolist(),
                  'shape': shape.to_dict(), 'contacts': contacts}
        if estimate is not None:
            result['estimate'] = {'converged': bool(estimate.converged),
                                  'residual_m': float(estimate.residual),
                                  'iterations': int(estimate.iterations),
                                  'message': estimate.message}
        if args.plot:
            result['plot'] = args.plot
        print(json.dumps(result))
        return 0
    x, y, z = shape.tip_position
    print('robot %s, frame %s, tip force %s N, tip moment %s N m'
          % (robot.name, robot.base_frame_id, args.tip_force, args.tip_moment))
    print('tip position    [m]  x=%+.6f y=%+.6f z=%+.6f' % (x, y, z))
    print('tip orientation xyzw %+.6f %+.6f %+.6f %+.6f' % tuple(quaternion))
    print('base bending u(0) [1/m] %+.5f %+.5f %+.5f   solved in %.2f ms'
          % (*shape.u0, elapsed * 1e3))
    if robot.cable_names:
        print('cable lengths   [m]  %s' % '  '.join(
            '%s=%.6f' % item for item in zip(robot.cable_names, robot.cable_lengths(shape))))
    for c in contacts:
        print('contact with %-12s s=%.4f m  point %s m  normal %s  force %.4g N' % (
            repr(c['obstacle']), c['s'], _triple(c['point']), _triple(c['normal']), c['force']))
    if estimate is not None:
        print('estimate: %s, cable length residual %.3g m, %d iterations%s' % (
            _estimate_status(estimate), estimate.residual, estimate.iterations,
            (': ' + estimate.message) if estimate.message else ''))
    if args.plot:
        print('backbone drawn in %s' % args.plot)
    return 0


def _obstacles(path, robot):
    """``--obstacles FILE`` parsed (None without it: the robot file's obstacles)."""
    if path is None:
        return None
    try:
        with open(path, encoding='utf-8') as stream:
            data = yaml.safe_load(stream)
    except (OSError, yaml.YAMLError) as error:
        raise ValueError('--obstacles %s: %s' % (path, error)) from None
    if isinstance(data, dict):
        data = data.get('obstacles')
    return robot.obstacles_or_file(parse_obstacles(data, '%s: obstacles' % path))


def _noise_value(kind, value):
    """One ``--noise KIND SIGMA``: a number, or P% for tension."""
    if value.strip().endswith('%') and kind == 'tension':
        return value
    try:
        return float(value)
    except ValueError:
        raise ValueError('--noise %s %s: SIGMA must be a number in %s (a percentage P%% only '
                         'for tension)' % (kind, value, {'length': 'm', 'tension': 'N',
                                                          'tip_position': 'm',
                                                          'tip_angle': 'rad'}.get(kind, 'SI')))


def _estimate_load(args, robot):
    """``--estimate-load``: print the tip wrench, its sigma and what the measurements miss."""
    noise = {kind: _noise_value(kind, value) for kind, value in args.noise}
    load = _load_model(args.load)
    start = time.perf_counter()
    estimate = robot.estimate_tip_wrench(lengths=args.cable_lengths, tensions=args.tensions,
                                         tip_position=args.tip_position, noise=noise,
                                         moment=args.moment, load=load)
    elapsed = time.perf_counter() - start
    sigma = estimate.sigma
    with_moment = len(sigma) == 6
    if args.json:
        print(json.dumps({
            'robot': robot.name, 'frame_id': robot.base_frame_id,
            'load': estimate.load.name, 'mass': estimate.mass, 'mass_sigma': estimate.mass_sigma,
            'force_n': estimate.force.tolist(), 'force_sigma_n': sigma[:3].tolist(),
            'moment_nm': estimate.moment.tolist(),
            'moment_sigma_nm': sigma[3:].tolist() if with_moment else None,
            'covariance': estimate.covariance.tolist(),
            'unseen_directions': estimate.unseen.tolist(), 'converged': estimate.converged,
            'chi2': estimate.chi2, 'iterations': estimate.iterations,
            'tip_position': estimate.shape.tip_position.tolist(),
            'message': estimate.message, 'elapsed_ms': elapsed * 1e3}))
        return 0 if estimate.converged else 1
    print('robot %s, frame %s: tip load estimated in %.1f ms (%d iterations)%s' % (
        robot.name, robot.base_frame_id, elapsed * 1e3, estimate.iterations,
        '' if estimate.converged else ', NOT converged'))
    if estimate.mass is not None:
        print('mass   [g]    %.4g   sigma %.3g   (a payload along gravity)' % (
            1e3 * estimate.mass, 1e3 * estimate.mass_sigma))
    print('force  [N]    %s   sigma %s' % (_triple(estimate.force), _triple(sigma[:3])))
    if with_moment:
        print('moment [N m]  %s   sigma %s' % (_triple(estimate.moment), _triple(sigma[3:])))
    print('chi2 per measurement %.3g%s' % (estimate.chi2, (
        '\n' + estimate.message) if estimate.message else ''))
    return 0 if estimate.converged else 1


def _load_model(words):
    """``--load MODEL [DX DY DZ]`` -> the ``load`` argument of estimate_tip_wrench."""
    if not words:
        return None
    name, rest = words[0], words[1:]
    if name == 'direction':
        try:
            direction = [float(v) for v in rest]
        except ValueError:
            direction = []
        if len(direction) != 3:
            raise ValueError('--load direction needs three numbers DX DY DZ (base frame), '
                             'got %s' % (' '.join(rest) or 'none'))
        return ('direction', tuple(direction))
    if name not in ('weight', 'force', 'wrench') or rest:
        raise ValueError('--load must be weight, force, wrench or direction DX DY DZ, got %s'
                         % ' '.join(words))
    return name


def _triple(values):
    return ' '.join('%+.4g' % v for v in values)


def _estimate_status(estimate):
    """Return one status: a converged best fit of inconsistent lengths is not an exact shape."""
    if not estimate.converged:
        return 'NOT converged'
    return 'best fit (no exact shape)' if 'fit no shape' in estimate.message else 'converged'


def _plot(args, robot, shape):
    from continuum_statics.tools.plot import plot_backbones

    loads = 'tip force %s N' % ' '.join('%g' % f for f in args.tip_force)
    if args.tensions is not None:
        loads += ', tensions %s N' % ' '.join('%g' % t for t in args.tensions)
    if args.cable_lengths is not None:
        loads = 'from cable lengths, ' + loads
    plot_backbones(args.plot, [(loads, shape.positions)], frame_id=robot.base_frame_id,
                   title='%s: backbone' % robot.name)
