"""``make soak``: bringup under load for minutes, with a random reachable tip goal every 2 s.

Starts ``bringup`` (simulated driver publishing ``cable_states`` at ``--rate``, 1 kHz by default,
so statics solves at that rate) and calls ``tip_goal`` with a random reachable goal every
``--period`` seconds for ``--minutes``. Prints goals answered and reached, the bringup process's
resident memory at the start (after the first goal) and at the end, the number of warning and
error lines it logged, how often a node's diagnostics still said WARN (or worse) one second after
a goal ended, and statics' processed rate. Figures only; the exit code is 1 when a reachable goal
was not reached or bringup died. Not part of ``make test`` (it takes minutes).

``--normal-use`` models a lab's normal use instead (``benchmarks/soak_use.py``): the simulated
driver in motion (``--dynamics``), a noisy tip tracker with dropouts (``--tracker``), goals from
the ``move_tip`` action and the ``tip_goal`` service, some cancelled or pre-empted
(``--actions``), and one SIGINT and restart of bringup half way (``--restart``); each can be
given alone. Its exit code is 1 when a goal went unanswered, a callback raised (a log line with
``callback of node``, ``Traceback`` or ``ERROR``), an exit code at a SIGINT was not 0 or
``tip_pose`` carried a non-finite value.
"""
import argparse
import os
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from continuum_statics.config_paths import default_robot_file, share_dir
from continuum_statics.core.statics.workspace import reachable_tips
from continuum_statics.tools.processes import ros_environment, stop


def rss_mb(pid):
    """Resident set size of a process, MB (Linux /proc)."""
    with open('/proc/%d/status' % pid) as status:
        for line in status:
            if line.startswith('VmRSS:'):
                return int(line.split()[1]) / 1024.0
    return float('nan')


def soak(robot_file, minutes, period, rate, noise, tolerance, seed):
    """Run the soak; return a dict of figures."""
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.srv import GetPlan
    import rclpy

    from continuum_statics import load_robot

    robot = load_robot(robot_file)
    namespace = 'soak_%d' % os.getpid()
    log = tempfile.NamedTemporaryFile('w+', prefix='soak_bringup_', suffix='.log', delete=False)
    ros_args = ['--ros-args', '--log-level', 'warn', '-p', 'publish_rate:=%r' % float(rate)]
    if noise > 0.0:
        ros_args += ['-p', 'sim.noise_std:=%r' % float(noise),
                     '-p', 'length_noise_std:=%r' % float(noise)]
    process = subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics', 'bringup', '--robot', robot_file,
         '--namespace', namespace] + ros_args, stdout=log, stderr=subprocess.STDOUT)
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('soak_client', namespace=namespace, context=context)
    levels, statics_rates = {}, []

    def on_diagnostics(msg):
        for status in msg.status:
            if status.name.startswith(namespace + '/'):
                levels[status.name] = (ord(status.level), status.message, time.monotonic())
                if status.name.endswith('/statics'):
                    for kv in status.values:
                        if kv.key == 'output_rate_hz':
                            statics_rates.append(float(kv.value))

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    client = node.create_client(GetPlan, 'tip_goal')
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor,), daemon=True)
    spinner.start()
    figures = {'answered': 0, 'reached': 0, 'sent': 0, 'idle_warn': 0, 'idle_checks': 0,
               'failures': []}
    try:
        if not client.wait_for_service(timeout_sec=60.0):
            raise RuntimeError('bringup offered no tip_goal service within 60 s')
        end = time.monotonic() + 60.0 * minutes
        goals = reachable_tips(robot, int(60.0 * minutes / period) + 2, seed)
        next_send = time.monotonic()
        for index, goal in enumerate(goals):
            if time.monotonic() >= end or process.poll() is not None:
                break
            time.sleep(max(0.0, next_send - time.monotonic()))
            next_send = time.monotonic() + period
            if index > 0:  # one second or more after the previous goal ended
                figures['idle_checks'] += 1
                now = time.monotonic()
                warned = [name for name, (level, _, stamp) in levels.items()
                          if level >= 1 and now - stamp < 1.5]
                if warned:
                    figures['idle_warn'] += 1
                    figures.setdefault('idle_warn_examples', []).append(
                        '%s: %s' % (warned[0], levels[warned[0]][1]))
            request = GetPlan.Request(tolerance=float(tolerance))
            request.goal.header.frame_id = robot.base_frame_id
            p = request.goal.pose.position
            p.x, p.y, p.z = (float(v) for v in goal)
            request.goal.pose.orientation.w = 1.0
            figures['sent'] += 1
            future = client.call_async(request)
            deadline = time.monotonic() + 30.0
            while not future.done() and time.monotonic() < deadline and process.poll() is None:
                time.sleep(0.005)
            if not future.done():
                client.remove_pending_request(future)
                figures['failures'].append('no answer for goal %s' % np.round(goal, 4))
                continue
            figures['answered'] += 1
            plan = future.result().plan
            if plan.poses:
                figures['reached'] += 1
            else:
                figures['failures'].append('not reached: %s' % np.round(goal, 4))
            if index == 0:
                figures['rss_start_mb'] = rss_mb(process.pid)
        figures['rss_end_mb'] = rss_mb(process.pid)
        figures['alive'] = process.poll() is None
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        figures['exit_code'] = stop(process)
    log.seek(0)
    lines = log.read().splitlines()
    log.close()
    warnings = [line for line in lines if '[WARN]' in line or '[ERROR]' in line]
    figures.update(log=log.name, warnings=len(warnings), warning_examples=warnings[:5],
                   tracebacks=sum('Traceback' in line for line in lines),
                   statics_rate_hz=float(np.median(statics_rates[2:])) if len(
                       statics_rates) > 2 else float('nan'))
    return figures


