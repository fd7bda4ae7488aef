"""``python -m continuum_statics simulate``: the robot in motion, before it moves on hardware.

``--release``: the rod held under a tip force (``--force``, N) is let go at t = 0.
``--step CABLE DL``: one motor steps by DL (m, + pays out) at t = 0 (real tendons).
``--commands BAG``: the ``cable_commands`` of a recording (rosbag2 directory or .mcap) replayed.
Motors follow their targets as the simulated driver's (a first-order lag, ``--motor-bandwidth``
Hz, and ``--max-speed`` m/s). Prints the tip's settling time, overshoot and first frequencies
(the spectrum's peaks); ``--plot`` draws the tip against time, ``--json`` prints it all.
"""
import argparse
import json
import math
import sys
import time

import numpy as np

from continuum_statics import load_robot
from continuum_statics.core.dynamics.response import overshoot, settling_time, spectrum_peaks
from continuum_statics.drivers.sim import SimulatedCableBackend


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
    targets = motors.copy()
    if step is not None:
        targets[step[0]] += step[1]
    steps = int(round(duration / sim.dt))
    times, tips, tensions, failed = [0.0], [sim.state.tip_position.copy()], [sim.state.tensions], 0
    lengths = [motors.copy()]
    began = time.perf_counter()
    for i in range(steps):
        t = (i + 1) * sim.dt
        if commands is not None:
            row = np.searchsorted(commands[0], t, side='right') - 1
            if row >= 0:
                targets = commands[1][row]
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
            'alpha': sim.alpha, 'segments': sim.segments}


def summary(result):
    """Return the response's figures: settling time, overshoot, frequencies, pace."""
    times, tips = result['time'], result['tip']
    settle = settling_time(times, tips)
    return {
        'duration_s': float(times[-1]), 'dt_s': result['dt'], 'alpha': result['alpha'],
        'steps': len(times) - 1, 'failed_steps': result['failed_steps'],
        'real_time_factor': float(times[-1] / max(result['compute_s'], 1e-9)),
        'shooting_segments': result['segments'],
        'tip_start_m': tips[0].tolist(), 'tip_final_m': tips[-1].tolist(),
        'move_mm': float(1e3 * np.linalg.norm(tips[-1] - tips[0])),
        'settling_time_s': settle, 'overshoot_percent': overshoot(tips),
        'frequencies_hz': spectrum_peaks(times, tips),
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


def plot(result, path):
    """Draw the tip (x, y, z relative to its start, mm) against time into a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    figure, axes = plt.subplots(figsize=(8, 4.5))
    for axis, name in enumerate('xyz'):
        axes.plot(result['time'], 1e3 * (result['tip'][:, axis] - result['tip'][0, axis]),
                  label=name)
    axes.set_xlabel('time (s)')
    axes.set_ylabel('tip from its start (mm)')
    axes.legend()
    axes.grid(True, alpha=0.3)
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv=None):
    """Run ``simulate`` (see the module docstring); returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics simulate',
                                     description=__doc__.split('\n')[0])
    parser.add_argument('--robot', required=True, help='robot file (YAML)')
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument('--release', action='store_true',
                      help='let go of the rod held under --force at t = 0')
    what.add_argument('--step', nargs=2, metavar=('CABLE', 'DL'),
                      help='step one motor by DL m (+ pays out) at t = 0')
    what.add_argument('--commands', metavar='BAG', help="replay a recording's cable_commands")
    parser.add_argument('--force', nargs=3, type=float, metavar=('FX', 'FY', 'FZ'),
                        help='tip force held before --release, N (default: a tenth of the '
                        "rod's plausible load, sideways)")
    parser.add_argument('--duration', type=float, default=2.0, help='simulated s (2)')
    parser.add_argument('--dt', type=float, default=None, help="time step, s (robot file's)")
    parser.add_argument('--alpha', type=float, default=None, help="BDF-alpha (robot file's)")
    parser.add_argument('--motor-bandwidth', type=float, default=8.0,
                        help="Hz of the motors (first-order; 8: the sim driver's 0.02 s)")
    parser.add_argument('--max-speed', type=float, default=0.05, help='motor speed, m/s')
    parser.add_argument('--tip-mass', type=float, default=0.0, help='payload, kg')
    parser.add_argument('--plot', metavar='PNG', help='draw the tip against time')
    parser.add_argument('--json', action='store_true', help='print JSON (with the trajectory)')
    args = parser.parse_args(argv)
    try:
        robot = load_robot(args.robot)
        step = commands = force = None
        if args.release:
            from continuum_statics.core.estimation.load_estimation import plausible_tip_load
            force = (np.array(args.force) if args.force is not None
                     else np.array([0.1 * plausible_tip_load(robot)[0], 0.0, 0.0]))
        elif args.step:
            cable, dl = args.step[0], float(args.step[1])
            if cable not in robot.cable_names:
                raise ValueError('--step: no cable %r (cables: %s)'
                                 % (cable, ', '.join(robot.cable_names)))
            step = (list(robot.cable_names).index(cable), dl)
        else:
            commands = read_commands(args.commands, robot)
        if not args.duration > 0.0:
            raise ValueError('--duration must be > 0 s')
        result = run(robot, args.duration, force, step, commands, args.dt, args.alpha,
                     args.motor_bandwidth, args.max_speed, args.tip_mass)
    except (ValueError, NotImplementedError) as error:
        print('simulate: %s' % error, file=sys.stderr)
        return 2
    figures = summary(result)
    if args.plot:
        plot(result, args.plot)
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
          % (figures['move_mm'], 'not within the run' if settle is None else '%.3f s' % settle,
             figures['overshoot_percent'],
             ', '.join('%.2f' % f for f in figures['frequencies_hz']) or 'none'))
    return 0


if __name__ == '__main__':
    sys.exit(main())
