"""A lab's normal use for ``benchmarks.soak --normal-use`` (issue 44: ten minutes of it).

What runs, each part its own option of ``python -m benchmarks.soak``:

- ``--dynamics``: the simulated driver in motion (``sim.dynamics:=true``) on a robot file with a
  ``dynamics`` block (``config/tendon_robot_dynamic.yaml`` unless ``--robot`` says otherwise);
- ``--tracker``: a tip tracker in this process, the true tip (``sim/tip_pose_true``) plus
  Gaussian noise at 100 Hz on the robot file's tip sensor topic (``sensors/<name>``; a robot file
  without one gets a copy with a ``tip_tracker`` sensor in a temporary folder), occluded for 1-3 s
  at random every ~20 s;
- ``--actions``: goals from both the ``move_tip`` action and the ``tip_goal`` service, some
  action goals cancelled and some goals pre-empted by the next;
- ``--restart``: SIGINT to bringup half way through (a goal in flight), its exit code checked,
  bringup started again and the goals go on.

Every goal must get exactly one answer. Printed: goals sent / answered / reached per source and
how the others ended, the true tip's distance from each reached goal when it was answered, the
exit code at each SIGINT, log lines naming a failed callback, a traceback or ERROR, non-finite
``tip_pose`` values, bringup's RSS, the tracker's readings statics set aside and which tip
tip_controller judged goals on (its /diagnostics).
"""
import bisect
import collections
import math
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np

from continuum_statics.core.estimation.gates import chi2_quantile
from continuum_statics.core.statics.workspace import reachable_tips
from continuum_statics.tools.processes import stop

#: Log lines that mean a callback raised or the process logged an error.
BAD_LINE = re.compile(r'callback of node|Traceback|ERROR')
#: Service and action goals: how long one may take to be answered before it counts as unanswered.
ANSWER_TIMEOUT = 60.0  # s
#: Fates of a goal: answered on its own, cancelled after a while, pre-empted by the next goal.
NORMAL, CANCEL, PREEMPT = 'normal', 'cancel', 'preempt'
#: The goal sent half a second before the restart's SIGINT.
AT_SIGINT = 'at-sigint'
#: A position error inside its 95 % ellipsoid: chi-square, 3 degrees of freedom, 95 %.
NEES_95 = chi2_quantile(0.95, 3)
#: GoalStatus values of a result: succeeded, canceled, aborted.
STATUS_NAMES = {4: 'succeeded', 5: 'canceled', 6: 'aborted'}


def rss_mb(pid):
    """Resident set size of a process, MB (Linux /proc); nan once it is gone."""
    try:
        with open('/proc/%d/status' % pid) as status:
            for line in status:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return float('nan')


def robot_with_tip_sensor(robot_file, noise, folder):
    """(robot file, sensor name): ``robot_file`` if it has a tip sensor, else a copy with one.

    The copy (in ``folder``) adds a position sensor ``tip_tracker`` at the tip with ``noise``
    (m) and, when the file has none, the model uncertainty of ``config/tendon_robot_sensors.yaml``.
    """
    import yaml

    from continuum_statics import load_robot

    robot = load_robot(robot_file)
    for sensor in robot.sensors:
        if sensor.at_tip:
            return robot_file, sensor.name
    with open(robot_file) as stream:
        data = yaml.safe_load(stream)
    data['name'] = '%s_tracked' % data.get('name', 'robot')
    data['sensors'] = list(data.get('sensors') or []) + [
        {'name': 'tip_tracker', 'at': 'tip', 'kind': 'position', 'noise': {'position': noise}}]
    data.setdefault('model_uncertainty', {
        'tip_force': 0.05, 'section_moment': 0.005, 'cable_length': 3.0e-4,
        'base_position': 5.0e-4, 'correlation_time': 10.0})
    path = os.path.join(folder, os.path.basename(robot_file).replace('.yaml', '_tracked.yaml'))
    with open(path, 'w') as stream:
        yaml.safe_dump(data, stream, sort_keys=False)
    load_robot(path)  # refuse a bad copy here, not in three nodes
    return path, 'tip_tracker'


