"""Dynamixel backend benchmark against the Protocol 2.0 emulator on a simulated 1 Mbps wire.

``make bench-drivers``. For 4 and 9 servos: (1) the sync-write + sync-read cycle of the backend
(``command`` then ``read``, as cable_driver does every tick) with the emulator in another process,
next to the wire time the bytes alone need; (2) the highest cable_driver ``publish_rate`` that
holds (the node's own publish count reaches 95 % of the rate over a window). The emulator is a
test fixture (``test/emulators``), so this runs from a source checkout.
"""
import argparse
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BYTE_TIME_S = 10e-6  # 1 Mbps, 10 bits per byte
PRESENT_BYTES = 10  # Present Current, Velocity, Position


def wire_time(servos, return_delay_us):
    """Bytes on the wire for one sync write + one sync read of ``servos`` servos, in s."""
    sync_write = 14 + 5 * servos
    sync_read = 14 + servos
    status = 11 + PRESENT_BYTES
    return (sync_write + sync_read + status * servos) * BYTE_TIME_S + \
        servos * return_delay_us * 1e-6


def start_emulator(ids, link, return_delay_us):
    """Start the emulator process; return it once it serves ``link``."""
    emulator_dir = REPO / 'test'
    if not (emulator_dir / 'emulators' / 'dynamixel_bus.py').is_file():
        raise SystemExit('driver_bench: needs the source checkout (test/emulators) next to '
                         'the package')
    process = subprocess.Popen(
        [sys.executable, '-m', 'emulators.dynamixel_bus', '--ids', *map(str, ids), '--link',
         str(link), '--baudrate', '1000000', '--return-delay-us', str(return_delay_us),
         '--max-speed', '1e6'], cwd=emulator_dir, stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, text=True)
    line = process.stdout.readline()
    if not line.startswith('ready'):
        process.kill()
        raise SystemExit('driver_bench: the emulator did not start')
    return process


def stop_emulator(process):
    """Ask the emulator to quit, then make sure it is gone."""
    try:
        process.stdin.write('quit\n')
        process.stdin.flush()
        process.wait(5.0)
    except (OSError, subprocess.TimeoutExpired):
        process.kill()
        process.wait()


def backend_for(servos, link):
    """Return a started dynamixel backend for ``servos`` cables on ``link``."""
    from continuum_statics.drivers.dynamixel import DynamixelCableBackend

    names = ['cable_%d' % i for i in range(servos)]
    backend = DynamixelCableBackend(names, [[0.27, 0.33]] * servos, [0.30] * servos,
                                    port=str(link), baudrate=1000000,
                                    ids=list(range(1, servos + 1)), spool_radius=0.01,
                                    zero_ticks=[0])
    backend.start(time.monotonic())
    return backend


def cycle_times(servos, cycles, return_delay_us, workdir):
    """Durations (s) of ``cycles`` command+read cycles, retried sync reads, lost cycles."""
    from continuum_statics.drivers import ConnectionLost

    link = Path(workdir) / ('tty_%d_%d' % (servos, return_delay_us))
    emulator = start_emulator(range(1, servos + 1), link, return_delay_us)
    try:
        backend = backend_for(servos, link)
        durations = []
        targets = np.full(servos, 0.30)
        lost = 0
        for k in range(cycles):
            targets[:] = 0.30 + 0.01 * np.sin(0.01 * k)
            started = time.perf_counter()
            try:
                backend.command(targets, time.monotonic())
                backend.read(time.monotonic())
            except ConnectionLost:  # a status packet missed twice (a stalled machine)
                lost += 1
                for _ in range(10):
                    try:
                        backend.start(time.monotonic())
                        break
                    except ConnectionLost:
                        time.sleep(0.1)
                continue
            durations.append(time.perf_counter() - started)
        retries = backend.retries
        backend.close()
        return np.array(durations), retries, lost
    finally:
        stop_emulator(emulator)