def statics_rate(robot_file, rate, duration, noise, seed):
    """Statics alone, fed ``rate`` Hz of noisy cable lengths (node_bench's measurement)."""
    from continuum_statics.tools import node_bench

    rng = np.random.default_rng(seed)

    def noisy(robot, count, rate):
        lengths = np.asarray(node_bench.measurement_lengths(robot, count, rate))
        return (lengths + rng.normal(0.0, noise, lengths.shape)).tolist()

    return node_bench.bench_statics(robot_file, rate, duration, parameters=[
        'length_noise_std:=%r' % float(noise)], lengths_source=noisy)


def _spin(executor):
    try:
        executor.spin()
    except Exception:  # shut down at the end
        pass


def main(argv=None):
    """Run the soak; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m benchmarks.soak',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=10.0, help='duration (default 10)')
    parser.add_argument('--period', type=float, default=2.0, help='s between goals')
    parser.add_argument('--rate', type=float, default=None,
                        help="cable_states rate, Hz (default 1000; 200, the driver's own "
                        'default, with any normal-use option)')
    parser.add_argument('--noise', type=float, default=0.0,
                        help='sim encoder noise, m (statics is told the same)')
    parser.add_argument('--tolerance', type=float, default=1e-3, help='goal tolerance, m')
    parser.add_argument('--seed', type=int, default=1, help='goal sequence seed')
    parser.add_argument('--robot', default=None, help='robot description YAML (default: '
                        'config/tendon_robot.yaml; config/tendon_robot_dynamic.yaml with '
                        '--dynamics)')
    use = parser.add_argument_group('normal use (all off by default; --normal-use: all on)')
    use.add_argument('--normal-use', action='store_true',
                     help='--dynamics --tracker --actions --restart')
    use.add_argument('--dynamics', action='store_true',
                     help='the simulated driver in motion (sim.dynamics:=true)')
    use.add_argument('--tracker', action='store_true',
                     help="a tip tracker: sim/tip_pose_true plus noise on the robot file's tip "
                     'sensor topic (a copy with one if it has none), occluded 1-3 s every ~20 s '
                     '(needs --dynamics)')
    use.add_argument('--tracker-noise', type=float, default=3e-4,
                     help='tracker noise, m (default 3e-4)')
    use.add_argument('--tracker-rate', type=float, default=100.0, help='tracker rate, Hz')
    use.add_argument('--actions', action='store_true',
                     help='goals from move_tip and tip_goal, some cancelled or pre-empted')
    use.add_argument('--restart', action='store_true',
                     help='SIGINT bringup half way (a goal in flight) and start it again')
    parser.add_argument('--statics-only', type=float, metavar='SECONDS',
                        help='instead: statics alone, fed --rate Hz of lengths with --noise for '
                        'this long; prints its processed rate')
    options = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if options.normal_use:
        options.dynamics = options.tracker = options.actions = options.restart = True
    normal_use = options.dynamics or options.tracker or options.actions or options.restart
    if options.tracker and not options.dynamics:
        parser.error('--tracker needs --dynamics (it reads the simulated true tip)')
    if options.rate is None:
        options.rate = 200.0 if normal_use else 1000.0
    if options.robot is None:
        options.robot = (os.path.join(share_dir(), 'config', 'tendon_robot_dynamic.yaml')
                         if options.dynamics else default_robot_file())
    ros_environment()
    if options.statics_only:
        figures = statics_rate(os.path.abspath(options.robot), options.rate,
                               options.statics_only, options.noise, options.seed)
        print('statics alone, %g Hz input with noise %g m: processed %.1f Hz, dropped %d, '
              'latency median %.2f ms, p99 %.2f ms, CPU %.0f %%' % (
                  options.rate, options.noise, figures['processed_rate_hz'],
                  figures['dropped'], figures['latency_median_ms'], figures['latency_p99_ms'],
                  figures['statics_cpu_percent']))
        return 0
    if normal_use:
        return normal_use_main(options)
    print('soak: %g min, a goal every %g s, cable_states at %g Hz, noise %g m ...'
          % (options.minutes, options.period, options.rate, options.noise), flush=True)
    f = soak(os.path.abspath(options.robot), options.minutes, options.period, options.rate,
             options.noise, options.tolerance, options.seed)
    print('goals: %d sent, %d answered, %d reached' % (f['sent'], f['answered'], f['reached']))
    for failure in f['failures'][:10]:
        print('  ' + failure)
    print('bringup RSS: %.1f MB after the first goal, %.1f MB at the end (%+.2f MB)' % (
        f.get('rss_start_mb', float('nan')), f.get('rss_end_mb', float('nan')),
        f.get('rss_end_mb', float('nan')) - f.get('rss_start_mb', float('nan'))))
    print('warnings: %d WARN/ERROR log lines, %d tracebacks (log: %s)'
          % (f['warnings'], f['tracebacks'], f['log']))
    for line in f['warning_examples']:
        print('  ' + line[:160])
    print('diagnostics WARN 1 s after a goal ended: %d of %d checks'
          % (f['idle_warn'], f['idle_checks']))
    for line in f.get('idle_warn_examples', [])[:5]:
        print('  ' + line[:160])
    print('statics processed rate (median of its 1 s reports): %.1f Hz' % f['statics_rate_hz'])
    ok = f['reached'] == f['sent'] and f['tracebacks'] == 0 and f.get('alive', False)
    return 0 if ok else 1


def normal_use_main(options):
    """Run the soak of a lab's normal use (``benchmarks/soak_use.py``); return the exit code."""
    from benchmarks import soak_use

    parts = [name for name in ('dynamics', 'tracker', 'actions', 'restart')
             if getattr(options, name)]
    print('soak, normal use (%s): %g min, a goal every ~%g s, cable_states at %g Hz, '
          'tolerance %g m%s ...' % (
              ', '.join(parts), options.minutes, options.period, options.rate,
              options.tolerance, ', tracker %g m at %g Hz' % (
                  options.tracker_noise, options.tracker_rate) if options.tracker else ''),
          flush=True)
    folder = tempfile.mkdtemp(prefix='soak_')
    figures = soak_use.normal_use_soak(
        os.path.abspath(options.robot), options.minutes, options.period, options.rate,
        options.tolerance, options.seed, options.dynamics, options.tracker, options.actions,
        options.restart, options.tracker_noise, options.tracker_rate, folder)
    return soak_use.report(figures)


if __name__ == '__main__':
    sys.exit(main())
