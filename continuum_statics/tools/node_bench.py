"""``python -m continuum_statics bench --nodes``: the ROS nodes measured over DDS.

1. Starts the statics node as its own process, publishes ``cable_states`` from this process at
   ``--rate`` (1 kHz) for ``--duration`` (10 s) and receives ``backbone`` as serialized bytes (the
   stamp is read straight from the CDR header, so the receiver adds no deserialization time).
   Reported: processed rate, dropped messages, stamp-to-``backbone`` latency (median, p99, max)
   and the CPU used by the statics process.
2. Starts the full bringup (simulated driver) and calls ``tip_goal`` for a few reachable goals and
   one unreachable goal: reported round trip per goal.

Figures go to stdout; the exit code is 0 when the runs completed (targets are reported, not
asserted: performance belongs in benchmarks, not in pass/fail tests).
"""
import argparse
import os
import struct
import subprocess
import sys
import threading
import time

import numpy as np

from continuum_statics.config_paths import default_robot_file
from continuum_statics.tools.processes import cpu_seconds, ros_environment, stop


def measurement_lengths(robot, count, rate):
    """Cable lengths of equilibria circling at 0.5 Hz: realistic, always solvable.

    Every section's cables bend it by 2 1/m in a direction turning at 0.5 Hz (robot equilibria
    of any robot file, solved along the way with :meth:`Robot.equilibrium_between`).
    """
    lengths, previous = [], None
    for i in range(count):
        angle = 2.0 * np.pi * 0.5 * i / rate
        state = robot.passive_state()
        for first, rank in zip(robot.section_state_index, robot.section_ranks):
            if rank == 2:
                state[first:first + 2] = 2.0 * np.array([np.cos(angle), np.sin(angle)])
        target = robot.make_shape(state, np.zeros(3), robot.integrate_state(state, np.zeros(3)))
        previous = robot.equilibrium_between(target, target, 0.0, warm_start=previous)
        lengths.append(previous.cable_lengths.tolist())
    return lengths


def noisy_lengths(sigma, seed=0):
    """Return a lengths source: :func:`measurement_lengths` plus seeded Gaussian noise (m)."""
    def source(robot, count, rate):
        exact = np.array(measurement_lengths(robot, count, rate))
        noise = np.random.default_rng(seed).normal(0.0, sigma, exact.shape)
        return (exact + noise).tolist()
    return source


