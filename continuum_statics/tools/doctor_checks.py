"""What ``doctor`` concludes from what it observed: findings, each with the one thing to do.

No ROS here: :mod:`.doctor` gathers an :class:`Observation` (the environment, the robot file, the
kernel cache, the ROS graph of one namespace for a few seconds) and every check below is a plain
function of it, so the judgement is tested without DDS too.
"""
from dataclasses import dataclass, field
import datetime
import math
import os
import re

#: Finding levels, mildest first; ``doctor`` exits 1 when any finding is an error.
OK, NOTE, WARN, ERROR = 'ok', 'note', 'warn', 'error'
LEVELS = (OK, NOTE, WARN, ERROR)
#: The nodes a robot runs in its namespace (bringup, the launch file).
NODES = ('statics', 'tip_controller', 'cable_driver')
#: A measured rate below this fraction of its parameter is reported.
RATE_FRACTION = 0.8
#: Sensor messages older than this are stale (the controller's and estimator's default), s.
SENSOR_MAX_AGE = 0.5
#: A robot file edited this long after its calibration header was written is reported, s.
EDITED_AFTER_CALIBRATION = 3600.0
#: A calibration older than this is worth repeating, days.
OLD_CALIBRATION_DAYS = 180
_CALIBRATED = re.compile(r'^# Calibrated by .* on (\d{4}-\d\d-\d\d \d\d:\d\d) UTC', re.M)


@dataclass(frozen=True)
class Finding:
    """One conclusion: ``level``, the ``check`` it came from, what is so, and what to do."""

    level: str
    check: str
    message: str
    action: str = ''

    def as_dict(self):
        """Return the finding as a JSON-ready dict."""
        return {'level': self.level, 'check': self.check, 'message': self.message,
                'action': self.action}


@dataclass
class TopicSample:
    """What arrived on one topic during the observation window.

    :ivar publishers: publishers in the graph
    :ivar count: messages received
    :ivar rate: messages per second over the window (0 without two messages)
    :ivar frame_id: ``header.frame_id`` of the last message ('' without a header)
    :ivar age: seconds between the last message's stamp and the observer's clock (None: no
        stamp, or a zero stamp)
    """

    publishers: int = 0
    count: int = 0
    rate: float = 0.0
    frame_id: str = ''
    age: float = None


@dataclass
class Observation:
    """Everything a diagnosis looks at (filled by :mod:`.doctor`; plain data, no ROS objects).

    :ivar environment: the ROS environment variables (``ROS_DOMAIN_ID``, ...)
    :ivar namespace: the robot's namespace, absolute ('/continuum')
    :ivar robot_file: path of the robot file the nodes use ('' when unknown)
    :ivar robot: the loaded robot, or None; ``robot_error`` says why not
    :ivar kernels_cached: (cached, total) kernel entry points found in numba's cache
    :ivar graph_seen: False when the ROS graph was not looked at (``--no-graph``)
    :ivar nodes: node names present in the namespace
    :ivar statuses: node name -> (level, message, values) of its latest /diagnostics status
    :ivar parameters: node name -> {parameter: value} read from the running node
    :ivar topics: relative topic name -> :class:`TopicSample` (absolute names for /tf)
    :ivar tf_frames: (parent, child) pairs seen on /tf
    """

    environment: dict = field(default_factory=dict)
    namespace: str = '/continuum'
    robot_file: str = ''
    robot: object = None
    robot_error: str = ''
    kernels_cached: tuple = (0, 0)
    graph_seen: bool = True
    nodes: tuple = ()
    statuses: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    topics: dict = field(default_factory=dict)
    tf_frames: tuple = ()
    duration: float = 3.0


def _node(observation, name):
    return '%s/%s' % (observation.namespace.rstrip('/'), name)


def check_environment(observation):
    """Check the domain id and discovery range: what the nodes can hear."""
    env = observation.environment
    findings = []
    domain = env.get('ROS_DOMAIN_ID', '')
    if domain and (not domain.isdigit() or int(domain) > 232):
        findings.append(Finding(ERROR, 'environment', 'ROS_DOMAIN_ID=%r is not a domain id '
                                'in 0..232' % domain, "export ROS_DOMAIN_ID=<the robot's "
                                'domain, 0 by default> in every terminal'))
    scope = env.get('ROS_AUTOMATIC_DISCOVERY_RANGE', '') or 'SUBNET (default)'
    findings.append(Finding(OK, 'environment', 'ROS_DOMAIN_ID=%s, discovery range %s' % (
        domain or '0 (unset)', scope)))
    if env.get('ROS_LOCALHOST_ONLY') and not env.get('ROS_AUTOMATIC_DISCOVERY_RANGE'):
        findings.append(Finding(WARN, 'environment', 'ROS_LOCALHOST_ONLY is set: Jazzy reads '
                                'it, Kilted ignores it', 'use ROS_AUTOMATIC_DISCOVERY_RANGE='
                                'LOCALHOST (scripts/ros_env.sh sets it)'))
    return findings


