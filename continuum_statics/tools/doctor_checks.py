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
#: Tension tolerance beyond the model's friction band and 3 sigma of the readings' scatter:
#: an unloaded load cell's offset or a motor's cogging at rest (N), plus the scale error of a
#: current-sensed tension (a fraction of the reading). Less than a homing error of 0.5 mm makes
#: on the real-tendon example (1.9 N more in the shortened cable: 3.7 N/mm, 15x at the tip).
TENSION_FLOOR, TENSION_SCALE = 1.0, 0.1
#: A cable is named as off its zero when the tensions say it reads at least this far (m) from
#: its length, and at least half as far as the cable furthest off (the others follow it): below
#: the 0.4 mm the tension tolerance lets through, so a mismatch names its cable.
HOMING_NAMED = 3e-4
#: Free-length step (m) of the solves that put every cable in the pulled, then the released,
#: friction state: well past the solver's motion threshold (1e-7 m).
FRICTION_PROBE = 1e-4
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
class CableSample:
    """``cable_states`` over the observation window, robot-file order.

    :ivar lengths: (n,) mean measured lengths, m
    :ivar tensions: (n,) mean ``effort``, N (None: the driver reports no tensions)
    :ivar tension_std: (n,) standard deviation of single tension readings, N
    :ivar count: messages averaged
    """

    lengths: object
    tensions: object = None
    tension_std: object = None
    count: int = 0


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
    :ivar cables: :class:`CableSample` of ``cable_states`` in the robot file's cable order, or
        None (no message, other names)
    :ivar tip_force: (3,) mean ``tip_wrench`` force (N, base frame), None when none came
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
    cables: CableSample = None
    tip_force: object = None


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
        frame = _OBSTACLE_FRAME.search(observation.robot_error)
        return [Finding(ERROR, 'robot_file', 'robot file %s does not load: %s' % (
            observation.robot_file or '(none)', observation.robot_error),
            'fix the named field (format: doc/robot_files.md), then restart the nodes'
            if frame is None else 'give obstacle %s in the base frame %s in the robot file '
            '(no frame_id), or publish it on the obstacles topic with header.frame_id %s: '
            'statics and tip_controller map that through /tf' % frame.group(1, 3, 2))]
    robot = observation.robot
    findings = [Finding(OK, 'robot_file', '%s: robot %r, %d cable(s), %d section(s)' % (
        observation.robot_file, robot.name, len(robot.cable_names),
        len(robot.sections or ())))]
    for warning in getattr(robot.description, 'warnings', ()):
        findings.append(Finding(WARN, 'robot_file', 'implausible: %s' % warning,
                                'check that value against the robot (a unit slip: mm for m?)'))
    findings += _calibration_age(observation.robot_file)
    return findings


#: The core's refusal of a robot file's obstacle in another frame (obstacles.in_base_frame).
_OBSTACLE_FRAME = re.compile(r"obstacle ('[^']*') is in frame ('[^']*'), not the base frame "
                             r"('[^']*')")