class Truth:
    """The newest ``sim/tip_pose_true`` (best effort: sensor-data QoS) and ``tip_pose`` checks."""

    def __init__(self, node, sensor=None):
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
        from rclpy.qos import qos_profile_sensor_data

        from continuum_statics.nodes.qos import LATCHED_QOS

        self.lock = threading.Lock()
        self.true_tip = None  # (xyz, header stamp, monotonic s of arrival)
        self.true_count = self.true_nonfinite = 0
        self.tip_count = self.tip_nonfinite = 0
        self.tip_arrival = None  # monotonic s of the newest tip_pose
        self.gaps = []  # (monotonic s, m): tip_pose's distance from the newest true tip
        self.tips = []  # (wall s, x, y, z) of each tip_pose
        self.accepted = []  # (wall s, x, y, z) of each tracker reading statics passed on
        self.true_history = collections.deque(maxlen=4096)  # (stamp s, xyz) of the true tip
        self.matched = []  # (m, NEES, true tip speed m/s) of each tip_pose_covariance
        if sensor is not None:
            node.create_subscription(PoseStamped, 'sensors/%s/accepted' % sensor,
                                     self._on_accepted, qos_profile_sensor_data)
        node.create_subscription(PoseStamped, 'sim/tip_pose_true', self._on_true,
                                 qos_profile_sensor_data)
        node.create_subscription(PoseStamped, 'tip_pose', self._on_tip, LATCHED_QOS)
        node.create_subscription(PoseWithCovarianceStamped, 'tip_pose_covariance',
                                 self._on_covariance, LATCHED_QOS)

    @staticmethod
    def _values(pose):
        p, q = pose.position, pose.orientation
        return np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w])

    def _on_true(self, msg):
        values = self._values(msg.pose)
        with self.lock:
            self.true_count += 1
            if not np.all(np.isfinite(values)):
                self.true_nonfinite += 1
                return
            self.true_tip = (values[:3], msg.header.stamp, time.monotonic())
            self.true_history.append((_seconds(msg.header.stamp), values[:3]))

    def _on_covariance(self, msg):
        """Compare the estimate with the true tip of its stamp (the driver's clock for both)."""
        p = msg.pose.pose.position
        with self.lock:
            history = tuple(self.true_history)
        when = _seconds(msg.header.stamp)
        at = bisect.bisect_left(history, when, key=lambda sample: sample[0])
        candidates = [i for i in (at - 1, at) if 0 <= i < len(history)]
        if not candidates:
            return
        nearest = min(candidates, key=lambda i: abs(history[i][0] - when))
        if abs(history[nearest][0] - when) > 0.005:
            return
        error = np.array([p.x, p.y, p.z]) - history[nearest][1]
        covariance = np.array(msg.pose.covariance).reshape(6, 6)[:3, :3]
        a, b = history[max(nearest - 5, 0)], history[min(nearest + 5, len(history) - 1)]
        speed = (float(np.linalg.norm(b[1] - a[1]) / (b[0] - a[0])) if b[0] > a[0]
                 else float('nan'))
        try:
            nees = float(error @ np.linalg.solve(covariance, error))
        except np.linalg.LinAlgError:
            nees = float('nan')
        with self.lock:
            self.matched.append((float(np.linalg.norm(error)), nees, speed))

    def _on_accepted(self, msg):
        p = msg.pose.position
        with self.lock:
            self.accepted.append((time.time(), p.x, p.y, p.z))

    def _on_tip(self, msg):
        values = self._values(msg.pose)
        with self.lock:
            self.tips.append((time.time(), *values[:3]))
            self.tip_count += 1
            self.tip_arrival = time.monotonic()
            if not np.all(np.isfinite(values)):
                self.tip_nonfinite += 1
            elif self.true_tip is not None and self.tip_arrival - self.true_tip[2] < 0.05:
                self.gaps.append((self.tip_arrival,
                                  float(np.linalg.norm(values[:3] - self.true_tip[0]))))

    def fresh_true_tip(self, max_age=0.1):
        """(xyz, stamp) of the true tip if it arrived within ``max_age`` s, else None."""
        with self.lock:
            if self.true_tip is None or time.monotonic() - self.true_tip[2] > max_age:
                return None
            return self.true_tip[0].copy(), self.true_tip[1]


def _seconds(stamp):
    return stamp.sec + 1e-9 * stamp.nanosec