def check_robot_file(observation):
    """Check that the robot file loads and is plausible, and how old its calibration is."""
    if observation.robot is None:
        return [Finding(ERROR, 'robot_file', 'robot file %s does not load: %s' % (
            observation.robot_file or '(none)', observation.robot_error),
            'fix the named field (format: doc/robot_files.md), then restart the nodes')]
    robot = observation.robot
    findings = [Finding(OK, 'robot_file', '%s: robot %r, %d cable(s), %d section(s)' % (
        observation.robot_file, robot.name, len(robot.cable_names),
        len(robot.sections or ())))]
    for warning in getattr(robot.description, 'warnings', ()):
        findings.append(Finding(WARN, 'robot_file', 'implausible: %s' % warning,
                                'check that value against the robot (a unit slip: mm for m?)'))
    findings += _calibration_age(observation.robot_file)
    return findings


def _calibration_age(path):
    try:
        text = open(path, encoding='utf-8').read(4096)
        modified = os.path.getmtime(path)
    except OSError:
        return []
    match = _CALIBRATED.search(text)
    if match is None:
        return [Finding(NOTE, 'calibration', 'the robot file has not been calibrated (no '
                        '"Calibrated by" header)', 'record a run with a tip tracker and run '
                        'calibrate (doc/calibration.md)')]
    when = datetime.datetime.strptime(match.group(1), '%Y-%m-%d %H:%M').replace(
        tzinfo=datetime.timezone.utc)
    findings = []
    if modified - when.timestamp() > EDITED_AFTER_CALIBRATION:
        findings.append(Finding(WARN, 'calibration', 'the robot file was changed %.1f days '
                                'after its calibration of %s' % (
                                    (modified - when.timestamp()) / 86400.0, match.group(1)),
                                'calibrate again if the change was to the robot (geometry, '
                                'tendons), not a comment'))
    days = (datetime.datetime.now(datetime.timezone.utc) - when).total_seconds() / 86400.0
    level = WARN if days > OLD_CALIBRATION_DAYS else OK
    findings.append(Finding(level, 'calibration', 'calibrated %s UTC, %.0f days ago' % (
        match.group(1), days), 'tendons creep and clamps move: calibrate again'
        if level == WARN else ''))
    return findings


def check_kernels(observation):
    """Check that the kernels are in numba's cache (else each start compiles for a minute)."""
    cached, total = observation.kernels_cached
    if total and cached == total:
        return [Finding(OK, 'kernels', 'all %d kernels compiled in the numba cache' % total)]
    return [Finding(WARN, 'kernels', '%d of %d kernels in the numba cache: each node compiles '
                    'the rest at start (20-60 s, status "starting")' % (cached, total),
                    'run `python -m continuum_statics warmup` once as the user that runs the '
                    'nodes (or set NUMBA_CACHE_DIR to a writable directory)')]


def check_nodes(observation):
    """Check that each node is in the graph and its /diagnostics status says ready."""
    if not observation.graph_seen:
        return []
    domain = observation.environment.get('ROS_DOMAIN_ID') or '0'
    present = [name for name in NODES if name in observation.nodes]
    if not present:
        return [Finding(ERROR, 'nodes', 'no node of the robot in %s on ROS_DOMAIN_ID=%s '
                        '(discovery range %s)' % (
                            observation.namespace, domain,
                            observation.environment.get('ROS_AUTOMATIC_DISCOVERY_RANGE')
                            or 'SUBNET'),
                        "start them (bringup or the launch file), or use the robot's "
                        'ROS_DOMAIN_ID and discovery range here, or pass --namespace')]
    findings = []
    for name in NODES:
        status = observation.statuses.get(_node(observation, name).lstrip('/'))
        if name not in observation.nodes:
            findings.append(Finding(ERROR, 'nodes', '%s is not running in %s' % (
                name, observation.namespace), 'start it (python -m continuum_statics %s, or '
                'restart the launch file) and read its last log lines for why it stopped'
                % name))
        elif status is None:
            findings.append(Finding(WARN, 'nodes', '%s is in the graph but published no '
                                    '/diagnostics in %g s' % (name, observation.duration),
                                    'it may be stuck or starting: read its log'))
        elif status[2].get('state') == 'starting':
            waiting = status[1][len('starting: '):] if status[1].startswith('starting: ') \
                else status[1]
            findings.append(Finding(WARN, 'nodes', '%s is starting: %s' % (name, waiting),
                                    'wait for it; if it stays, do what it waits for'))
        elif status[0] == ERROR:
            findings.append(Finding(ERROR, 'nodes', '%s reports an error: %s' % (
                name, status[1]), 'see doc/actuators.md (faults) or doc/nodes.md'))
        else:
            findings.append(Finding(OK, 'nodes', '%s ready: %s' % (name, status[1])))
    return findings


