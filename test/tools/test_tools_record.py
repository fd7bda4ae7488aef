"""``record`` against the real nodes (bringup subprocess), read back with ``rosbags``; ``plot``.

One recording for the module: bringup (simulated driver) in a namespace of its own, the recorder
as a user runs it (``python -m continuum_statics record``, stopped with SIGINT), and a tip goal
sent on ``tip_goal_pose`` meanwhile so that commands, goals and motion are in the bag.
"""
import math
import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time
import uuid

from conftest import REPO
from nodes_helpers import LATCHED, RELIABLE, Collector, pose_xyz, stop_process
import numpy as np
import pytest
import yaml

rclpy = pytest.importorskip('rclpy')
from geometry_msgs.msg import PoseStamped  # noqa: E402
from rosbags.highlevel import AnyReader  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from continuum_statics import load_robot  # noqa: E402
from continuum_statics.tools import plot  # noqa: E402

pytestmark = pytest.mark.ros
ROBOT = load_robot(REPO / 'config' / 'tendon_robot.yaml')
PNG_SIGNATURE = b'\x89PNG\r\n\x1a\n'


class Lines:
    """Collects a subprocess's output lines in a thread, so tests can wait for one."""

    def __init__(self, process):
        self.lines = []
        self.thread = threading.Thread(target=self._read, args=(process,), daemon=True)
        self.thread.start()

    def _read(self, process):
        for line in process.stdout:
            self.lines.append(line.rstrip('\n'))

    def text(self):
        return '\n'.join(self.lines)


def spin_until(executor, predicate, timeout, what, processes=()):
    deadline = time.monotonic() + timeout
    while not predicate():
        for process in processes:
            assert process.poll() is None, '%s exited early' % process.args
        assert time.monotonic() < deadline, 'timed out after %g s waiting for %s' % (timeout, what)
        executor.spin_once(timeout_sec=0.02)


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """Record bringup for a few seconds around one tip goal; yield (bag, recorder output, ns)."""
    namespace = 'rec_' + uuid.uuid4().hex[:8]
    bag = tmp_path_factory.mktemp('record') / 'bag'
    env = os.environ.copy()
    bringup = subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics', 'bringup', '--namespace', namespace,
         '--ros-args', '--log-level', 'warn'], cwd=REPO, env=env, stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT)
    recorder = subprocess.Popen(
        [sys.executable, '-m', 'continuum_statics', 'record', '--namespace', namespace,
         '--output', str(bag)], cwd=REPO, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    output = Lines(recorder)
    context = rclpy.Context()
    rclpy.init(context=context)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    node = rclpy.create_node('record_test_client', namespace=namespace, context=context)
    executor.add_node(node)
    try:
        tips = Collector(node, PoseStamped, 'tip_pose', LATCHED)
        goals = node.create_publisher(PoseStamped, 'tip_goal_pose', RELIABLE)
        wanted = ['/%s/%s' % (namespace, t) for t in ('backbone', 'tip_pose', 'cable_states',
                                                      'cable_commands', 'tip_goal_pose')]
        wanted.append('/diagnostics')
        spin_until(executor, lambda: all('record: recording %s ' % t in output.text()
                                         for t in wanted),
                   60.0, 'the recorder to subscribe to %s' % wanted, [bringup, recorder])
        # The streaming goal reaches the controller and the recorder (both reliable).
        spin_until(executor, lambda: goals.get_subscription_count() >= 2, 30.0,
                   'tip_goal_pose subscribers', [bringup, recorder])
        # the recorder's cable_commands reader discovered too (driver + recorder), or the
        # half-second ramp can be over before it hears it
        spin_until(executor, lambda: node.count_subscribers(
            '/%s/cable_commands' % namespace) >= 2, 30.0, 'cable_commands subscribers',
                   [bringup, recorder])
        goal = ROBOT.solve_ivp([1.5, -1.0, 0.0]).tip_position
        msg = PoseStamped()
        msg.header.frame_id = 'base_link'
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in goal)
        msg.pose.orientation.w = 1.0
        goals.publish(msg)
        spin_until(executor, lambda: tips.last is not None and np.linalg.norm(
            pose_xyz(tips.last.pose) - goal) < 2e-3, 60.0, 'the tip at the goal', [bringup])
        # More tip poses after the goal, so /diagnostics (1 Hz) is in as well.
        count = len(tips)
        spin_until(executor, lambda: len(tips) > count + 200, 30.0, 'more tip poses',
                   [bringup, recorder])
        recorder.send_signal(signal.SIGINT)
        recorder.wait(timeout=30)
        output.thread.join(timeout=5)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        stop_process(recorder)
        stop_process(bringup)
    assert recorder.returncode == 0, output.text()
    yield bag, output.text(), namespace