class Tracker:
    """A tip tracker: the true tip plus N(0, ``sigma``) at ``rate`` Hz on ``topic``, with dropouts.

    Occluded (publishes nothing) for U(1, 3) s starting U(15, 25) s after the last occlusion
    ended. Each reading carries the stamp of the true tip it was taken from. Nothing is published
    while the true tip is older than 0.1 s (bringup down): a tracker of a robot that is not there.
    """

    def __init__(self, node, truth, topic, sigma, rate, rng):
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import qos_profile_sensor_data

        self.truth, self.sigma, self.rng = truth, float(sigma), rng
        self.msg = PoseStamped()
        self.msg.header.frame_id = 'base_link'
        self.msg.pose.orientation.w = 1.0
        self.publisher = node.create_publisher(PoseStamped, topic, qos_profile_sensor_data)
        self.published = self.occlusions = self.no_truth = 0
        self.occluded_s = 0.0
        now = time.monotonic()
        self._occluded_until = now
        self._next_occlusion = now + float(rng.uniform(15.0, 25.0))
        self.timer = node.create_timer(1.0 / rate, self._tick)

    def _tick(self):
        now = time.monotonic()
        if now >= self._next_occlusion:
            length = float(self.rng.uniform(1.0, 3.0))
            self._occluded_until = now + length
            self._next_occlusion = self._occluded_until + float(self.rng.uniform(15.0, 25.0))
            self.occlusions += 1
            self.occluded_s += length
        if now < self._occluded_until:
            return
        true = self.truth.fresh_true_tip()
        if true is None:
            self.no_truth += 1
            return
        xyz, stamp = true
        xyz = xyz + self.rng.normal(0.0, self.sigma, 3)
        self.msg.header.stamp = stamp
        p = self.msg.pose.position
        p.x, p.y, p.z = (float(v) for v in xyz)
        self.publisher.publish(self.msg)
        self.published += 1


class Diagnostics:
    """The newest /diagnostics values of each node of the namespace, per bringup run (epoch)."""

    def __init__(self, node, namespace):
        from diagnostic_msgs.msg import DiagnosticArray

        self.namespace = namespace
        self.lock = threading.Lock()
        self.epoch = 0
        self.latest = [{}]  # per epoch: node name -> {key: value}
        self.tip_sources = {}  # tip_controller's tip_source while moving to a goal: count
        self.levels = {}  # node -> (level, message) of the newest report
        self.warn_reports = {}  # node -> number of WARN-or-worse reports
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)

    def new_epoch(self):
        """Count from here on as the next bringup run's."""
        with self.lock:
            self.epoch += 1
            self.latest.append({})

    def _on_diagnostics(self, msg):
        with self.lock:
            for status in msg.status:
                if not status.name.startswith(self.namespace + '/'):
                    continue
                name = status.name[len(self.namespace) + 1:]
                values = {kv.key: kv.value for kv in status.values}
                self.latest[self.epoch][name] = values
                level = ord(status.level) if isinstance(status.level, bytes) else status.level
                self.levels[name] = (level, status.message)
                if level >= 1:
                    self.warn_reports[name] = self.warn_reports.get(name, 0) + 1
                if name.endswith('tip_controller') and values.get('phase') not in (
                        None, 'idle') and 'tip_source' in values:
                    source = values['tip_source']
                    self.tip_sources[source] = self.tip_sources.get(source, 0) + 1

    def sensor_counts(self, sensor):
        """Return statics' used / set aside / stale / rejected counts of ``sensor``, all runs."""
        totals = {'used': 0, 'set aside': 0, 'stale': 0, 'rejected': 0}
        last_reason = ''
        with self.lock:
            for epoch in self.latest:
                text = epoch.get('statics', {}).get('sensor_%s' % sensor, '')
                for key in totals:
                    found = re.search(r'%s (\d+)' % key, text)
                    if found:
                        totals[key] += int(found.group(1))
                if ': ' in text:
                    last_reason = text.split(': ', 1)[1]
        return totals, last_reason

    def values_of(self, node_name, key):
        """Return the newest value of ``key`` from ``node_name`` in each run."""
        with self.lock:
            return [epoch.get(node_name, {}).get(key) for epoch in self.latest]