def check_driver(observation):
    """Check cable_driver: active, connected, homed (lengths inside the file's limits)."""
    status = observation.statuses.get(_node(observation, 'cable_driver').lstrip('/'))
    findings = []
    if status is not None:
        values = status[2]
        lifecycle = values.get('lifecycle', '')
        if lifecycle and lifecycle != 'active':
            findings.append(Finding(ERROR, 'driver', 'cable_driver is %s: it refuses cable '
                                    'commands, so goals fail' % lifecycle,
                                    'ros2 lifecycle set %s %s (or start it with '
                                    'autostart:=true)' % (
                                        _node(observation, 'cable_driver'),
                                        'activate' if lifecycle == 'inactive'
                                        else 'configure, then activate')))
        if values.get('connected') == 'False':
            findings.append(Finding(ERROR, 'driver', 'cable_driver lost its actuators: %s'
                                    % status[1], 'check power and cable; then call '
                                    'cable_driver/reset'))
    findings += _homing(observation)
    return findings


def _homing(observation):
    statics = observation.statuses.get(_node(observation, 'statics').lstrip('/'))
    robot = observation.robot
    findings = []
    if statics is not None:
        outside = statics[2].get('outside_limits_total', '0')
        rejection = statics[2].get('last_rejection', '')
        if 'fit no shape' in rejection:
            findings.append(Finding(ERROR, 'driver', 'statics drops cable_states that fit no '
                                    'shape (%s): a cable is not homed (its zero is off), or '
                                    'one broke or jumped a spool' % rejection.split(': ', 1)[-1],
                                    'hold the robot straight and call the cable_driver/'
                                    'set_home service; if it persists, check each cable'))
        if outside not in ('0', ''):
            findings.append(Finding(ERROR, 'driver', 'statics dropped %s cable_states outside '
                                    "the robot file's length limits (%s): the driver is not "
                                    'homed, or this is the wrong robot file' % (
                                        outside, statics[2].get('last_rejection', '')),
                                    'hold the robot straight and call the cable_driver/'
                                    'set_home service (home_force:=true the first time)'))
    parameters = observation.parameters.get('cable_driver', {})
    if robot is not None and robot.cable_names and parameters.get('backend', 'sim') != 'sim' \
            and not parameters.get('home_file'):
        findings.append(Finding(WARN, 'driver', 'cable_driver has no home_file: its zeros are '
                                'the %s.zero_* parameters' % parameters['backend'],
                                'set home_file and call cable_driver/set_home with the robot '
                                'straight, so the zeros survive a restart'))
    return findings


def check_rates(observation):
    """Check cable_states against the driver's publish_rate, and statics keeping up."""
    if not observation.graph_seen or 'cable_driver' not in observation.nodes \
            and 'statics' not in observation.nodes:
        return []
    states = observation.topics.get('cable_states', TopicSample())
    backbone = observation.topics.get('backbone', TopicSample())
    findings = []
    wanted = observation.parameters.get('cable_driver', {}).get('publish_rate')
    if states.publishers and states.count == 0:
        findings.append(Finding(ERROR, 'rates', 'cable_states is silent (%d publisher(s), no '
                                'message in %g s)' % (states.publishers,
                                                        observation.duration),
                                'the driver reads nothing: check its connection and '
                                'lifecycle state'))
    elif not states.publishers and observation.robot is not None \
            and observation.robot.cable_names:
        findings.append(Finding(ERROR, 'rates', 'nobody publishes cable_states',
                                'start cable_driver (or your driver) in %s' %
                                observation.namespace))
    elif wanted and states.rate < RATE_FRACTION * float(wanted):
        findings.append(Finding(WARN, 'rates', 'cable_states at %.0f Hz, publish_rate is %g '
                                'Hz' % (states.rate, float(wanted)),
                                'the driver cannot keep up: lower publish_rate or the servo '
                                'count per bus (make bench-drivers)'))
    elif states.count:
        findings.append(Finding(OK, 'rates', 'cable_states at %.0f Hz' % states.rate))
    if states.rate > 0 and backbone.rate < RATE_FRACTION * states.rate:
        findings.append(Finding(WARN, 'rates', 'backbone at %.0f Hz of %.0f Hz cable_states' % (
            backbone.rate, states.rate), 'statics falls behind or drops input: read its '
            '/diagnostics (last_rejection, residual) and doc/nodes.md'))
    return findings