def read_counts(bag):
    with AnyReader([Path(bag)]) as reader:
        counts = {}
        for connection, _, _ in reader.messages():
            counts[connection.topic] = counts.get(connection.topic, 0) + 1
        return counts


def test_record_writes_a_rosbag2_mcap_directory_readable_by_rosbags(recording):
    bag, output, namespace = recording
    metadata = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert metadata['storage_identifier'] == 'mcap'
    assert [f['path'] for f in metadata['files']] == ['bag.mcap'] and (bag / 'bag.mcap').is_file()
    topics = {t['topic_metadata']['name']: t for t in metadata['topics_with_message_count']}
    assert all(t['topic_metadata']['serialization_format'] == 'cdr' for t in topics.values())
    assert topics['/%s/backbone' % namespace]['topic_metadata']['type'] == 'nav_msgs/msg/Path'
    # Every message the metadata announces is in the MCAP file, topic by topic.
    counts = read_counts(bag)  # (topics that appeared but sent nothing, e.g. a lifecycle
    # transition_event, are listed with 0 messages, as ros2 bag record lists them)
    assert counts == {name: t['message_count'] for name, t in topics.items()
                      if t['message_count']}
    assert sum(counts.values()) == metadata['message_count']
    for topic in ('backbone', 'tip_pose', 'cable_states', 'cable_commands'):
        assert counts['/%s/%s' % (namespace, topic)] >= 10, counts
    assert counts['/diagnostics'] >= 2
    # The recorder's report per topic matches what is in the bag.
    for topic, count in counts.items():
        assert any(line.split()[:2] == [topic, str(count)] for line in output.splitlines()), (
            topic, count, output)


def test_recorded_path_deserializes_to_a_finite_backbone(recording):
    bag, _, namespace = recording
    with AnyReader([Path(bag)]) as reader:
        connections = [c for c in reader.connections if c.topic == '/%s/backbone' % namespace]
        paths = [reader.deserialize(raw, c.msgtype)
                 for c, _, raw in reader.messages(connections=connections)]
    last = paths[-1]
    points = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z]
                       for p in last.poses])
    assert last.header.frame_id == 'base_link' and len(last.poses) == 20
    assert np.all(np.isfinite(points))
    np.testing.assert_allclose(points[0], [0.0, 0.0, 0.0], atol=1e-9)
    # Base to tip along the rod: the polyline is as long as the rod (inextensible to 1e-3).
    assert math.isclose(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)), ROBOT.length,
                        rel_tol=1e-3)


