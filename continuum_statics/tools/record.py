"""``python -m continuum_statics record``: the robot's topics into a rosbag2 directory (MCAP).

What ``ros2 bag record`` writes, without rosbag2 installed: a directory with ``metadata.yaml`` and
one ``.mcap`` file (ros2 profile, cdr messages, ros2msg schemas), written by the ``rosbags``
writer from the raw serialized messages (``raw=True`` subscriptions: nothing is deserialized).
Memory stays bounded: the writer flushes a chunk every MiB and keeps only its small index.

Default topics: everything in the robot's namespace (default ``continuum``) plus
``/diagnostics``, subscribed as they appear. The subscription QoS follows the publishers, as
``ros2 bag record`` does: reliable only if every publisher is, transient local only if every
publisher is (so the latched backbone and tip pose are recorded even when they are not
republished). Ctrl-C (SIGINT) or SIGTERM ends the recording with a complete bag.

``--duration`` counts from the first message written, not from start-up: discovery and
subscription matching take 1-4 s, which a clock started at launch cut off the recording (issue
44). Rates are over each topic's own span, first to last message.
"""
import argparse
import datetime
import importlib
from importlib import metadata as package_metadata
import os
from pathlib import Path
import signal
import sys
import time

DEFAULT_NAMESPACE = 'continuum'
#: Topics recorded besides the namespace's own (absolute names).
EXTRA_TOPICS = ('/diagnostics',)
#: How often the graph is searched for new topics (s).
DISCOVERY_PERIOD = 0.5
#: Longest wait for the first message when a duration is given (s; at least the duration):
#: a recording of nothing then ends instead of waiting for Ctrl-C.
FIRST_MESSAGE_WAIT = 30.0


def _print(text):
    print(text, flush=True)


def ros_distro():
    """Return the running ROS 2 distribution ('jazzy', 'kilted', ...), or '' if unknown."""
    distro = os.environ.get('ROS_DISTRO', '')
    if distro:
        return distro
    try:  # pip route: the rclpy wheel's version tells the distribution
        major = int(package_metadata.version('ros-rclpy').split('.')[0])
    except (package_metadata.PackageNotFoundError, ValueError):
        return ''
    return {7: 'jazzy', 9: 'kilted'}.get(major, '')


def make_typestore():
    """Return a rosbags type store of the running distribution (definitions and hashes)."""
    from rosbags.typesys import Stores, get_typestore

    store = {'humble': Stores.ROS2_HUMBLE, 'jazzy': Stores.ROS2_JAZZY,
             'kilted': Stores.ROS2_KILTED}.get(ros_distro(), Stores.LATEST)
    return get_typestore(store)


def _interface_dirs():
    """Prefixes whose ``share/<package>/msg`` hold installed .msg files (ament index, venv)."""
    prefixes = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return [Path(p) / 'share' for p in prefixes] + [Path(sys.prefix) / 'share']


def register_type(typestore, msgtype):
    """Make sure ``msgtype`` ('pkg/msg/Name') and its field types are in ``typestore``.

    Standard types are already there; others are read from the installed .msg files.

    :raises ValueError: when no definition of the type (or of a field type) is installed
    """
    from rosbags.typesys import get_types_from_msg

    pending = [msgtype]
    while pending:
        name = pending.pop()
        if name in typestore.fielddefs:
            continue
        types = get_types_from_msg(_definition(name), name)
        missing = set()
        for _, fields in types.values():
            for _, (kind, detail) in fields:
                for candidate in _nested_names(kind, detail):
                    if candidate not in typestore.fielddefs and candidate not in types:
                        missing.add(candidate)
        if missing:
            pending.append(name)
            pending.extend(sorted(missing))
            continue
        typestore.register(types)


