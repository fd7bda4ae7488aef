"""``python -m continuum_statics doctor [--namespace NS]``: what is wrong, and what to do.

Looks at the environment (domain id, discovery range), the robot file, the kernel cache and, for
``--duration`` seconds, the robot's namespace in the ROS graph: the nodes and their
``/diagnostics``, the driver's lifecycle state (and why a transition failed) and homing, topic
rates against the parameters (read from the running nodes), /tf, every sensor's frame and stamp
(the robot file's ``sensors/<name>`` too, once statics names its robot file), and on real
tendons the measured tensions against the model's for the measured lengths. The conclusions are
:mod:`.doctor_checks`'s; each finding says the one thing to do. Exit code 1 when any finding is
an error.

On a robot computer the same checks run inside ``ros2 doctor`` (entry points
``ros2doctor.checks`` and ``ros2doctor.report``: :class:`RobotCheck`, :class:`RobotReport`; the
namespace from ``CONTINUUM_STATICS_NAMESPACE``, default ``continuum``).
"""
import argparse
import json
import os
import sys
import time

from continuum_statics.tools.doctor_checks import (
    ERROR,
    WARN,
    CableSample,
    Observation,
    TopicSample,
    diagnose,
    worst,
)

#: Environment variables a diagnosis reports.
ENV_KEYS = ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_STATIC_PEERS',
            'ROS_LOCALHOST_ONLY', 'RMW_IMPLEMENTATION')
#: Parameters read from each running node (name -> parameters).
NODE_PARAMETERS = {'statics': ('robot_file', 'publish_tf', 'tip_frame_id'),
                   'cable_driver': ('backend', 'publish_rate', 'home_file')}
#: Topics sampled (relative to the namespace), with their message types' import paths.
SAMPLED_TOPICS = {'cable_states': 'sensor_msgs.msg:JointState',
                  'backbone': 'nav_msgs.msg:Path',
                  'tip_pose_measured': 'geometry_msgs.msg:PoseStamped',
                  'tip_wrench': 'geometry_msgs.msg:WrenchStamped'}


def kernel_cache_state():
    """Return (kernels found in numba's cache, kernels): nothing is compiled to find out."""
    import importlib

    from continuum_statics.core.warmup import ENTRY_POINTS

    cached = 0
    for dotted in ENTRY_POINTS:
        module, name = dotted.rsplit('.', 1)
        dispatcher = getattr(importlib.import_module(module), name)
        cache = getattr(dispatcher, '_cache', None)  # numba's FunctionCache of a cache=True jit
        index = getattr(getattr(cache, '_cache_file', None), '_index_path', None)
        cached += bool(index and os.path.isfile(index))
    return cached, len(ENTRY_POINTS)


def absolute_namespace(namespace):
    """Return '/ns' for 'ns', '/ns' or '/ns/'."""
    return '/' + namespace.strip('/')


def observe(namespace='continuum', duration=3.0, robot_file=None, domain_id=None, graph=True):
    """Gather an :class:`Observation` of one robot namespace.

    :param domain_id: ROS domain to look in (None: ``ROS_DOMAIN_ID`` as ROS reads it)
    :param graph: False: environment, robot file and kernels only (no DDS)
    """
    observation = Observation(environment={key: os.environ.get(key, '') for key in ENV_KEYS},
                              namespace=absolute_namespace(namespace), duration=duration,
                              graph_seen=graph)
    from continuum_statics.config_paths import resolve_config_path

    if domain_id is not None:
        observation.environment['ROS_DOMAIN_ID'] = str(domain_id)
    observation.kernels_cached = kernel_cache_state()
    samplers = _observe_graph(observation, domain_id, robot_file) if graph else {}
    statics_file = observation.parameters.get('statics', {}).get('robot_file')
    if not observation.robot_file or not robot_file and statics_file and \
            resolve_config_path(statics_file) != observation.robot_file:  # statics seen late
        observation.robot, observation.robot_error = None, ''
        _load_robot(observation, robot_file)
    if observation.robot is not None and 'cable_states' in samplers:
        observation.cables = samplers['cable_states'].cables(observation.robot.cable_names)
    if 'tip_wrench' in samplers:
        observation.tip_force = samplers['tip_wrench'].mean_force()
    return observation