def highest_rate(servos, rates, window, workdir):
    """Highest publish_rate (Hz) whose achieved rate is >= 95 % of it, and every figure."""
    import rclpy
    from rclpy.parameter import Parameter

    from continuum_statics.nodes.cable_driver_node import CableDriverNode

    link = Path(workdir) / ('tty_node_%d' % servos)
    emulator = start_emulator(range(1, servos + 1), link, 0)
    robot = Path(workdir) / ('robot_%d.yaml' % servos)
    robot.write_text(_robot_file(servos))
    context = rclpy.Context()
    rclpy.init(context=context)
    figures, best = [], 0.0
    try:
        node = CableDriverNode(context=context, parameter_overrides=[
            Parameter('robot_file', value=str(robot)),
            Parameter('backend', value='dynamixel'),
            Parameter('dynamixel.port', value=str(link)),
            Parameter('dynamixel.baudrate', value=1000000),
            Parameter('dynamixel.ids', value=list(range(1, servos + 1))),
            Parameter('dynamixel.zero_ticks', value=[0]),
            Parameter('command_timeout', value=0.0)])
        try:
            for rate in rates:
                node.set_parameters([Parameter('publish_rate', value=float(rate))])
                time.sleep(0.3)  # settle on the new rate
                before, started = node.health.rate.total, time.monotonic()
                time.sleep(window)
                achieved = (node.health.rate.total - before) / (time.monotonic() - started)
                figures.append((rate, achieved))
                if achieved >= 0.95 * rate:
                    best = max(best, rate)
        finally:
            node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
        stop_emulator(emulator)
    return best, figures


def _robot_file(servos):
    """Return a one-section robot file with ``servos`` cables (for the node benchmark)."""
    cables = '\n'.join(
        '  - {name: cable_%d, offset: [%.6f, %.6f, 0.0], length_limits: [0.27, 0.33]}' % (
            i, 0.01 * np.cos(2 * np.pi * i / servos), 0.01 * np.sin(2 * np.pi * i / servos))
        for i in range(servos))
    guides = ', '.join('%.2f' % (0.03 * k) for k in range(1, 11))
    return ('name: bench_%d_cables\nrod: {length: 0.30, diameter: 1.4e-3, youngs_modulus: '
            '54.0e9, poisson_ratio: 0.3, density: 6450.0}\nbase: {frame_id: base_link, '
            'position: [0, 0, 0], orientation: [0, 0, 0, 1]}\ngravity: [0, 0, -9.81]\n'
            'guides: [%s]\ncables:\n%s\n' % (servos, guides, cables))


def main(argv=None):
    """Print the cycle figures and the highest publish rate for each servo count."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--servos', type=int, nargs='+', default=[4, 9])
    parser.add_argument('--cycles', type=int, default=1000)
    parser.add_argument('--rates', type=float, nargs='+',
                        default=[100, 200, 300, 400, 500, 600, 800, 1000])
    parser.add_argument('--window', type=float, default=2.0, help='s per rate')
    parser.add_argument('--no-node', action='store_true', help='skip the publish_rate sweep')
    args = parser.parse_args(argv)
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    with tempfile.TemporaryDirectory() as workdir:
        print('sync write (Goal Position) + sync read (current, velocity, position), '
              'simulated 1 Mbps wire, emulator in another process')
        print('%7s %9s %8s %10s %8s %8s %8s %5s' % (
            'servos', 'delay us', 'wire ms', 'median ms', 'p99 ms', 'max ms', 'retries', 'lost'))
        for servos in args.servos:
            for delay in (0, 500):
                times, retries, lost = cycle_times(servos, args.cycles, delay, workdir)
                times = times * 1e3
                print('%7d %9d %8.2f %10.2f %8.2f %8.2f %8d %5d' % (
                    servos, delay, wire_time(servos, delay) * 1e3, np.median(times),
                    np.percentile(times, 99), times.max(), retries, lost))
        if args.no_node:
            return 0
        print('\ncable_driver publish_rate sweep (Return Delay Time 0; holds = >= 95 %)')
        for servos in args.servos:
            best, figures = highest_rate(servos, args.rates, args.window, workdir)
            print('%d servos: %s -> highest publish_rate that holds: %g Hz' % (
                servos, ', '.join('%g->%.0f' % f for f in figures), best))
    return 0


if __name__ == '__main__':
    sys.exit(main())