#: The message types rosidl makes of an action ``A`` and where their fields come from: the
#: parts of ``A.action`` (goal --- result --- feedback) or the feedback topic's wrapper. The
#: wrapper's feedback field is named ``pkg/msg/A_Feedback`` in a bag's definitions (rosbags
#: writes nested definitions of /msg/ types only; the bytes and every reader's decoding are
#: the same).
ACTION_PARTS = {'_Goal': 0, '_Result': 1, '_Feedback': 2}
FEEDBACK_MESSAGE = ('unique_identifier_msgs/UUID goal_id\n'
                    '%s/msg/%s_Feedback feedback\n')


def _definition(msgtype):
    """Return the text of an installed message definition.

    ``pkg/msg/Name`` from its .msg file; an action's topic types (``pkg/action/A_Feedback
    Message`` and its parts) from ``A.action``.

    :raises ValueError: when none is installed
    """
    package, kind, short = msgtype.split('/')
    if kind == 'action' and short.endswith('_FeedbackMessage'):
        action = short[:-len('_FeedbackMessage')]
        _installed(package, 'action', action + '.action', msgtype)
        return FEEDBACK_MESSAGE % (package, action)
    if kind == 'msg':
        try:
            return _installed(package, 'msg', short + '.msg', msgtype)
        except ValueError:
            if not short.endswith(tuple(ACTION_PARTS)):
                raise
    for suffix, part in ACTION_PARTS.items():
        if short.endswith(suffix):
            text = _installed(package, 'action', short[:-len(suffix)] + '.action', msgtype)
            return text.split('\n---')[part]
    raise ValueError('no message definition for %s installed' % msgtype)


def _installed(package, kind, filename, msgtype):
    """Text of ``share/<package>/<kind>/<filename>`` of the first prefix that has it."""
    for share in _interface_dirs():
        path = share / package / kind / filename
        if path.is_file():
            return path.read_text(encoding='utf-8')
    raise ValueError('no message definition for %s installed' % msgtype)


def _nested_names(kind, detail):
    """Names of message types a rosbags field refers to (plain, array or sequence)."""
    from rosbags.typesys.base import Nodetype

    if kind == Nodetype.NAME:
        return [detail]
    if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
        inner_kind, inner = detail[0]
        return _nested_names(inner_kind, inner)
    return []


def message_class(msgtype):
    """Return the message class of 'pkg/msg/Name' (raw subscriptions need it too)."""
    package, kind, name = msgtype.split('/')
    module = importlib.import_module('%s.%s' % (package, kind))
    if kind == 'action' and not hasattr(module, name):  # A_FeedbackMessage: A.Impl's
        action, _, part = name.partition('_')
        return getattr(getattr(module, action).Impl, part)
    return getattr(module, name)


def wanted(topic, namespace, topics):
    """Return True if ``topic`` is to be recorded: listed, or in the namespace / an extra topic."""
    if topics:
        return topic in topics
    prefix = '/' + namespace.strip('/') + '/'
    return topic.startswith(prefix) or topic in EXTRA_TOPICS


def absolute_topics(topics, namespace):
    """Resolve relative topic names against the robot's namespace."""
    ns = '/' + namespace.strip('/')
    return {t if t.startswith('/') else '%s/%s' % (ns.rstrip('/'), t) for t in topics}