class Goals:
    """Goals through ``tip_goal`` and ``move_tip``, each with one record of how it ended."""

    def __init__(self, node, robot, truth, tolerance, use_actions):
        from nav_msgs.srv import GetPlan

        self.robot, self.truth, self.tolerance = robot, truth, float(tolerance)
        self.service = node.create_client(GetPlan, 'tip_goal')
        self.action = None
        if use_actions:
            from continuum_statics.nodes.action_client import HandoverActionClient
            from continuum_statics.nodes.qos import ACTION_SERVICE_QOS
            from continuum_statics_interfaces.action import MoveTip
            self.MoveTip = MoveTip
            self.action = HandoverActionClient(
                node, MoveTip, 'move_tip', goal_service_qos_profile=ACTION_SERVICE_QOS,
                result_service_qos_profile=ACTION_SERVICE_QOS,
                cancel_service_qos_profile=ACTION_SERVICE_QOS)
        self.GetPlan = GetPlan
        self.records = []

    def ready(self):
        """Return True when tip_goal (and move_tip) are served."""
        return self.service.service_is_ready() and (
            self.action is None or self.action.server_is_ready())

    def send(self, source, position, fate):
        """Send one goal; return its record."""
        record = {'source': source, 'fate': fate, 'goal': np.asarray(position, dtype=float),
                  'sent': time.monotonic(), 'answered': None, 'answers': 0, 'reached': False,
                  'outcome': None, 'message': '', 'error': math.nan, 'true_error': math.nan,
                  'cancel_at': None, 'cancelled': False, 'handle': None, 'result': None}
        if source == 'service':
            request = self.GetPlan.Request(tolerance=self.tolerance)
            request.goal.header.frame_id = self.robot.base_frame_id
            p = request.goal.pose.position
            p.x, p.y, p.z = (float(v) for v in position)
            request.goal.pose.orientation.w = 1.0
            record['future'] = self.service.call_async(request)
        else:
            goal = self.MoveTip.Goal(tolerance=self.tolerance)
            goal.target.header.frame_id = self.robot.base_frame_id
            p = goal.target.pose.position
            p.x, p.y, p.z = (float(v) for v in position)
            goal.target.pose.orientation.w = 1.0
            record['future'] = self.action.send_goal_async(goal)
        self.records.append(record)
        return record

    def poll(self):
        """Move every outstanding goal on: acceptance, cancel when due, its one answer."""
        now = time.monotonic()
        for record in self.records:
            if record['answered'] is not None or record.get('abandoned'):
                continue
            if record['source'] == 'service':
                if record['future'].done():
                    self._answer(record, now, *self._service_outcome(record['future']))
                continue
            if record['handle'] is None:
                if not record['future'].done():
                    continue
                handle = record['future'].result()
                record['handle'] = handle
                if not handle.accepted:
                    self._answer(record, now, 'rejected', False, math.nan, 'rejected')
                    continue
                record['result'] = handle.get_result_async()
            if (record['cancel_at'] is not None and not record['cancelled']
                    and now >= record['cancel_at']):
                record['handle'].cancel_goal_async()
                record['cancelled'] = True
            if record['result'] is not None and record['result'].done():
                response = record['result'].result()
                result = response.result
                outcome = STATUS_NAMES.get(response.status, 'status %d' % response.status)
                self._answer(record, now, outcome, bool(result.reached), float(result.error),
                             result.message)

    @staticmethod
    def _service_outcome(future):
        """(outcome, reached, error, message) of a tip_goal answer: a plan, or empty."""
        if not future.result().plan.poses:
            return 'empty plan', False, math.nan, ''
        return 'plan', True, math.nan, ''

    def _answer(self, record, now, outcome, reached, error, message):
        record['answers'] += 1
        record.update(answered=now, outcome=outcome, reached=reached, error=error,
                      message=message)
        true = self.truth.fresh_true_tip(max_age=0.5)
        if reached and true is not None:
            record['true_error'] = float(np.linalg.norm(true[0] - record['goal']))

    def outstanding(self):
        """Return the goals still waiting for their answer."""
        return [r for r in self.records if r['answered'] is None and not r.get('abandoned')]

    def abandon_late(self, timeout=ANSWER_TIMEOUT):
        """Give up on goals unanswered after ``timeout`` s (they count as unanswered)."""
        now = time.monotonic()
        for record in self.outstanding():
            if now - record['sent'] > timeout:
                record['abandoned'] = True
                if record['source'] == 'service':
                    self.service.remove_pending_request(record['future'])


class Bringup:
    """One bringup process after another, each logging into its own file."""

    def __init__(self, robot_file, namespace, ros_args, folder):
        self.command = [sys.executable, '-m', 'continuum_statics', 'bringup', '--robot',
                        robot_file, '--namespace', namespace] + ros_args
        self.folder = folder
        self.runs = []  # {'process', 'log', 'rss_start', 'rss_end', 'exit_code'}

    @property
    def process(self):
        """Return the newest bringup process."""
        return self.runs[-1]['process']

    def start(self):
        """Start bringup (again)."""
        log = open(os.path.join(self.folder, 'bringup_%d.log' % (len(self.runs) + 1)), 'w+')
        process = subprocess.Popen(self.command, stdout=log, stderr=subprocess.STDOUT)
        self.runs.append({'process': process, 'log': log, 'rss_start': math.nan,
                          'rss_end': math.nan, 'exit_code': None})

    def alive(self):
        """Return True while the newest bringup runs."""
        return self.process.poll() is None

    def interrupt(self):
        """SIGINT (kill after 20 s); return the exit code."""
        run = self.runs[-1]
        run['rss_end'] = rss_mb(run['process'].pid)
        if run['process'].poll() is not None:  # died by itself: its code, no SIGINT sent
            run['exit_code'] = run['process'].returncode
            run['died'] = True
            return run['exit_code']
        run['exit_code'] = stop(run['process'], timeout=20.0)
        return run['exit_code']

    def log_lines(self):
        """Per run: (path, lines)."""
        out = []
        for run in self.runs:
            run['log'].flush()
            run['log'].seek(0)
            out.append((run['log'].name, run['log'].read().splitlines()))
        return out


