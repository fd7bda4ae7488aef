"""``python -m continuum_statics simulate``: the robot in motion, before it moves on hardware.

``--release``: the rod held under a tip force (``--force``, N) is let go at t = 0.
``--step CABLE DL``: one motor steps by DL (m, + pays out) at t = 0 (real tendons).
``--commands BAG``: the ``cable_commands`` of a recording (rosbag2 directory or .mcap) replayed.
Motors follow their targets as the simulated driver's (a first-order lag, ``--motor-bandwidth``
Hz, and ``--max-speed`` m/s). Prints the tip's settling time, overshoot and first frequencies
(the spectrum's peaks); ``--plot`` draws the tip against time, ``--json`` prints it all.
Every option is checked before the run (exit code 2 with the reason): numbers, the payload
against the rod, a step against the length limits, the plot's folder and the run's length.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

from continuum_statics import load_robot
from continuum_statics.core.description.robot_file import check_dynamics
from continuum_statics.core.dynamics.response import (
    final_value,
    overshoot,
    settling_time,
    spectrum_peaks,
)
from continuum_statics.core.estimation.load_estimation import plausible_tip_load
from continuum_statics.drivers.sim import SimulatedCableBackend, implausible_load

#: most time steps a run may take: 20-30 s of computing at the benchmarks' 70-150 us a step,
#: and a record (tip, tensions, motors every step) of some 100 MB; beyond it a typo
#: (``--duration 1e9``, ``--dt 1e-9``) would run until killed
MAX_STEPS = 200_000
#: what ``--plot`` can write (matplotlib picks the format by the suffix)
PLOT_SUFFIXES = ('.png', '.pdf', '.svg')


def run(robot, duration, release_force=None, step=None, commands=None, dt=None, alpha=None,
        motor_bandwidth=8.0, max_speed=0.05, tip_mass=0.0):
    """Simulate; return {'time', 'tip', 'tensions', 'motors', 'failed_steps', ...}.

    ``step`` is (cable index, dl m); ``commands`` (times (T,) s, targets (T, n) m), held
    between samples. Real tendons are driven by the motors' lengths, ideal cables (release
    only) by zero tensions.
    """
    sim = robot.dynamics(dt=dt, alpha=alpha, tip_mass=tip_mass)
    n = len(robot.cable_names)
    by_lengths = not robot.tendons.is_ideal
    if (step is not None or commands is not None) and not by_lengths:
        raise ValueError('--step and --commands move motors: robot %r has ideal cables (no '
                         'tendons block); --release works' % robot.name)
    motors = robot.straight_cable_lengths.copy()
    force = np.zeros(3) if release_force is None else np.asarray(release_force, dtype=float)
    if by_lengths:
        sim.start(lengths=motors, tip_force=force)
    else:
        sim.start(tensions=np.zeros(n), tip_force=force)
    time_constant = 1.0 / (2.0 * math.pi * motor_bandwidth)
    low, high = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2).T
    targets = motors.copy()
    if step is not None:
        targets[step[0]] += step[1]
    targets = np.clip(targets, low, high)  # the driver's backend clips as well
    clipped = 0  # commands outside the length limits, clipped
    steps = int(round(duration / sim.dt))
    times, tips, tensions, failed = [0.0], [sim.state.tip_position.copy()], [sim.state.tensions], 0
    lengths = [motors.copy()]
    last_row = -1
    began = time.perf_counter()
    for i in range(steps):
        t = (i + 1) * sim.dt
        if commands is not None:
            row = np.searchsorted(commands[0], t, side='right') - 1
            if row >= 0 and row != last_row:
                targets = np.clip(commands[1][row], low, high)
                clipped += bool(np.any(targets != commands[1][row]))
                last_row = row
        if by_lengths:
            motors = SimulatedCableBackend.step(motors, targets, sim.dt, time_constant,
                                                max_speed)
            state = sim.step(lengths=motors)
        else:
            state = sim.step(tensions=np.zeros(n))
        failed += not state.converged
        times.append(t)
        tips.append(state.tip_position.copy())
        tensions.append(state.tensions)
        lengths.append(motors.copy())
    return {'time': np.array(times), 'tip': np.array(tips), 'tensions': np.array(tensions),
            'motors': np.array(lengths),
            'failed_steps': failed, 'compute_s': time.perf_counter() - began, 'dt': sim.dt,
            'alpha': sim.alpha, 'segments': sim.segments, 'clipped_commands': clipped}


def summary(result):
    """Return the response's figures: settling time (None: not settled), overshoot, pace."""
    times, tips = result['time'], result['tip']
    final = final_value(tips)  # the centre a run cut short swings about, not its last sample
    settle = settling_time(times, tips, final)
    return {
        'duration_s': float(times[-1]), 'dt_s': result['dt'], 'alpha': result['alpha'],
        'steps': len(times) - 1, 'failed_steps': result['failed_steps'],
        'real_time_factor': float(times[-1] / max(result['compute_s'], 1e-9)),
        'shooting_segments': result['segments'],
        'tip_start_m': tips[0].tolist(), 'tip_final_m': final.tolist(),
        'tip_end_m': tips[-1].tolist(), 'move_mm': float(1e3 * np.linalg.norm(final - tips[0])),
        'settling_time_s': settle, 'overshoot_percent': overshoot(tips, final),
        'frequencies_hz': spectrum_peaks(times, tips),
        'clipped_commands': result.get('clipped_commands', 0),
    }