class Recorder:
    """Subscribes to wanted topics as they appear and writes every message to a rosbag2 writer.

    All callbacks run in the thread that spins ``node``, which is also the one that adds
    connections, so the writer needs no lock. ``times`` holds each topic's first and last
    receive stamp (ns, the bag's clock); ``started`` the monotonic time of the first message (s).
    """

    def __init__(self, node, writer, namespace=DEFAULT_NAMESPACE, topics=(), log=_print):
        self.node = node
        self.writer = writer
        self.namespace = namespace
        self.topics = absolute_topics(topics, namespace)
        self.log = log
        self.typestore = make_typestore()
        self.counts = {}
        self.times = {}
        self.started = None
        self.subscriptions = {}
        self.skipped = {}

    def discover(self):
        """Subscribe to every wanted topic that has publishers and no subscription yet."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self.subscriptions or topic in self.skipped:
                continue
            if not wanted(topic, self.namespace, self.topics):
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            if len(types) != 1:
                self._skip(topic, 'more than one type on it: %s' % ', '.join(types))
                continue
            try:
                self._subscribe(topic, types[0], publishers)
            except (ValueError, ImportError, AttributeError) as error:
                self._skip(topic, str(error))

    def _skip(self, topic, reason):
        self.skipped[topic] = reason
        self.log('record: not recording %s: %s' % (topic, reason))

    def _subscribe(self, topic, msgtype, publishers):
        register_type(self.typestore, msgtype)
        qos = subscription_qos(publishers)
        connection = self.writer.add_connection(
            topic, msgtype, typestore=self.typestore, serialization_format='cdr',
            offered_qos_profiles=[offered_qos(info.qos_profile) for info in publishers])
        self.counts[topic] = 0

        def write(data, topic=topic, connection=connection):
            stamp = time.time_ns()
            self.writer.write(connection, stamp, data)
            self.counts[topic] += 1
            self.times[topic] = (self.times.get(topic, (stamp,))[0], stamp)
            if self.started is None:
                self.started = time.monotonic()

        self.subscriptions[topic] = self.node.create_subscription(
            message_class(msgtype), topic, write, qos, raw=True)
        self.log('record: recording %s (%s)' % (topic, msgtype))


def subscription_qos(publishers):
    """Subscription QoS compatible with every publisher, as ``ros2 bag record`` picks it."""
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    reliable = all(p.qos_profile.reliability == ReliabilityPolicy.RELIABLE for p in publishers)
    latched = all(p.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                  for p in publishers)
    return QoSProfile(
        depth=100,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


def offered_qos(profile):
    """Convert a publisher's QoS to what rosbags writes as ``offered_qos_profiles``."""
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, ReliabilityPolicy
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    zero = QosTime(0, 0)
    history = (QosHistory.KEEP_ALL if profile.history == HistoryPolicy.KEEP_ALL
               else QosHistory.KEEP_LAST)
    reliability = (QosReliability.RELIABLE if profile.reliability == ReliabilityPolicy.RELIABLE
                   else QosReliability.BEST_EFFORT)
    durability = (QosDurability.TRANSIENT_LOCAL
                  if profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
                  else QosDurability.VOLATILE)
    return Qos(history, int(profile.depth), reliability, durability, zero, zero,
               QosLiveliness.AUTOMATIC, zero, False)


def default_output():
    """Return ``rosbag2_YYYY_MM_DD-HH_MM_SS``, the name ``ros2 bag record`` would pick."""
    return datetime.datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S')