def normal_use_soak(robot_file, minutes, period, rate, tolerance, seed, dynamics, tracker,
                    actions, restart, tracker_noise, tracker_rate, folder):
    """Run the soak of a lab's normal use; return a dict of figures."""
    import rclpy
    from rclpy.executors import MultiThreadedExecutor

    from continuum_statics import load_robot

    rng = np.random.default_rng(seed)
    sensor = None
    if tracker:
        robot_file, sensor = robot_with_tip_sensor(robot_file, tracker_noise, folder)
    robot = load_robot(robot_file)
    namespace = 'soak_%d' % os.getpid()
    ros_args = ['--ros-args', '--log-level', 'warn', '-p', 'publish_rate:=%r' % float(rate)]
    if dynamics:
        ros_args += ['-p', 'sim.dynamics:=true']
    bringup = Bringup(robot_file, namespace, ros_args, folder)
    bringup.start()
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('soak_client', namespace=namespace, context=context)
    truth = Truth(node, sensor)
    diagnostics = Diagnostics(node, namespace)
    goals = Goals(node, robot, truth, tolerance, actions)
    tracking = None
    if tracker:
        tracking = Tracker(node, truth, 'sensors/%s' % sensor, tracker_noise, tracker_rate,
                           np.random.default_rng(seed + 1000))
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor,), daemon=True)
    spinner.start()
    figures = {'robot_file': robot_file, 'folder': folder, 'sensor': sensor,
               'tolerance': float(tolerance), 'failures': [], 'restarted': False}

    def wait_ready(timeout):
        since = time.monotonic()
        first_tip = truth.tip_arrival
        while time.monotonic() - since < timeout:
            if not bringup.alive():
                raise RuntimeError('bringup exited with code %s while starting'
                                   % bringup.process.returncode)
            tip_fresh = truth.tip_arrival is not None and truth.tip_arrival != first_tip
            if goals.ready() and tip_fresh and (not dynamics or truth.fresh_true_tip()):
                return time.monotonic() - since
            time.sleep(0.05)
        raise RuntimeError('bringup not ready within %g s' % timeout)

    def pause(seconds):
        """Sleep ``seconds`` while moving the goals on."""
        until = time.monotonic() + seconds
        while True:
            goals.poll()
            left = until - time.monotonic()
            if left <= 0.0:
                return
            time.sleep(min(0.01, left))

    def wait_answered(record, timeout=ANSWER_TIMEOUT):
        until = record['sent'] + timeout
        while record['answered'] is None and time.monotonic() < until:
            if not bringup.alive():
                pause(1.0)  # the results owed are sent before the process ends
                break
            pause(0.01)
        goals.abandon_late(timeout)

    try:
        figures['ready_s'] = [wait_ready(600.0)]
        start = time.monotonic()
        end = start + 60.0 * minutes
        restart_at = start + 30.0 * minutes if restart else math.inf
        targets = reachable_tips(robot, int(60.0 * minutes / (0.5 * period)) + 10, seed)
        index = 0
        next_send = time.monotonic()
        while time.monotonic() < end and index < len(targets):
            if not bringup.alive():
                figures['failures'].append('bringup died with code %s'
                                           % bringup.process.returncode)
                break
            pause(max(0.0, next_send - time.monotonic()))
            if time.monotonic() >= restart_at:
                restart_at = math.inf
                # a goal in flight at SIGINT: it must still be answered
                in_flight = goals.send('action' if actions else 'service', targets[index],
                                       AT_SIGINT)
                index += 1
                pause(0.5)
                code = bringup.interrupt()
                print('soak: bringup SIGINT half way: exit code %s' % code, flush=True)
                wait_answered(in_flight, timeout=10.0)
                pause(1.0)
                figures['restarted'] = True
                diagnostics.new_epoch()
                bringup.start()
                figures['ready_s'].append(wait_ready(600.0))
                next_send = time.monotonic()
                continue
            source = 'action' if actions and rng.random() < 0.5 else 'service'
            draw = rng.random()
            fate = NORMAL
            if source == 'action' and draw < 0.15:
                fate = CANCEL
            elif draw > 0.85:
                fate = PREEMPT
            record = goals.send(source, targets[index], fate)
            index += 1
            if fate == PREEMPT:  # the next goal comes before this one is done
                next_send = time.monotonic() + float(rng.uniform(0.2, 1.0))
                continue
            if fate == CANCEL:
                record['cancel_at'] = time.monotonic() + float(rng.uniform(0.2, 1.0))
            wait_answered(record)
            if math.isnan(bringup.runs[-1]['rss_start']):  # after the run's first goal
                bringup.runs[-1]['rss_start'] = rss_mb(bringup.process.pid)
            next_send = max(record['sent'] + period * float(rng.uniform(0.75, 1.25)),
                            time.monotonic() + 0.1)
        # the last answers (pre-empted goals answer when pre-empted; a last one in flight)
        until = time.monotonic() + 30.0
        while goals.outstanding() and time.monotonic() < until:
            pause(0.05)
        goals.abandon_late(0.0)
        pause(1.5)  # a last diagnostics report of each node
    finally:
        alive_at_end = bringup.alive()
        code = bringup.interrupt()
        if figures.get('restarted') or len(bringup.runs) > 1:
            print('soak: bringup SIGINT at the end: exit code %s' % code, flush=True)
        pause_end = time.monotonic() + 2.0
        while time.monotonic() < pause_end:  # answers sent at shutdown
            goals.poll()
            time.sleep(0.01)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    figures['alive_at_end'] = alive_at_end
    figures['goals'] = goals.records
    figures['runs'] = bringup.runs
    figures['logs'] = bringup.log_lines()
    figures['tip'] = (truth.tip_count, truth.tip_nonfinite)
    figures['true_tip'] = (truth.true_count, truth.true_nonfinite)
    figures['gaps'] = np.array(truth.gaps).reshape(-1, 2)
    figures['matched'] = np.array(truth.matched).reshape(-1, 3)
    figures['tips'] = np.array(truth.tips).reshape(-1, 4)
    figures['accepted'] = np.array(truth.accepted).reshape(-1, 4)
    figures['tracker'] = tracking
    figures['diagnostics'] = diagnostics
    return figures