def read_commands(bag, robot):
    """Return (times (T,) s from the first, targets (T, n) m) of the ``cable_commands``."""
    from continuum_statics.calibration.bag_reading import open_bag, pick_connections

    reader = open_bag(bag)
    try:
        connections = pick_connections(reader.connections, 'cable_commands',
                                       'sensor_msgs/msg/JointState')
        if not connections:
            raise ValueError('%s has no cable_commands (sensor_msgs/JointState)' % bag)
        names = list(robot.cable_names)
        targets = robot.straight_cable_lengths.copy()
        times, rows = [], []
        for connection, stamp, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            for name, position in zip(msg.name, msg.position):
                if name in names and math.isfinite(position):
                    targets[names.index(name)] = position
            times.append(stamp * 1e-9)
            rows.append(targets.copy())
    finally:
        reader.close()
    times = np.array(times)
    return times - times[0], np.array(rows)


def plot(result, path, title):
    """Draw the tip (x, y, z relative to its start, mm) against time into ``path`` (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 4.5))
    for axis, name in enumerate('xyz'):
        axes.plot(result['time'], 1e3 * (result['tip'][:, axis] - result['tip'][0, axis]),
                  label=name)
    axes.set_title(title)
    axes.set_xlabel('time (s)')
    axes.set_ylabel('tip from its start (mm)')
    axes.legend()
    axes.grid(True, alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def _number(low=None, above=None, finite=True):
    """Return an argparse type: a float >= ``low`` or > ``above``; finite unless told not."""
    def parse(text):
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError('not a number: %r' % text) from None
        wanted = ['finite'] if finite else []
        wanted += [] if low is None else ['>= %g' % low]
        wanted += [] if above is None else ['> %g' % above]
        wanted = wanted or ['a number']
        if (math.isnan(value) or (finite and not math.isfinite(value))
                or (low is not None and not value >= low)
                or (above is not None and not value > above)):
            raise argparse.ArgumentTypeError('must be %s, got %s' % (' and '.join(wanted), text))
        return value
    return parse


def _check_plot(parser, path):
    """Refuse, before the run, a plot that could not be written; return its absolute path."""
    path = os.path.abspath(path)
    folder = os.path.dirname(path)
    if not path.lower().endswith(PLOT_SUFFIXES):
        parser.error('--plot %s: the name must end in %s' % (path, ', '.join(PLOT_SUFFIXES)))
    if not os.path.isdir(folder):
        parser.error('--plot %s: no folder %s' % (path, folder))
    if not os.access(folder, os.W_OK):
        parser.error('--plot %s: folder %s is not writable' % (path, folder))
    return path


def _what(args, robot, step, force):
    """Return the run in words (the plot's title)."""
    if args.release:
        what = 'release from %.3g N' % np.linalg.norm(force)
    elif step is not None:
        what = 'step %s %+g mm' % (args.step[0], 1e3 * step[1])
    else:
        what = 'cable_commands of %s' % os.path.basename(os.path.normpath(args.commands))
    payload = ', payload %g kg' % args.tip_mass if args.tip_mass else ''
    return 'robot %s: %s%s' % (robot.name, what, payload)


def main(argv=None):
    """Run ``simulate`` (see the module docstring); returns the exit code (2: bad input)."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics simulate',
                                     description=__doc__.split('\n')[0])
    parser.add_argument('--robot', required=True, help='robot file (YAML)')
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument('--release', action='store_true',
                      help='let go of the rod held under --force at t = 0')
    what.add_argument('--step', nargs=2, metavar=('CABLE', 'DL'),
                      help='step one motor by DL m (+ pays out) at t = 0, within the length '
                      'limits')
    what.add_argument('--commands', metavar='BAG', help="replay a recording's cable_commands")
    parser.add_argument('--force', nargs=3, type=_number(), metavar=('FX', 'FY', 'FZ'),
                        help='tip force held before --release, N (default: a tenth of the '
                        "rod's plausible load, sideways)")
    parser.add_argument('--duration', type=_number(above=0.0), default=2.0,
                        help='simulated s (2)')
    parser.add_argument('--dt', type=_number(above=0.0), default=None,
                        help="time step, s (robot file's)")
    parser.add_argument('--alpha', type=_number(), default=None,
                        help="BDF-alpha in [-0.45, 0] (robot file's)")
    parser.add_argument('--motor-bandwidth', type=_number(above=0.0), default=8.0,
                        help="Hz of the motors (first-order; 8: the sim driver's 0.02 s)")
    parser.add_argument('--max-speed', type=_number(above=0.0, finite=False), default=0.05,
                        help='motor speed, m/s (inf: no limit)')
    parser.add_argument('--tip-mass', type=_number(low=0.0), default=0.0,
                        help="payload, kg (its weight within the rod's plausible load)")
    parser.add_argument('--plot', metavar='PNG', help='draw the tip against time (.png, .pdf, '
                        '.svg) into an existing folder')
    parser.add_argument('--json', action='store_true', help='print JSON (with the trajectory)')
    args = parser.parse_args(argv)
    if args.force is not None and not args.release:
        parser.error('--force is the load held before --release')
    plot_path = _check_plot(parser, args.plot) if args.plot else None
    try:
        robot = load_robot(args.robot)
    except (ValueError, OSError) as error:
        parser.error('--robot %s: %s' % (args.robot, error))
    settings = robot.description.dynamics
    try:
        dt, _ = check_dynamics(settings.dt if args.dt is None else args.dt,
                               settings.alpha if args.alpha is None else args.alpha)
    except ValueError as error:
        parser.error('--dt / --alpha: %s' % error)
    steps = int(round(args.duration / dt))  # as run() counts them
    if steps < 1:
        parser.error('--duration %g s is shorter than one step (dt %g s)' % (args.duration, dt))
    if steps > MAX_STEPS:
        parser.error('--duration %g s at dt %g s is %d steps; the limit is %d (a shorter '
                     'duration or a longer --dt)' % (args.duration, dt, steps, MAX_STEPS))
    step = commands = force = None
    if args.release:
        force = (np.array(args.force) if args.force is not None
                 else np.array([0.1 * plausible_tip_load(robot)[0], 0.0, 0.0]))
    # a payload (and the force held) as the simulated driver checks them: the same bound
    problem = implausible_load(robot, np.concatenate([np.zeros(3) if force is None else force,
                                                      np.zeros(3)]), args.tip_mass,
                               'tip force held before the release')
    if problem:
        parser.error('%s: %s' % ('--tip-mass' if args.tip_mass else '--force', problem))
    if args.step:
        cable, dl = args.step
        if cable not in robot.cable_names:
            parser.error('--step: no cable %r (cables: %s)'
                         % (cable, ', '.join(robot.cable_names)))
        try:
            dl = _number()(dl)
        except argparse.ArgumentTypeError as error:
            parser.error('--step DL: %s' % error)
        index = list(robot.cable_names).index(cable)
        target = robot.straight_cable_lengths[index] + dl
        low, high = np.asarray(robot.cable_length_limits, dtype=float).reshape(-1, 2)[index]
        if not low <= target <= high:
            parser.error("--step %s %g: the target %.4f m is outside the cable's length limits "
                         '[%.4f, %.4f] m (the driver refuses such a command); DL within '
                         '[%.4f, %.4f] m' % (cable, dl, target, low, high,
                                             low - target + dl, high - target + dl))
        step = (index, dl)
    elif args.commands:
        try:
            commands = read_commands(args.commands, robot)
        except (ValueError, OSError) as error:
            parser.error('--commands %s: %s' % (args.commands, error))
    try:
        result = run(robot, args.duration, force, step, commands, args.dt, args.alpha,
                     args.motor_bandwidth, args.max_speed, args.tip_mass)
    except (ValueError, NotImplementedError) as error:
        parser.error(str(error))
    figures = summary(result)
    if plot_path:
        plot(result, plot_path, _what(args, robot, step, force))
        figures['plot'] = plot_path
    if args.json:
        every = max(1, int(round(1e-3 / result['dt'])))  # the trajectory at 1 kHz at most
        figures['time_s'] = result['time'][::every].tolist()
        figures['tip_m'] = result['tip'][::every].tolist()
        figures['tensions_n'] = result['tensions'][::every].tolist()
        print(json.dumps(figures))
        return 0
    settle = figures['settling_time_s']
    print('robot %s: %d steps of %g s (alpha %g), real-time factor %.1f, %d failed'
          % (robot.name, figures['steps'], figures['dt_s'], figures['alpha'],
             figures['real_time_factor'], figures['failed_steps']))
    print('tip moved %.2f mm; settling time %s; overshoot %.1f %%; frequencies %s Hz'
          % (figures['move_mm'], 'not settled within the run' if settle is None
             else '%.3f s' % settle, figures['overshoot_percent'],
             ', '.join('%.2f' % f for f in figures['frequencies_hz']) or 'none'))
    if figures['clipped_commands']:
        print('%d cable_commands outside the length limits were clipped to them, as the '
              "driver's backend clips (the node refuses those beyond its length_margin)"
              % figures['clipped_commands'])
    if plot_path:
        print('plot: %s' % plot_path)
    return 0


if __name__ == '__main__':
    sys.exit(main())