def bench_statics(robot_file, rate, duration, warmup=2.0, parameters=(),
                  lengths_source=None):
    """Publish cable_states at ``rate`` to a statics process; return the figures as a dict."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Path
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
    from sensor_msgs.msg import JointState

    from continuum_statics import load_robot
    from continuum_statics.nodes.dedicated_intake import DedicatedIntake
    from continuum_statics.nodes.ros_conversions import seconds_to_stamp

    robot = load_robot(robot_file)
    period_count = int(round(rate * 2.0))  # two seconds of distinct lengths, then repeat
    lengths = (lengths_source or measurement_lengths)(robot, period_count, rate)
    namespace = '/bench_statics'
    received = []  # (stamp s, receive time s)
    record = [False]
    window = {}

    totals = {}

    def on_diagnostics(msg):
        for status in msg.status:
            if status.name.endswith('bench_statics/statics'):
                values = {kv.key: kv.value for kv in status.values}
                totals[time.time()] = tuple(int(values.get(key, -1)) for key in (
                    'received_total', 'published_total', 'input_skipped_total',
                    'input_lost_total'))

    def on_backbone(data):
        now = time.time()
        if record[0]:
            sec, nanosec = struct.unpack_from('<iI', data, 4)
            received.append((sec + nanosec * 1e-9, now))

    process = subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics.nodes.statics_node', '--ros-args',
         '-r', '__ns:=' + namespace, '-p', 'robot_file:=' + robot_file,
         '--log-level', 'warn'] + [arg for p in parameters for arg in ('-p', p)])
    context = rclpy.Context()
    rclpy.init(context=context)
    node = intake = executor = None
    try:
        node = rclpy.create_node('bench_statics_client', namespace=namespace, context=context)
        publisher = node.create_publisher(JointState, 'cable_states', qos_profile_sensor_data)
        # Received as bytes in a thread of its own: the client must not be the bottleneck.
        intake = DedicatedIntake(node, 'bench_intake')
        intake.add(Path, 'backbone', on_backbone,
                   QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE), raw=True)
        intake.start()
        node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        spinner = threading.Thread(target=_spin_until_shutdown, args=(executor,), daemon=True)
        spinner.start()
        deadline = time.monotonic() + 60.0
        while publisher.get_subscription_count() < 1 or node.count_publishers(
                namespace + '/backbone') < 1:
            if process.poll() is not None:
                raise RuntimeError('the statics process exited with %s' % process.returncode)
            if time.monotonic() > deadline:
                raise RuntimeError('statics did not connect within 60 s')
            time.sleep(0.05)
        msg = JointState(name=list(robot.cable_names))
        start = time.monotonic()
        sent = 0
        send_times = []
        last = -1.0
        for i in range(int(round((warmup + duration) * rate))):
            # On schedule, but never closer than 0.75 periods after the previous message: a
            # late wake-up must not turn into a burst (a real driver does not burst either).
            delay = max(start + i / rate, last + 0.75 / rate) - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            last = time.monotonic()
            if i == int(warmup * rate):
                window.update(start=time.time(), cpu=cpu_seconds(process.pid),
                              own_cpu=cpu_seconds(os.getpid()))
                record[0], sent = True, 0
            msg.header.stamp = seconds_to_stamp(time.time())
            msg.position = lengths[i % period_count]
            publisher.publish(msg)
            sent += 1
            send_times.append(last)
        window.update(end=time.time(), cpu_end=cpu_seconds(process.pid),
                      own_cpu_end=cpu_seconds(os.getpid()))
        time.sleep(0.5)  # let the last backbones arrive
        record[0] = False
        deadline = time.monotonic() + 3.0  # statics reports its totals once a second
        while time.monotonic() < deadline and not any(t > window['end'] + 0.5 for t in totals):
            time.sleep(0.05)
    finally:
        if intake is not None:
            intake.stop()
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        stop(process)
    elapsed = window['end'] - window['start']
    stamps = np.array([r[0] for r in received if r[0] >= window['start']])
    latencies = np.array([r[1] - r[0] for r in received if r[0] >= window['start']]) * 1e3
    empty = latencies.size == 0
    # Counters of the statics node itself (diagnostics, once a second): what reached it and what
    # it published, so losses on the way in and on the way back can be told apart.
    before = [v for t, v in sorted(totals.items()) if t <= window['start']]
    after = [v for t, v in sorted(totals.items()) if t > window['end'] + 0.5]
    statics_counts = [-1] * 4
    if before and after:
        statics_counts = [a - b for a, b in zip(after[0], before[-1])]
    gaps = np.diff(send_times[-sent:]) * 1e3
    return {
        'sent': sent, 'processed': int(stamps.size), 'dropped': int(sent - stamps.size),
        'input_rate_hz': sent / elapsed, 'processed_rate_hz': stamps.size / elapsed,
        'latency_median_ms': np.nan if empty else float(np.median(latencies)),
        'latency_p99_ms': np.nan if empty else float(np.percentile(latencies, 99)),
        'latency_max_ms': np.nan if empty else float(latencies.max()),
        'statics_cpu_percent': 100.0 * (window['cpu_end'] - window['cpu']) / elapsed,
        'send_gap_p99_ms': float(np.percentile(gaps, 99)), 'send_gap_max_ms': float(gaps.max()),
        'statics_received': statics_counts[0], 'statics_published': statics_counts[1],
        'statics_skipped': statics_counts[2], 'statics_lost': statics_counts[3],
        'client_cpu_percent': 100.0 * (window['own_cpu_end'] - window['own_cpu']) / elapsed,
    }


def _spin_until_shutdown(executor):
    try:
        executor.spin()
    except Exception:  # ExternalShutdownException and friends: the bench is ending
        pass


def bench_tip_goal(robot_file, goals=5):
    """Start bringup, call tip_goal for reachable goals and one unreachable; return figures."""
    from continuum_statics.tools.goal_client import run_client

    namespace = 'bench_goal'
    process = subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics', 'bringup', '--robot', robot_file,
         '--namespace', namespace, '--ros-args', '--log-level', 'warn'])
    try:
        rows = run_client(robot_file, namespace, goals=goals, tolerance=1e-3,
                               print_rows=False, process=process)
    finally:
        stop(process)
    reached = [row for row in rows if row['reachable'] and row['reached']]
    rejected = [row for row in rows if not row['reachable']]
    return {
        'goals': len([row for row in rows if row['reachable']]),
        'reached': len(reached),
        'round_trip_median_s': float(np.median([r['time'] for r in reached])) if reached
        else np.nan,
        'round_trip_max_s': max((r['time'] for r in reached), default=np.nan),
        'unreachable_round_trip_ms': rejected[0]['time'] * 1e3 if rejected else np.nan,
        'unreachable_rejected': bool(rejected) and not rejected[0]['reached'],
    }


def main(argv=None):
    """Run the node benchmark; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics bench --nodes',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--robot', default=default_robot_file(), help='robot description YAML')
    parser.add_argument('--rate', type=float, default=1000.0, help='cable_states rate, Hz')
    parser.add_argument('--duration', type=float, default=10.0, help='measured time, s')
    parser.add_argument('--goals', type=int, default=5, help='reachable tip goals to time')
    parser.add_argument('--skip-goals', action='store_true', help='only the statics part')
    parser.add_argument('--statics-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='parameter for the statics process (repeatable)')
    parser.add_argument('--noise', type=float, default=0.0, metavar='SIGMA',
                        help='Gaussian encoder noise added to every length, m (seeded)')
    options = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    ros_environment()
    robot_file = os.path.abspath(options.robot)
    print('statics: cable_states at %g Hz for %g s (robot %s, noise sigma %g m) ...'
          % (options.rate, options.duration, os.path.basename(robot_file), options.noise),
          flush=True)
    statics = bench_statics(robot_file, options.rate, options.duration,
                            parameters=options.statics_param,
                            lengths_source=noisy_lengths(options.noise))
    print('  sent %(sent)d, processed %(processed)d, dropped %(dropped)d' % statics)
    print('  statics counted (window +-1 s): %(statics_received)d solved, %(statics_published)d '
          'published, %(statics_skipped)d skipped as stale, %(statics_lost)d lost before the '
          'intake' % statics)
    print('  input %(input_rate_hz).1f Hz (gap between sends p99 %(send_gap_p99_ms).2f ms, max '
          '%(send_gap_max_ms).2f ms), processed %(processed_rate_hz).1f Hz' % statics)
    print('  stamp-to-backbone latency: median %(latency_median_ms).2f ms, p99 '
          '%(latency_p99_ms).2f ms, max %(latency_max_ms).2f ms' % statics)
    print('  CPU: statics process %(statics_cpu_percent).0f %%, this client process '
          '%(client_cpu_percent).0f %% (of one core; %(cores)d cores)'
          % dict(statics, cores=os.cpu_count()), flush=True)
    line = ('figures: processed %.1f Hz (target >= 995), dropped %d, latency median %.2f ms, '
            'p99 %.2f ms (<= 2), statics CPU %.0f %%' % (
                statics['processed_rate_hz'], statics['dropped'], statics['latency_median_ms'],
                statics['latency_p99_ms'], statics['statics_cpu_percent']))
    if not options.skip_goals:
        print('tip_goal: %d reachable goals and one unreachable through bringup ...'
              % options.goals, flush=True)
        goal = bench_tip_goal(robot_file, options.goals)
        print('  reached %(reached)d/%(goals)d, round trip median %(round_trip_median_s).2f s, '
              'max %(round_trip_max_s).2f s; unreachable answered empty in '
              '%(unreachable_round_trip_ms).0f ms' % goal)
        line += ', tip_goal round trip median %.2f s (unreachable %.0f ms)' % (
            goal['round_trip_median_s'], goal['unreachable_round_trip_ms'])
    print(line)
    return 0


if __name__ == '__main__':
    sys.exit(main())