def _spin(executor):
    try:
        executor.spin()
    except Exception:  # shut down at the end
        pass


def set_aside_at(f):
    """Print, at each 'tracker set aside' WARN, the age of the newest accepted tracker reading.

    tip_controller compares that reading with the newest model tip (tip_pose): a reading of
    0.4 s ago against the tip of now, on a robot in motion, is far away without being wrong.
    """
    accepted, tips = f['accepted'], f['tips']
    if not accepted.size or not tips.size:
        return
    stamp = re.compile(r'^\[WARN\] \[([0-9.]+)\].*tracker set aside: tip_pose_measured is '
                       r'([0-9.]+) mm')
    rows = []
    for _, lines in f['logs']:
        for line in lines:
            found = stamp.match(line)
            if not found:
                continue
            when, said = float(found.group(1)), float(found.group(2))
            a = np.searchsorted(accepted[:, 0], when) - 1
            t = np.searchsorted(tips[:, 0], when) - 1
            if a < 0 or t < 0:
                continue
            # the model tip when that reading arrived, against the one it was compared with
            then = max(0, np.searchsorted(tips[:, 0], accepted[a, 0]) - 1)
            rows.append((said, when - accepted[a, 0],
                         1e3 * np.linalg.norm(accepted[a, 1:] - tips[t, 1:]),
                         1e3 * np.linalg.norm(accepted[a, 1:] - tips[then, 1:])))
    intervals = np.diff(accepted[:, 0])
    print('  accepted tracker readings: %d, longest interval between two %.2f s' % (
        len(accepted), intervals.max() if intervals.size else math.nan))
    for said, age, now_gap, then_gap in rows[:8]:
        print('  set aside: WARN said %.1f mm; newest accepted reading %.2f s old, %.1f mm from '
              'the newest tip_pose, %.1f mm from the tip_pose of its arrival' % (
                  said, age, now_gap, then_gap))