def _load_robot(observation, robot_file=None):
    """Load the robot file the nodes use: ``robot_file``, else statics', else the shipped one."""
    from continuum_statics import load_robot
    from continuum_statics.config_paths import default_robot_file, resolve_config_path

    path = robot_file or observation.parameters.get('statics', {}).get('robot_file') \
        or default_robot_file()
    observation.robot_file = resolve_config_path(path)
    try:
        observation.robot = load_robot(observation.robot_file)
    except (ValueError, OSError) as error:
        observation.robot_error = str(error)


class _Sampler:
    """Counts, rate, last frame and age of one topic's messages.

    And their values, for ``cable_states`` and ``tip_wrench``.
    """

    def __init__(self, clock):
        self.clock = clock
        self.times = []
        self.frame_id = ''
        self.age = None
        self.values = []  # (names, positions, efforts) of JointStates; forces of wrenches

    def __call__(self, msg):
        self.times.append(time.monotonic())
        header = getattr(msg, 'header', None)
        if header is not None:
            self.frame_id = header.frame_id
            stamp = header.stamp.sec + 1e-9 * header.stamp.nanosec
            self.age = (self.clock.now().nanoseconds * 1e-9 - stamp) if stamp else None
        if hasattr(msg, 'effort'):
            self.values.append((tuple(msg.name), tuple(msg.position), tuple(msg.effort)))
        elif hasattr(msg, 'wrench'):
            force = msg.wrench.force
            self.values.append((force.x, force.y, force.z))

    def cables(self, names):
        """Return the :class:`CableSample` of the JointStates that name ``names``, or None."""
        import numpy as np

        names = tuple(names)
        lengths, efforts = [], []
        for got, positions, effort in self.values:
            if set(got) != set(names) or len(positions) != len(got):
                continue
            order = [got.index(name) for name in names]
            lengths.append([positions[i] for i in order])
            if len(effort) == len(got):
                efforts.append([effort[i] for i in order])
        if not lengths:
            return None
        efforts = np.array(efforts, dtype=float).reshape(-1, len(names))
        known = len(efforts) == len(lengths) and bool(np.all(np.isfinite(efforts)))
        return CableSample(np.mean(lengths, axis=0), np.mean(efforts, axis=0) if known else
                           None, np.std(efforts, axis=0) if known else None, len(lengths))

    def mean_force(self):
        """Return the mean force (3,) N of the wrenches received, or None."""
        import numpy as np

        return np.mean(self.values, axis=0) if self.values else None

    def sample(self, publishers):
        rate = 0.0
        if len(self.times) >= 2 and self.times[-1] > self.times[0]:
            rate = (len(self.times) - 1) / (self.times[-1] - self.times[0])
        return TopicSample(publishers, len(self.times), rate, self.frame_id, self.age)


def _message_class(path):
    import importlib

    module, name = path.split(':')
    return getattr(importlib.import_module(module), name)