def check_obstacles(observation):
    """Name the obstacles a node refuses (a frame /tf does not reach, a malformed entry)."""
    findings = []
    for name in ('statics', 'tip_controller'):
        status = observation.statuses.get(_node(observation, name).lstrip('/'))
        refused = status[2].get('obstacles_refused') if status else None
        if refused:
            findings.append(Finding(WARN, 'obstacles', '%s leaves out obstacle(s) of the '
                                    'obstacles topic: %s' % (name, refused),
                                    'publish the named frame on /tf or /tf_static (a chain to '
                                    'the base frame), or send the obstacle in the base frame; '
                                    'fix a malformed entry as named'))
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
    """Check that the kernels are in numba's cache (else each start compiles for ~22 s)."""
    cached, total = observation.kernels_cached
    if total and cached == total:
        return [Finding(OK, 'kernels', 'all %d kernels compiled in the numba cache' % total)]
    return [Finding(WARN, 'kernels', '%d of %d kernels in the numba cache: each node compiles '
                    'the rest at start (~22 s on two cores, status "starting")' % (cached, total),
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
        elif status[0] == WARN:  # was '[ok] statics ready: sensor ... silent for 55.1 s'
            findings.append(Finding(WARN, 'nodes', '%s warns: %s' % (name, status[1]),
                                    'read its /diagnostics values (doc/nodes.md); the checks '
                                    'below name the usual causes'))
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
        failure = values.get('transition_failure', '')
        if failure:  # the same transition would fail again: the cause first
            findings.append(Finding(ERROR, 'driver', 'cable_driver: %s; it stays %s' % (
                failure, lifecycle or 'where it was'),
                'fix that cause (the parameter or robot file it names), then restart '
                'cable_driver, or: ros2 lifecycle set %s %s' % (
                    _node(observation, 'cable_driver'),
                    failure.split(' ', 1)[0] if ' failed' in failure else 'configure')))
        elif lifecycle and lifecycle != 'active':
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


def _stamp_problem(sample):
    """Return why a sample's stamp is wrong ('' when it is not): too old, or ahead."""
    if sample.age is None:  # a zero stamp: taken on arrival
        return ''
    if not math.isfinite(sample.age) or abs(sample.age) > 1e6:
        return 'stamped %.0f s from this clock (an unset clock: 1970?)' % sample.age
    if sample.age > SENSOR_MAX_AGE:
        return 'stamped %.2f s in the past' % sample.age
    if sample.age < -SENSOR_MAX_AGE:
        return 'stamped %.2f s in the future' % -sample.age
    return ''


def _judge_sensor(observation, label, topics, declared=False, stamp_level=ERROR):
    """Judge one sensor read on ``topics`` (the first is its own): silent, frame, stamp.

    Silent and foreign-frame readings are errors (the nodes get nothing, or refuse it), and
    bad stamps ``stamp_level``; ``declared``: the robot file names the sensor, so nobody
    publishing it is an error too (statics fuses it).
    """
    level = ERROR
    robot = observation.robot
    samples = [(topic, observation.topics.get(topic, TopicSample())) for topic in topics]
    where = ' or '.join('%s/%s' % (observation.namespace.rstrip('/'), t) for t in topics)
    check = 'check the %s is publishing on %s (its driver running, the device connected, no ' \
        'remap)' % (label, where)
    publishers = sum(sample.publishers for _, sample in samples)
    heard = [(topic, sample) for topic, sample in samples if sample.count]
    if not heard:
        if publishers:
            return [Finding(level, 'sensors', '%s: %d publisher(s) on %s but no message in '
                            '%g s: a silent sensor' % (label, publishers, where,
                                                        observation.duration), check)]
        if not declared:  # an optional topic nobody publishes: nothing to say
            return []
        return [Finding(level, 'sensors', '%s: the robot file declares it but nobody '
                        'publishes %s' % (label, where),
                        check + ", or remove it from the robot file's sensors")]
    findings = []
    for topic, sample in heard:
        if sample.frame_id not in ('', robot.base_frame_id):
            findings.append(Finding(level, 'sensors', "%s: %s is in frame %r, the robot "
                                    "file's base frame is %r: it is refused" % (
                                        label, topic, sample.frame_id, robot.base_frame_id),
                                    'publish it in %r, or use the robot file calibrate wrote '
                                    '(its base is the tracker registration)'
                                    % robot.base_frame_id))
        stamp = _stamp_problem(sample)
        if stamp:
            findings.append(Finding(stamp_level, 'sensors', '%s: %s is %s: %s' % (
                label, topic, stamp, 'statics fuses its readings as nearly nothing (their '
                'weight decays with age)' if declared else 'its readings are stale'),
                'synchronise the clocks (chrony) or stamp at reception with this clock'))
    if not findings:
        topic, sample = heard[0]
        findings.append(Finding(OK, 'sensors', '%s: %s at %.0f Hz in %s' % (
            label, topic, sample.rate, sample.frame_id or robot.base_frame_id)))
    return findings


def _statics_sensor_notes(observation, named):
    """Return findings from statics' own status: a sensor it found silent or set aside."""
    statics = observation.statuses.get(_node(observation, 'statics').lstrip('/'))
    if statics is None:
        return []
    findings = []
    for name, seconds in re.findall(r'sensor (\S+) silent for ([\d.]+) s', statics[1]):
        if name not in named:  # the doctor's own sample already said it
            findings.append(Finding(ERROR, 'sensors', 'statics: sensor %s silent for %s s '
                                    '(the estimate runs without it)' % (name, seconds),
                                    'check the sensor is publishing on %s/sensors/%s' % (
                                        observation.namespace.rstrip('/'), name)))
    for name, reason in re.findall(r'sensor (\S+) set aside: ([^;]+)', statics[1]):
        findings.append(Finding(WARN, 'sensors', 'statics set sensor %s aside: %s' % (
            name, reason), 'a reading the model cannot explain at its noise: check the '
            "sensor's registration (calibrate) and its noise in the robot file"))
    return findings


def _stand_in_prior(observation):
    """Return a WARN when the robot file has sensors but no ``model_uncertainty`` of its own."""
    robot = observation.robot
    if not robot.sensors or getattr(robot.description, 'model_uncertainty', None) is not None:
        return []
    prior = robot.model_uncertainty
    statics = observation.statuses.get(_node(observation, 'statics').lstrip('/'))
    sigma = statics[2].get('tip_sigma_mm', '') if statics else ''
    seen = ", tip sigma %s mm on statics' /diagnostics" % sigma if sigma not in (
        '', 'nan') else ''
    return [Finding(WARN, 'sensors', 'the robot file has sensors but no model_uncertainty: '
                    'they are fused against a stand-in prior (tip force %.3g N, section moment '
                    '%.3g N m, cable %.2g mm, base %.2g mm, a guess from the rod%s)' % (
                        prior.tip_force, prior.section_moment, 1e3 * prior.cable_length,
                        1e3 * prior.base_position, seen),
                    'record a run with the sensors and run calibrate --model-uncertainty '
                    '(doc/state_estimation.md); use the robot file it writes')]


def check_sensors(observation):
    """Check every sensor: silent, frame, stamp, prior; statics' verdicts on them.

    The robot file's ``sensors/<name>``, ``tip_pose_measured`` and ``tip_wrench``.
    """
    robot = observation.robot
    if robot is None:
        return []
    findings = _stand_in_prior(observation)
    if not observation.graph_seen:
        return findings
    tip_sensor = next((s.name for s in robot.sensors if s.at_tip), None)
    named = set()
    for sensor in robot.sensors:
        topics = ['sensors/%s' % sensor.name]
        if sensor.name == tip_sensor:  # statics reads the tip tracker there too
            topics.append('tip_pose_measured')
        own = _judge_sensor(observation, 'sensor %s' % sensor.name, topics, declared=True)
        named.update(sensor.name for f in own if f.level == ERROR)
        findings += own
    if tip_sensor is None:
        findings += _judge_sensor(observation, 'tip tracker', ['tip_pose_measured'])
    findings += _judge_sensor(observation, 'tip load', ['tip_wrench'], stamp_level=WARN)
    if 'statics' in observation.nodes:
        findings += _statics_sensor_notes(observation, named)
    return findings


@dataclass
class TensionComparison:
    """Measured tensions against the model's for the measured lengths (real tendons).

    :ivar model: (n,) N at the motors, the model's for the measured lengths (no friction)
    :ivar low, high: (n,) N, the friction band: every cable pulled last, every cable paid out
    :ivar tolerance: (n,) N beyond the band that noise and the sensor's calibration explain
    :ivar mismatch: (n,) N by which the measured tension lies outside band +- tolerance (0:
        inside)
    :ivar offsets: (n,) m, how far each cable reads from the length its measured tension says
        (< 0: reads short, its zero is off by that), NaN where unknown
    :ivar named: indices of the cables off their zero
    """

    model: object
    low: object
    high: object
    tolerance: object
    mismatch: object
    offsets: object
    named: tuple


def compare_tensions(robot, lengths, tensions, tension_std=None, tip_force=(0.0, 0.0, 0.0)):
    """Compare measured tensions (N) with the model's for measured lengths (m): a homing check.

    The model (:meth:`Robot.solve_lengths`) gives each cable's motor-side tension for the
    lengths; friction makes it anything between every cable last pulled and last paid out
    (capstan at the guides, one solve each). Beyond that band a reading may differ by 3 sigma
    of its scatter (``tension_std``, N) plus :data:`TENSION_FLOOR` and :data:`TENSION_SCALE`
    of the tension: the sensor's own error. Outside that, the lengths are not the lengths the
    tensions belong to: a cable's zero is off. Which one, and by how much: the shape the
    measured tensions make (:meth:`Robot.solve_tensions`) gives each cable's path, the tendon
    model its stretch, so the length each should read; the cables reading at least
    :data:`HOMING_NAMED`, and at least half the largest offset, away are named.
    Raises what the solvers raise (no equilibrium).
    """
    import numpy as np

    lengths = np.asarray(lengths, dtype=float)
    measured = np.asarray(tensions, dtype=float)
    std = np.zeros_like(measured) if tension_std is None else np.asarray(tension_std, float)
    force = np.asarray(tip_force, dtype=float)
    step = max(FRICTION_PROBE, 2.0 * float(np.max(robot.tendons.stick_length, initial=0.0)))
    model = robot.solve_lengths(lengths, force).tensions
    pulled = robot.solve_lengths(lengths, force, warm_start=robot.solve_lengths(
        lengths + step, force)).tensions
    released = robot.solve_lengths(lengths, force, warm_start=robot.solve_lengths(
        lengths - step, force)).tensions
    low = np.minimum(np.minimum(pulled, released), model)
    high = np.maximum(np.maximum(pulled, released), model)
    tolerance = 3.0 * std + TENSION_FLOOR + TENSION_SCALE * np.maximum(high, measured)
    mismatch = np.maximum(np.maximum(low - tolerance - measured, measured - high - tolerance),
                          0.0)
    offsets = np.full(len(lengths), np.nan)
    if np.any(mismatch > 0.0):
        tendons = robot.tendons
        shape = robot.solve_tensions(np.maximum(measured, 0.0), force)
        free = robot.cable_lengths(shape) / (1.0 + np.maximum(measured, 0.0)
                                             * tendons.compliance)
        offsets = lengths - tendons.lengths_for(free, robot.straight_cable_lengths)
        # a cable whose tension reads slack may be any length beyond its path: no offset
        offsets[(measured <= tolerance) & (offsets > 0.0)] = 0.0
    size = np.nan_to_num(np.abs(offsets))
    largest = float(np.max(size, initial=0.0))
    named = tuple(int(i) for i in np.nonzero((size >= HOMING_NAMED)
                                             & (size >= 0.5 * largest))[0])
    return TensionComparison(model, low, high, tolerance, mismatch, offsets, named)


def check_tensions(observation):
    """Check measured tensions against the model's for the measured lengths (real tendons)."""
    robot, cables = observation.robot, observation.cables
    if robot is None or cables is None or cables.tensions is None or robot.tendons.is_ideal \
            or not robot.cable_names:
        return []
    import numpy as np

    force = (0.0, 0.0, 0.0) if observation.tip_force is None else observation.tip_force
    try:
        result = compare_tensions(robot, cables.lengths, cables.tensions, cables.tension_std,
                                  force)
    except Exception as error:  # no equilibrium for these lengths: the driver check says more
        return [Finding(NOTE, 'tensions', 'no model equilibrium to compare the tensions with '
                        '(%s)' % error)]
    names = robot.cable_names
    measured = np.asarray(cables.tensions, dtype=float)
    if not np.any(result.mismatch > 0.0):
        worst_cable = int(np.argmax(np.abs(measured - result.model)))
        return [Finding(OK, 'tensions', 'measured tensions match the model for the measured '
                        'lengths (largest difference %.2g N on %s, tolerance %.2g N)' % (
                            abs(measured[worst_cable] - result.model[worst_cable]),
                            names[worst_cable], result.tolerance[worst_cable]))]
    off = [i for i in np.argsort(-result.mismatch) if result.mismatch[i] > 0.0]
    says = ', '.join('%s %.1f N measured, %.1f N in the model' % (
        names[i], measured[i], result.model[i]) for i in off)
    driver = _node(observation, 'cable_driver')
    if result.named:
        which = ', '.join('%s reads %.1f mm %s than its tension says' % (
            names[i], 1e3 * abs(result.offsets[i]), 'less' if result.offsets[i] < 0.0
            else 'more') for i in result.named)
        return [Finding(ERROR, 'tensions', 'a cable is homed off its zero: %s (%s; the shape '
                        'statics publishes is bent by it)' % (
                            which, says),
                        _home_action(driver, ', '.join(names[i] for i in result.named)))]
    return [Finding(ERROR, 'tensions', 'measured tensions disagree with the model for the '
                    'measured lengths beyond noise and friction (%s)' % says,
                    "check the tension readings' units and zero and the robot file's tendons "
                    '(stiffness, pretension); if they are right: ' + _home_action(driver))]


def _home_action(driver, cables=''):
    """Return the re-homing commands for cable_driver ``driver`` ('/ns/cable_driver')."""
    return ('hold the robot straight (cables just taut) and re-home%s: ros2 param set %s '
            'home_force true && ros2 service call %s/set_home std_srvs/srv/Trigger && ros2 '
            'param set %s home_force false' % (' ' + cables if cables else '', driver, driver,
                                               driver))


#: Every check, in the order they are reported.
CHECKS = (check_environment, check_robot_file, check_kernels, check_nodes, check_driver,
          check_rates, check_tf, check_sensors, check_tensions, check_obstacles)


def diagnose(observation):
    """Return every finding of every check."""
    findings = []
    for check in CHECKS:
        findings += check(observation)
    return findings


def worst(findings):
    """Return the highest level among ``findings`` (OK for none)."""
    return max((f.level for f in findings), key=LEVELS.index, default=OK)