def test_plot_writes_every_figure_of_a_recording(recording, tmp_path):
    bag, _, _ = recording
    result = subprocess.run([sys.executable, '-m', 'continuum_statics', 'plot', str(bag),
                             '--output', str(tmp_path)], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    for name in ('backbone.png', 'tip_path.png', 'cable_lengths.png', 'solver.png'):
        data = (tmp_path / name).read_bytes()
        assert data.startswith(PNG_SIGNATURE) and len(data) > 20000, name
    recording_data = plot.read_recording(bag)
    goals = np.array(recording_data.goals)[:, 1:]
    np.testing.assert_allclose(goals[0], ROBOT.solve_ivp([1.5, -1.0, 0.0]).tip_position,
                               atol=1e-6)
    assert len(recording_data.snapshots) >= 3
    assert set(recording_data.commanded) == set(ROBOT.cable_names)


def test_duration_namespace_filter_and_topic_list(harness, tmp_path):
    """Only the namespace (or the listed topics) is recorded, for --duration seconds."""
    from continuum_statics.tools.record import record

    node = harness.client()
    inside = node.create_publisher(PoseStamped, 'tip_goal_pose', RELIABLE)
    outside = node.create_publisher(PoseStamped, '/elsewhere/tip_goal_pose', RELIABLE)
    stop = threading.Event()

    def publish():
        while not stop.is_set():
            inside.publish(PoseStamped())
            outside.publish(PoseStamped())
            time.sleep(0.01)

    publisher = threading.Thread(target=publish, daemon=True)
    publisher.start()

    def until_recorded(topic, seconds=1.5):
        """Stop ``seconds`` after the recorder subscribed to ``topic`` (discovery varies)."""
        subscribed = []

        def log(text):
            if text.startswith('record: recording %s ' % topic):
                subscribed.append(time.monotonic())
        return log, lambda: bool(subscribed) and time.monotonic() > subscribed[0] + seconds

    try:
        namespace = harness.namespace.strip('/')
        mine = '/%s/tip_goal_pose' % namespace
        log, done = until_recorded(mine)
        counts, _ = record(tmp_path / 'all', duration=30.0, namespace=namespace, log=log,
                           stop_requested=done)
        log, done = until_recorded('/elsewhere/tip_goal_pose')
        listed, _ = record(tmp_path / 'listed', duration=30.0, namespace=namespace,
                           topics=['/elsewhere/tip_goal_pose'], log=log, stop_requested=done)
        start = time.monotonic()
        _, times = record(tmp_path / 'short', duration=0.5, namespace=namespace,
                          log=lambda text: None)
        assert time.monotonic() - start >= 0.5 and mine in times
    finally:
        stop.set()
        publisher.join()
    # /diagnostics is in the default set too (another test's node may still be publishing it).
    assert set(counts) - {'/diagnostics'} == {mine} and counts[mine] > 10
    assert set(listed) == {'/elsewhere/tip_goal_pose'} and listed['/elsewhere/tip_goal_pose'] > 10
    assert read_counts(tmp_path / 'all') == {t: n for t, n in counts.items() if n}
    with pytest.raises(ValueError, match='exists already'):
        record(tmp_path / 'all', duration=0.1, namespace=namespace)


def test_move_tip_feedback_and_status_are_recorded_and_read_back(harness, tmp_path):
    """The package's own action topics: feedback (MoveTip_FeedbackMessage) and status.

    Before: 'not recording .../move_tip/_action/feedback: no message definition installed'.
    """
    from continuum_statics.nodes.action_client import HandoverActionClient
    from continuum_statics.nodes.cable_driver_node import CableDriverNode
    from continuum_statics.nodes.statics_node import StaticsNode
    from continuum_statics.nodes.tip_controller_node import TipControllerNode
    from continuum_statics.tools.record import record

    MoveTip = pytest.importorskip('continuum_statics_interfaces.action').MoveTip
    harness.add(StaticsNode, marker_rate=0.0)
    harness.add(CableDriverNode)
    harness.add(TipControllerNode, max_cable_speed=0.01)  # a ramp long enough to record
    node = harness.client()
    action = HandoverActionClient(node, MoveTip, 'move_tip')
    assert action.wait_for_server(timeout_sec=10.0)
    namespace = harness.namespace.strip('/')
    feedback_topic = '/%s/move_tip/_action/feedback' % namespace
    status_topic = '/%s/move_tip/_action/status' % namespace
    logged, results = [], []

    def send_when_subscribed(text):
        logged.append(text)
        if text.startswith('record: recording %s ' % feedback_topic):
            goal = MoveTip.Goal(tolerance=1e-3)
            goal.target.header.frame_id = 'base_link'
            p = goal.target.pose.position
            p.x, p.y, p.z = (float(v) for v in ROBOT.solve_ivp([2.0, -1.0, 0.0]).tip_position)
            goal.target.pose.orientation.w = 1.0
            future = action.send_goal_async(goal)
            future.add_done_callback(
                lambda f: f.result().get_result_async().add_done_callback(results.append))

    # the action's topics exist once the server does: the recorder subscribes at its start
    record(tmp_path / 'bag', duration=30.0, namespace=namespace, log=send_when_subscribed,
           stop_requested=lambda: bool(results))
    assert not [line for line in logged if 'not recording' in line], logged
    counts = read_counts(tmp_path / 'bag')
    assert counts.get(feedback_topic, 0) >= 3, counts
    assert counts.get(status_topic, 0) >= 1, counts
    with AnyReader([tmp_path / 'bag']) as reader:
        connections = [c for c in reader.connections if c.topic == feedback_topic]
        distances = [reader.deserialize(raw, c.msgtype).feedback.distance
                     for c, _, raw in reader.messages(connections=connections)]
    assert connections[0].msgtype == 'continuum_statics_interfaces/action/MoveTip_FeedbackMessage'
    known = [d for d in distances if d >= 0.0]
    assert known and known[0] > known[-1], distances  # the tip got closer


def bag_stamps(bag, topic):
    """Receive stamps (ns) of ``topic``'s messages in ``bag``."""
    with AnyReader([Path(bag)]) as reader:
        connections = [c for c in reader.connections if c.topic == topic]
        return [stamp for _, stamp, _ in reader.messages(connections=connections)]


def test_duration_counts_from_the_first_message_and_rates_are_over_the_span(
        harness, tmp_path, capsys):
    """Issue 44: --duration counts from the first message; rates are over the topic's span.

    The clock started at launch (discovery ate 1-4 s of --duration) and the rate was the count
    over the requested time (`--duration 5`: 2.36 s saved, 96.4 Hz printed for 204 Hz).
    """
    from continuum_statics.tools import record as recorder

    node = harness.client()
    publisher = node.create_publisher(JointState, 'cable_states', RELIABLE)
    topic = '%s/cable_states' % harness.namespace
    subscribed, stop = threading.Event(), threading.Event()

    def publish():
        # the first message 2 s after the recorder subscribed: later than --duration 1.5
        # counted from launch, whatever discovery takes
        subscribed.wait(60.0)
        stop.wait(2.0)
        while not stop.is_set():
            publisher.publish(JointState(name=['c0'], position=[0.3]))
            time.sleep(0.005)

    def log(text):
        if text.startswith('record: recording %s ' % topic):
            subscribed.set()

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        counts, times = recorder.record(tmp_path / 'bag', duration=1.5, topics=[topic],
                                        log=log)
    finally:
        stop.set()
        thread.join()
    stamps = bag_stamps(tmp_path / 'bag', topic)
    # before: 0 messages (the 1.5 s had run out before the first message came)
    assert counts[topic] == len(stamps) > 50, counts
    # the whole 1.5 s from the first message is in the bag (less the last inter-message gap;
    # 0.5 s of slack for a loaded machine)
    assert times[topic] == (stamps[0], stamps[-1])
    assert recorder.recorded_span(times) == (stamps[-1] - stamps[0]) * 1e-9 > 1.0
    recorder.print_summary(tmp_path / 'bag', counts, times)
    line = next(line for line in capsys.readouterr().out.splitlines()
                if line.startswith(topic)).split()
    # messages, span (s) and rate (Hz) over the topic's own first-to-last span
    span = (stamps[-1] - stamps[0]) * 1e-9
    assert line[1:] == [str(len(stamps)), '%.2f' % span, '%.1f' % ((len(stamps) - 1) / span)]


def test_the_summary_says_what_the_span_and_rates_are_over(capsys):
    """A 200 Hz topic recorded for 5 s and a 1 Hz one: each rate over its own span."""
    from continuum_statics.tools.record import print_summary

    counts = {'/c/cable_states': 1001, '/diagnostics': 5, '/c/tip_pose': 1}
    times = {'/c/cable_states': (10 ** 9, 6 * 10 ** 9), '/diagnostics': (2 * 10 ** 9, 6 * 10 ** 9),
             '/c/tip_pose': (3 * 10 ** 9, 3 * 10 ** 9)}
    print_summary('bag', counts, times)
    out = capsys.readouterr().out
    # before: counts over the requested time: with --duration 10 'record: 10.0 s' and
    # cable_states 100.1 Hz, /diagnostics 0.5 Hz, tip_pose 0.1 Hz (from one message)
    assert out.startswith('record: 5.00 s from the first to the last message into bag\n'), out
    rows = {line.split()[0]: line.split()[1:] for line in out.splitlines()[2:5]}
    assert rows == {'/c/cable_states': ['1001', '5.00', '200.0'],
                    '/diagnostics': ['5', '4.00', '1.0'], '/c/tip_pose': ['1', '0.00', '-']}
    assert '(span: first to last message of the topic; rate: (messages - 1) / span)' in out