def _observe_graph(observation, domain_id, robot_file=None):
    """Watch the graph; return the topic samplers by relative topic name."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import qos_profile_sensor_data

    context = rclpy.Context()
    if domain_id is None:
        rclpy.init(context=context)
    else:
        rclpy.init(context=context, domain_id=int(domain_id))
    node = rclpy.create_node('continuum_doctor_%d' % os.getpid(), context=context,
                             start_parameter_services=False)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        return _watch(observation, node, executor, qos_profile_sensor_data, robot_file)
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def _watch(observation, node, executor, sensor_qos, robot_file=None):
    from diagnostic_msgs.msg import DiagnosticArray

    ns = observation.namespace.rstrip('/')
    statuses = observation.statuses

    def on_diagnostics(msg):
        for status in msg.status:
            statuses[status.name] = (_LEVEL_NAMES.get(ord(status.level), WARN), status.message,
                                     {kv.key: kv.value for kv in status.values})

    node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 100)
    samplers = {}

    def sample(topic, message_class):
        samplers[topic] = _Sampler(node.get_clock())
        node.create_subscription(message_class, '%s/%s' % (ns, topic), samplers[topic],
                                 sensor_qos)

    for topic, path in SAMPLED_TOPICS.items():
        sample(topic, _message_class(path))

    def on_found(nodes):
        """Once the namespace is seen: the robot file statics runs, and its sensors sampled."""
        if 'statics' in nodes:
            observation.parameters['statics'] = _parameters(
                node, executor, '%s/statics' % ns, NODE_PARAMETERS['statics'])
        _load_robot(observation, robot_file)
        sensors = () if observation.robot is None else observation.robot.sensors
        for sensor in sensors:
            sample('sensors/%s' % sensor.name, _message_class(
                'geometry_msgs.msg:PoseWithCovarianceStamped' if sensor.covariance
                else 'geometry_msgs.msg:PoseStamped'))
        return bool(sensors)  # a full window more for the sensors' topics

    tf_frames = set()
    try:
        from tf2_msgs.msg import TFMessage

        node.create_subscription(TFMessage, '/tf', lambda msg: tf_frames.update(
            (t.header.frame_id, t.child_frame_id) for t in msg.transforms), sensor_qos)
    except ImportError:  # no tf2_msgs: the tf check says nothing
        pass
    observation.nodes = _watch_until_found(node, executor, ns, observation.duration, on_found)
    for name, parameters in NODE_PARAMETERS.items():
        if name in observation.nodes and not observation.parameters.get(name):
            observation.parameters[name] = _parameters(node, executor, '%s/%s' % (ns, name),
                                                       parameters)
    observation.topics = {topic: sampler.sample(node.count_publishers('%s/%s' % (ns, topic)))
                          for topic, sampler in samplers.items()}
    observation.tf_frames = tuple(sorted(tf_frames))
    return samplers


_LEVEL_NAMES = {0: 'ok', 1: WARN, 2: ERROR, 3: WARN}
#: Longer watch, s, when no node of the namespace has been discovered yet (a busy machine's DDS
#: discovery); a namespace found late is watched for at least a second more.
DISCOVERY_GRACE = 5.0


def _watch_until_found(node, executor, ns, duration, on_found=None):
    """Spin for ``duration`` s (longer while the namespace has no node); return its nodes.

    ``on_found(nodes)`` is called once, when the namespace's nodes are first seen (else at the
    end); True from it watches ``duration`` s more (for the subscriptions it made).
    """
    start = time.monotonic()
    end, found, next_look = start + duration, (), start
    while True:
        executor.spin_once(timeout_sec=0.05)
        now = time.monotonic()
        if now >= next_look:
            next_look = now + 0.2
            if not found:
                found = tuple(sorted(name for name, namespace in
                                     node.get_node_names_and_namespaces()
                                     if namespace.rstrip('/') == ns))
                if found:
                    end = max(end, now + min(duration, 1.0))
                    if on_found is not None and on_found(found):
                        end = max(end, time.monotonic() + duration)
                    on_found = None
        if now >= end and (found or now >= start + duration + DISCOVERY_GRACE):
            break
    if on_found is not None:  # nothing found: the robot file all the same
        on_found(())
    return tuple(sorted(name for name, namespace in node.get_node_names_and_namespaces()
                        if namespace.rstrip('/') == ns))


def _parameters(node, executor, node_name, names, timeout=3.0):
    """Return {name: value} of a running node's parameters ({} when it does not answer)."""
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python

    client = node.create_client(GetParameters, node_name + '/get_parameters')
    try:
        if not client.wait_for_service(timeout_sec=timeout):
            return {}
        future = client.call_async(GetParameters.Request(names=list(names)))
        executor.spin_until_future_complete(future, timeout_sec=timeout)
        if not future.done() or future.result() is None:
            return {}
        return {name: parameter_value_to_python(value)
                for name, value in zip(names, future.result().values)}
    finally:
        node.destroy_client(client)