def check_tf(observation):
    """Check statics' frames on /tf: children of the robot file's base frame."""
    robot = observation.robot
    if not observation.graph_seen or robot is None or 'statics' not in observation.nodes:
        return []
    if observation.parameters.get('statics', {}).get('publish_tf') is False:
        return [Finding(NOTE, 'tf', 'statics publishes no /tf (publish_tf: false)',
                        'set publish_tf: true for RViz, robot_description and tf2')]
    tip = observation.parameters.get('statics', {}).get('tip_frame_id') or '%s_tip' % robot.name
    parents = {parent for parent, child in observation.tf_frames if child == tip}
    if not parents:
        return [Finding(ERROR, 'tf', 'no %s on /tf in %g s' % (tip, observation.duration),
                        'statics publishes /tf with each shape: give it cable_states (see '
                        'rates) and check that nothing remaps /tf')]
    if parents != {robot.base_frame_id}:
        return [Finding(ERROR, 'tf', '%s has parent %s on /tf, the robot file says %s' % (
            tip, ', '.join(sorted(parents)), robot.base_frame_id),
            'two robots publish the same frame names: give each its own robot name')]
    return [Finding(OK, 'tf', '%s -> %s and %d more frames on /tf' % (
        robot.base_frame_id, tip, len({c for _, c in observation.tf_frames}) - 1))]


def check_sensors(observation):
    """Check the tracker (``tip_pose_measured``) and tip load (``tip_wrench``): frame, age."""
    robot = observation.robot
    if not observation.graph_seen or robot is None:
        return []
    findings = []
    for topic, what in (('tip_pose_measured', 'tip tracker'), ('tip_wrench', 'tip load')):
        sample = observation.topics.get(topic, TopicSample())
        if not sample.publishers:
            continue
        if sample.count == 0:
            findings.append(Finding(ERROR, 'sensors', '%s (%s) has %d publisher(s) but sent '
                                    'nothing in %g s: a silent sensor' % (
                                        topic, what, sample.publishers, observation.duration),
                                    'check the %s driver (running, its device connected, a '
                                    'topic remap)' % what))
            continue
        if sample.frame_id != robot.base_frame_id:
            findings.append(Finding(ERROR, 'sensors', "%s is in frame %r, the robot file's "
                                    'base frame is %r: it is refused' % (
                                        topic, sample.frame_id, robot.base_frame_id),
                                    'publish it in %r, or use the robot file calibrate wrote '
                                    '(its base is the tracker registration)'
                                    % robot.base_frame_id))
        if sample.age is not None and (not math.isfinite(sample.age)
                                       or abs(sample.age) > SENSOR_MAX_AGE):
            findings.append(Finding(WARN, 'sensors', '%s is %.2f s old (stamp against this '
                                    'clock)' % (topic, sample.age),
                                    'synchronise the clocks (chrony) or stamp at reception'))
        if not any(f.check == 'sensors' and topic in f.message for f in findings):
            findings.append(Finding(OK, 'sensors', '%s at %.0f Hz in %s' % (
                topic, sample.rate, sample.frame_id)))
    return findings


#: Every check, in the order they are reported.
CHECKS = (check_environment, check_robot_file, check_kernels, check_nodes, check_driver,
          check_rates, check_tf, check_sensors)


def diagnose(observation):
    """Return every finding of every check."""
    findings = []
    for check in CHECKS:
        findings += check(observation)
    return findings


def worst(findings):
    """Return the highest level among ``findings`` (OK for none)."""
    return max((f.level for f in findings), key=LEVELS.index, default=OK)