def record(output, duration=None, namespace=DEFAULT_NAMESPACE, topics=(), log=_print,
           stop_requested=lambda: False):
    """Record ``duration`` s from the first message, or until ``stop_requested()``.

    With a duration and no message within ``max(duration, FIRST_MESSAGE_WAIT)`` s, it stops
    with an empty bag.

    :returns: (dict topic -> message count, dict topic -> (first, last) receive stamp in ns;
        a topic subscribed that sent nothing has a count of 0 and no stamps)
    :raises ValueError: when ``output`` exists (a bag is never overwritten)
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.errors import WriterError

    try:
        writer = Writer(output, version=9, storage_plugin=StoragePlugin.MCAP)
        writer.open()
    except WriterError as error:
        raise ValueError(str(error)) from None
    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node('recorder', namespace='/', context=context,
                             start_parameter_services=False)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(node)
    recorder = Recorder(node, writer, namespace, topics, log)
    start = time.monotonic()
    next_discovery = start
    try:
        while not stop_requested():
            now = time.monotonic()
            if duration is not None and (
                    now - start >= max(duration, FIRST_MESSAGE_WAIT) if recorder.started is None
                    else now - recorder.started >= duration):
                break
            if now >= next_discovery:
                recorder.discover()
                next_discovery = now + DISCOVERY_PERIOD
            executor.spin_once(timeout_sec=0.05)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        writer.close()
    return dict(recorder.counts), dict(recorder.times)


def recorded_span(times):
    """Seconds from the first to the last message of a recording (0 without messages).

    :param times: topic -> (first, last) receive stamp, ns
    """
    if not times:
        return 0.0
    return (max(last for _, last in times.values())
            - min(first for first, _ in times.values())) * 1e-9


def topic_rate(count, first_last):
    """Rate of a topic over its own span (Hz): (count - 1) / (last - first); None below 2.

    Over the topic's span, not the recording's: a topic discovered late, or a 1 Hz one whose
    next message is due after the end, is not diluted by time it could not be heard in.
    """
    if count < 2 or first_last is None or first_last[1] <= first_last[0]:
        return None
    return (count - 1) / ((first_last[1] - first_last[0]) * 1e-9)


def main(argv=None):
    """Record the robot's topics; prints messages per topic. Returns the exit code."""
    parser = argparse.ArgumentParser(
        prog='python -m continuum_statics record',
        description="Record the robot's topics into a rosbag2 directory (metadata.yaml + MCAP, "
                    'cdr), readable by ros2 bag, Foxglove and rosbags. Ctrl-C ends it.')
    parser.add_argument('--output', '-o', default=None,
                        help='bag directory to create (default rosbag2_<date>-<time>)')
    parser.add_argument('--duration', type=float, default=None,
                        help='stop after this many seconds (default: until Ctrl-C)')
    parser.add_argument('--namespace', default=DEFAULT_NAMESPACE,
                        help='robot namespace whose topics are recorded (default %(default)s)')
    parser.add_argument('--topics', nargs='+', default=(), metavar='TOPIC',
                        help='record only these topics (relative names are in the namespace)')
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.duration is not None and not args.duration > 0.0:
        parser.error('--duration must be > 0 s')
    output = args.output or default_output()
    stop = []

    def on_signal(signum, frame):
        stop.append(signum)

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    what = (' '.join(sorted(absolute_topics(args.topics, args.namespace))) if args.topics
            else '/%s/* and %s' % (args.namespace.strip('/'), ' '.join(EXTRA_TOPICS)))
    print('record: %s -> %s (ROS_DOMAIN_ID %s); %s' % (
        what, output, os.environ.get('ROS_DOMAIN_ID', '0'),
        '%g s from the first message' % args.duration if args.duration else 'Ctrl-C to stop'),
        flush=True)
    try:
        counts, times = record(output, args.duration, args.namespace, args.topics,
                               stop_requested=lambda: bool(stop))
    except ValueError as error:
        print('error: %s' % error, file=sys.stderr)
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    print_summary(output, counts, times)
    never = sorted(absolute_topics(args.topics, args.namespace) - set(counts))
    if never:
        print('record: never saw a publisher on %s' % ', '.join(never), flush=True)
    return 0


def print_summary(output, counts, times):
    """Print the recorded span, and messages, span and rate per topic.

    :param times: topic -> (first, last) receive stamp, ns (as :func:`record` returns)
    """
    print('record: %.2f s from the first to the last message into %s' % (
        recorded_span(times), output))
    print('%-44s %9s %8s %9s' % ('topic', 'messages', 'span[s]', 'rate[Hz]'))
    for topic in sorted(counts):
        first_last = times.get(topic)
        span = 0.0 if first_last is None else (first_last[1] - first_last[0]) * 1e-9
        rate = topic_rate(counts[topic], first_last)
        print('%-44s %9d %8.2f %9s' % (topic, counts[topic], span,
                                       '-' if rate is None else '%.1f' % rate))
    print('%-44s %9d' % ('total', sum(counts.values())))
    print('(span: first to last message of the topic; rate: (messages - 1) / span)', flush=True)
    if not counts:
        print('record: no topics found: is the robot running in this ROS_DOMAIN_ID and '
              'namespace?', flush=True)


if __name__ == '__main__':
    sys.exit(main())