def render(findings, stream):
    """Print the findings: one line each, the action indented below it."""
    for finding in findings:
        stream.write('[%-5s] %-12s %s\n' % (finding.level.upper() if finding.level in (
            WARN, ERROR) else finding.level, finding.check, finding.message))
        if finding.action:
            stream.write('%22s-> %s\n' % ('', finding.action))
    counts = {level: sum(f.level == level for f in findings) for level in (ERROR, WARN)}
    stream.write('doctor: %d error(s), %d warning(s)\n' % (counts[ERROR], counts[WARN]))


def main(argv=None):
    """Run the checks once and print the findings (``--json``: one JSON object)."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics doctor',
                                     description=__doc__.split('\n')[0])
    parser.add_argument('--namespace', default='continuum', help="the robot's namespace")
    parser.add_argument('--robot', default=None, help='robot file (default: the one statics '
                        'runs with, else the shipped tendon robot)')
    parser.add_argument('--duration', type=float, default=3.0,
                        help='seconds to watch the ROS graph (default 3)')
    parser.add_argument('--no-graph', action='store_true',
                        help='environment, robot file and kernels only')
    parser.add_argument('--json', action='store_true', help='print one JSON object')
    args = parser.parse_args(argv)
    findings = diagnose(observe(args.namespace, args.duration, args.robot,
                                graph=not args.no_graph))
    if args.json:
        print(json.dumps({'worst': worst(findings),
                          'findings': [f.as_dict() for f in findings]}, indent=1))
    else:
        render(findings, sys.stdout)
    return 1 if worst(findings) == ERROR else 0


# ros2doctor plug-in: its base classes where installed (a robot computer), stand-ins elsewhere.
try:  # pragma: no cover - ros2doctor is not installable on the pip route
    from ros2doctor.api import DoctorCheck as _DoctorCheck
    from ros2doctor.api import DoctorReport as _DoctorReport
    from ros2doctor.api import Report, Result
except ImportError:
    _DoctorCheck = _DoctorReport = object

    class Result:
        """ros2doctor's Result: counts of errors and warnings (printed as they come)."""

        def __init__(self):
            self.error = 0
            self.warning = 0

        def add_error(self, msg):
            """Count and print an error."""
            sys.stderr.write('UserWarning: %s\n' % msg)
            self.error += 1

        def add_warning(self, msg):
            """Count and print a warning."""
            sys.stderr.write('UserWarning: %s\n' % msg)
            self.warning += 1

    class Report:
        """ros2doctor's Report: a name and (item, info) pairs."""

        def __init__(self, name):
            self.name = name
            self.items = []

        def add_to_report(self, item_name, item_info):
            """Add one line."""
            self.items.append((item_name, item_info))

_LAST = {}  # namespace -> (time, findings): ``ros2 doctor --report`` checks, then reports


def _findings(max_age=30.0):
    namespace = os.environ.get('CONTINUUM_STATICS_NAMESPACE', 'continuum')
    cached = _LAST.get(namespace)
    if cached is None or time.monotonic() - cached[0] > max_age:
        cached = (time.monotonic(), diagnose(observe(namespace)))
        _LAST[namespace] = cached
    return cached[1]


class RobotCheck(_DoctorCheck):
    """``ros2 doctor`` check: the continuum robot's set-up (errors and warnings of doctor)."""

    def category(self):
        """Return the category linking this check and :class:`RobotReport`."""
        return 'continuum_statics'

    def check(self):
        """Run doctor's checks; each error and warning goes to ros2doctor with its action."""
        result = Result()
        for finding in _findings():
            text = '%s: %s -> %s' % (finding.check, finding.message, finding.action)
            if finding.level == ERROR:
                result.add_error(text)
            elif finding.level == WARN:
                result.add_warning(text)
        return result


class RobotReport(_DoctorReport):
    """``ros2 doctor --report`` section: every finding of doctor."""

    def category(self):
        """Return the category linking this report and :class:`RobotCheck`."""
        return 'continuum_statics'

    def report(self):
        """Return a Report of every finding."""
        report = Report('CONTINUUM STATICS')
        for finding in _findings():
            report.add_to_report('%s (%s)' % (finding.check, finding.level), finding.message)
        return report