def report(f):
    """Print the figures; return the exit code.

    1 when a goal went unanswered, a callback raised, an exit code was not 0, bringup died or a
    tip pose was not finite.
    """
    records = f['goals']
    failed = list(f['failures'])
    print('robot file: %s (bringup logs in %s)' % (f['robot_file'], f['folder']))
    print('goals by source (every goal exactly one answer):')
    print('  %-8s %5s %8s %7s  %s' % ('source', 'sent', 'answered', 'reached',
                                        'how the others ended'))
    for source in ('service', 'action'):
        mine = [r for r in records if r['source'] == source]
        if not mine:
            continue
        answered = [r for r in mine if r['answered'] is not None]
        reached = [r for r in answered if r['reached']]
        others = {}
        for r in answered:
            if not r['reached']:
                key = '%s %s' % (r['fate'], r['outcome'])
                others[key] = others.get(key, 0) + 1
        print('  %-8s %5d %8d %7d  %s' % (source, len(mine), len(answered), len(reached),
                                          ', '.join('%s: %d' % kv for kv in sorted(
                                              others.items())) or '-'))
        multiple = [r for r in mine if r['answers'] > 1]
        if multiple:
            failed.append('%d %s goals answered more than once' % (len(multiple), source))
    by_fate = {}
    for r in records:
        key = (r['fate'], r['reached'])
        by_fate[key] = by_fate.get(key, 0) + 1
    print('  by fate: ' + ', '.join('%s %s: %d' % (fate, 'reached' if ok else 'not reached', n)
                                    for (fate, ok), n in sorted(by_fate.items())))
    unanswered = [r for r in records if r['answered'] is None]
    for r in unanswered:
        failed.append('unanswered %s goal (%s) %s' % (r['source'], r['fate'],
                                                      np.round(r['goal'], 4)))
    missed = [r for r in records if r['fate'] == NORMAL and r['answered'] is not None
              and not r['reached']]
    for r in missed[:10]:
        print('  normal goal not reached (%s, %s): %s %s' % (
            r['source'], r['outcome'], np.round(1e3 * r['goal'], 1), r['message'][:160]))
    times = [r['answered'] - r['sent'] for r in records
             if r['answered'] is not None and r['reached']]
    if times:
        print('  time to a reached goal: median %.2f s, max %.2f s'
              % (np.median(times), np.max(times)))
    true_errors = np.array([r['true_error'] for r in records if r['reached']])
    true_errors = true_errors[np.isfinite(true_errors)]
    if true_errors.size:
        print('true tip error when a reached goal was answered (sim/tip_pose_true): median '
              '%.3f mm, max %.3f mm, over %d goals (tolerance %.3g mm)' % (
                  1e3 * np.median(true_errors), 1e3 * np.max(true_errors), true_errors.size,
                  1e3 * f.get('tolerance', math.nan)))
        far = true_errors > f.get('tolerance', math.nan) + 1e-3
        print("  beyond the tolerance + 1 mm (statics' friction resolution, as "
              'test_nodes_dynamics allows): %d of %d' % (np.sum(far), true_errors.size))
        judged = np.array([r['error'] for r in records if r['reached'] and r['error'] >= 0])
        if judged.size:
            print("  the controller's own error of reached action goals: median %.3f mm, "
                  'max %.3f mm' % (1e3 * np.median(judged), 1e3 * np.max(judged)))
    codes = [run['exit_code'] for run in f['runs']]
    print('bringup exit codes at each SIGINT: %s' % ', '.join(
        '%s%s' % (c, ' (died before it)' if run.get('died') else '')
        for c, run in zip(codes, f['runs'])))
    for code, run in zip(codes, f['runs']):
        if code != 0:
            failed.append('bringup exit code %s' % code)
        if run.get('died'):
            failed.append('bringup died before its SIGINT')
    bad_total = 0
    for (path, lines), run in zip(f['logs'], f['runs']):
        bad = [line for line in lines if BAD_LINE.search(line)]
        warn = [line for line in lines if '[WARN]' in line]
        bad_total += len(bad)
        print('log %s: %d lines with callback of node / Traceback / ERROR, %d WARN lines'
              % (path, len(bad), len(warn)))
        for line in bad[:5]:
            print('  ' + line[:200])
        kinds = {}
        for line in warn:
            text = re.sub(r'^\[WARN\] \[[0-9.]+\] \[[^\]]*\]: ', '', line)
            text = re.sub(r'[-0-9.]+', '#', text)[:90]
            kinds[text] = kinds.get(text, 0) + 1
        for text, count in sorted(kinds.items(), key=lambda kv: -kv[1])[:6]:
            print('  %4d x %s' % (count, text))
    if bad_total:
        failed.append('%d log lines name a failed callback, a traceback or ERROR' % bad_total)
    tip_count, tip_nonfinite = f['tip']
    true_count, true_nonfinite = f['true_tip']
    print('non-finite values: %d of %d tip_pose messages, %d of %d sim/tip_pose_true'
          % (tip_nonfinite, tip_count, true_nonfinite, true_count))
    if tip_nonfinite or true_nonfinite:
        failed.append('non-finite tip poses')
    gaps = f['gaps'][:, 1]
    if gaps.size:
        print('statics tip_pose against the true tip (each tip_pose): median %.2f mm, p99 '
              '%.2f mm, max %.2f mm; %.1f %% of them beyond 10 mm, %.2f %% beyond 30 mm' % (
                  1e3 * np.median(gaps), 1e3 * np.percentile(gaps, 99), 1e3 * np.max(gaps),
                  100.0 * np.mean(gaps > 0.01), 100.0 * np.mean(gaps > 0.03)))
    matched = f['matched']
    for name, rows in (('at rest (true tip < 5 mm/s)', matched[:, 2] < 5e-3),
                       ('moving', matched[:, 2] >= 5e-3)):
        if np.any(rows):
            errors, nees = matched[rows, 0], matched[rows, 1]
            print('tip_pose_covariance against the true tip of its stamp, %s: %d, error median '
                  '%.2f mm, p99 %.2f mm, max %.2f mm; 95 %% ellipsoid holds %.1f %%, NEES median '
                  '%.2f (2.37 when honest)' % (
                      name, np.sum(rows), 1e3 * np.median(errors),
                      1e3 * np.percentile(errors, 99), 1e3 * np.max(errors),
                      100.0 * np.mean(nees <= NEES_95), np.nanmedian(nees)))
    print('bringup RSS: ' + '; '.join(
        'run %d %.1f MB after its first goal, %.1f MB at its end (%+.1f MB)' % (
            i + 1, run['rss_start'], run['rss_end'], run['rss_end'] - run['rss_start'])
        for i, run in enumerate(f['runs'])))
    print('ready after start: %s s' % ', '.join('%.1f' % s for s in f.get('ready_s', [])))
    diagnostics = f['diagnostics']
    tracking = f['tracker']
    if tracking is not None:
        totals, reason = diagnostics.sensor_counts(f['sensor'])
        print('tracker: %d readings published, %d occlusions (%.1f s), %d ticks without a '
              'fresh true tip (bringup down)' % (tracking.published, tracking.occlusions,
                                                 tracking.occluded_s, tracking.no_truth))
        print('  statics (sensor_%s, summed over the runs): used %d, set aside %d, stale %d, '
              'rejected %d%s' % (f['sensor'], totals['used'], totals['set aside'],
                                 totals['stale'], totals['rejected'],
                                 '; last reason: %s' % reason[:120] if reason else ''))
    sources = diagnostics.tip_sources
    print('tip_controller judged goals on (its /diagnostics tip_source while moving, reports): '
          '%s' % (', '.join('%s %d' % kv for kv in sorted(sources.items())) or 'none seen'))
    print('  (tip_controller reports no count of trackers set aside; its WARN "tracker set '
          'aside" lines: %d)' % sum(
              sum('tracker set aside' in line for line in lines) for _, lines in f['logs']))
    set_aside_at(f)
    driver = diagnostics.values_of('cable_driver', 'real_time_factor')
    if any(v is not None for v in driver):
        print('cable_driver per run: real_time_factor %s, failed_steps %s, dropped_time_s %s, '
              'true_tip_from_model_m %s' % (
                  driver, diagnostics.values_of('cable_driver', 'failed_steps'),
                  diagnostics.values_of('cable_driver', 'dropped_time_s'),
                  diagnostics.values_of('cable_driver', 'true_tip_from_model_m')))
    outcomes = {}
    for epoch in diagnostics.latest:
        for key, value in epoch.get('tip_controller', {}).items():
            if key.startswith('goals_'):
                outcomes[key] = outcomes.get(key, 0) + int(value)
    if outcomes:
        print('tip_controller goal outcomes (its diagnostics, summed over the runs): %s'
              % ', '.join('%s %d' % kv for kv in sorted(outcomes.items())))
    rates = diagnostics.values_of('statics', 'output_rate_hz')
    print('statics output rate at the end of each run: %s Hz' % rates)
    print('WARN-or-worse diagnostics reports per node: %s' % (
        ', '.join('%s %d' % kv for kv in sorted(diagnostics.warn_reports.items())) or 'none'))
    if failed:
        print('FAILED:')
        for line in failed[:20]:
            print('  ' + line)
        return 1
    print('OK: every goal answered once, no callback raised, exit 0 at every SIGINT')
    return 0
