"""The parameter table of each node: name, default (its type), description with the unit, range.

What a user can tell a node, in one place per node (``ros2 param describe`` shows the same text);
``config/continuum_robot.params.yaml`` lists every one (a test checks).
"""
import math

from continuum_statics.drivers import backend_class
from continuum_statics.nodes.controller_obstacles import FILE_CLEARANCE, check_clearance
from continuum_statics.nodes.node_params import (
    ParamSpec,
    diagnostics_rate_spec,
    robot_file_spec,
    tip_wrench_limit_specs,
)

#: s a tip_wrench estimate stays in use (statics, tip_controller): a dead stream, not a slow
#: solve (tip_load_estimator's capped solve under friction took 1.08 s on a 2-GHz machine; at
#: 1 s statics fell to zero load and a goal was judged on a model tip 10 mm from the true one).
TIP_WRENCH_TIMEOUT = 3.0


def _check_backend(value):
    try:
        backend_class(value)
    except ValueError as error:
        return str(error)
    return None


def _check_wrench_source(value):
    return None if value in ('topic', 'estimate') else "must be 'topic' or 'estimate'"


def contact_specs(read_only=False):
    """Return the tip_contact parameters (tip_load_estimator; statics with a load_model)."""
    return [
        ParamSpec('contact_threshold', 0.0, 'tip_contact turns true when the force exceeds '
                  'this with 3-sigma confidence, N (0: E I / L^2 of the rod, the force that '
                  'bends it by about 30 degrees)', 0.0, 1e6, read_only=read_only),
        # 0.2 s: 20 estimates at the default rate, so that no single outlier or transient
        # declares contact, and still below a human's reaction time (~0.25 s)
        ParamSpec('contact_min_time', 0.2, 'tip_contact changes only once the force has '
                  'stayed past the threshold this long (tip_load_estimator: and the cables have '
                  'stood still; statics: the load is not updated while they move), s',
                  0.0, 60.0, read_only=read_only),
    ]


def _check_load_model(value):
    return None if value in ('weight', 'force', 'wrench', 'direction') else (
        "must be 'weight', 'force', 'wrench' or 'direction' (with load_direction)")


def _direction(value):
    values = list(value)
    if len(values) != 3 or not all(math.isfinite(v) for v in values) or \
            not any(v != 0.0 for v in values):
        return 'must be 3 finite numbers [dx, dy, dz], not all zero, got %s' % values
    return None


def _six_finite(value):
    values = list(value)
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        return 'must be 6 finite numbers [fx, fy, fz, mx, my, mz], got %s' % values
    return None


def max_stamp_offset_spec():
    """Return the stamp rule's parameter (:mod:`continuum_statics.control.stamps`)."""
    return ParamSpec('max_stamp_offset', 1.0, 'an input stamped further than this from the '
                     "node's clock, or going backwards, is stamped on arrival instead (with a "
                     "warning); statics sets such a sensor reading aside; s (1e12: "
                     'effectively off)', 1e-3, 1e12)


def statics_parameters():
    """Return the statics node's ParamSpecs."""
    return [
        robot_file_spec('rod, base frame, cables, guides'),
        diagnostics_rate_spec(),
        ParamSpec('path_samples', 20, 'poses in each backbone Path, base to tip', 2, 500),
        ParamSpec('marker_rate', 30.0, 'backbone_markers rate, Hz (0: off)', 0.0, 200.0),
        ParamSpec('publish_tf', True, "publish the robot's frames on /tf at the backbone rate "
                  '(tip, section ends; base frame -> each)', read_only=True),
        ParamSpec('tip_frame_id', '', "the tip's frame on /tf (empty: <robot name>_tip); a name "
                  "another published frame has is refused",
                  read_only=True),
        ParamSpec('tf_disks', False, 'also one /tf frame per guide disk (<robot name>_disk_<i>)',
                  read_only=True),
        ParamSpec('frame_prefix', '', 'put before every frame statics publishes on /tf (e.g. '
                  "'arm1/': two arms from one robot file); the base frame stays the robot "
                  "file's", read_only=True),
        max_stamp_offset_spec(),
        ParamSpec('sensor_timeout', 0.5, "a reading of one of the robot file's sensors "
                  '(sensors/<name>, tip_pose_measured) older than this at the next estimate is '
                  'not fused, s', 0.0, 3600.0),
        ParamSpec('covariance_rate', 50.0, 'tip_pose_covariance and backbone_estimate (robot '
                  'files with model_uncertainty) at most this often, Hz (0: with every '
                  'estimate)', 0.0, 10000.0, read_only=True),
        ParamSpec('tip_wrench_timeout', TIP_WRENCH_TIMEOUT, 'a tip_wrench older than this is '
                  'replaced by zero (a tip_wrench_estimate is kept, with a warning), s (0: '
                  'never expires)', 0.0, 3600.0),
        ParamSpec('tip_wrench_source', 'topic', 'where the tip load comes from: topic '
                  '(tip_wrench, a force sensor or your estimator) or estimate '
                  '(tip_wrench_estimate, from the tip_load_estimator node; a robot file with '
                  'load_model: statics estimates the load itself and reads tip_wrench)',
                  read_only=True, check=_check_wrench_source),
        *contact_specs(read_only=True),
        ParamSpec('warn_residual', 1e-4, 'above this cable-length residual (RMS) the '
                  'lengths are not exactly a shape: the best fit is published with WARN on '
                  'diagnostics, m (>= 1e-7: a smaller one would warn on round-off)', 1e-7,
                  1.0),
        ParamSpec('max_residual', 2e-3, 'above this residual no shape is near the measured '
                  'lengths: the input is dropped and the last good shape kept, m (>= 1e-6: '
                  'a smaller one would drop every real measurement)', 1e-6, 1.0),
        ParamSpec('length_noise_std', 0.0, 'standard deviation of the measured cable lengths '
                  '(encoder noise), m: the thresholds are at least 3x (warn) and 10x (drop) '
                  'this', 0.0, 0.1),
        ParamSpec('length_limit_margin', 1e-3, 'lengths further than this outside the robot '
                  "file's length limits are dropped, m", 0.0, 1.0),
        ParamSpec('max_iterations', 3, 'Gauss-Newton iterations per measurement (0: the '
                  "robot file's solver.max_iterations): a fit that needs more goes on from "
                  'this estimate with the next measurement; one that is still far off is '
                  'finished at once', 0, 1000),
        ParamSpec('max_model_runs', 24, 'rod integrations (IVPs) a warm-started estimate may '
                  'spend per measurement, ~10-25 us each (0: until it converges): an estimate '
                  'that needs more (or had to make its Jacobians anew) is published as the best '
                  'state reached (capped, counted on diagnostics) and goes on with the next '
                  'measurement', 0, 100000),
        ParamSpec('use_measured_tensions', True, 'estimate with cable_states.effort as cable '
                  'tensions (N) when every one is present, finite, >= 0 and <= max_tension, '
                  'and the shape they give agrees with the lengths within warn_residual '
                  '(else the shape follows the lengths, with WARN)'),
        ParamSpec('max_tension', 0.0, 'measured tensions above this are implausible and '
                  'rejected, N (0: the tension that bends the rod into a full circle from '
                  'its outermost hole, 2 pi EI / (L r))', 0.0, 1e6),
        ParamSpec('tube_diameter', 0.006, 'diameter of the rod drawn in RViz, m', 1e-4, 0.2),
        ParamSpec('dedicated_intake_thread', True, 'serve cable_states from a thread of its '
                  'own instead of the executor (~0.3 ms less per message)', read_only=True),
        ParamSpec('input_queue_depth', 10, 'cable_states queue (dedicated intake thread '
                  'only; the executor path keeps depth 1): absorbs scheduling stalls', 1, 100,
                  read_only=True),
        ParamSpec('max_input_lag', 0.005, 'when the oldest queued cable_states was received '
                  'longer ago than this, skip to the newest, s', 0.0, 1.0, read_only=True),
    ] + tip_wrench_limit_specs()


def tip_controller_parameters():
    """Return the tip_controller node's ParamSpecs."""
    return [
        robot_file_spec('must be the one statics uses'),
        diagnostics_rate_spec(),
        ParamSpec('max_cable_speed', 0.02, 'fastest cable speed of a ramp, m/s', 1e-5, 1.0),
        ParamSpec('goal_orientation', 'ignore', 'ignore: goals are tip positions; direction: '
                  'the tip z axis also points along the z axis of the goal orientation',
                  check=lambda v: None if v in ('ignore', 'direction')
                  else "must be 'ignore' or 'direction'"),
        ParamSpec('control_rate', 50.0, 'cable_commands rate while a goal runs, Hz', 1.0,
                  1000.0),
        ParamSpec('goal_timeout', 10.0, 'a goal not reached after this long fails, s', 0.1,
                  3600.0),
        ParamSpec('default_tolerance', 0.001, 'tip position tolerance of tip_goal_pose '
                  'goals, m', 1e-6, 1.0),
        ParamSpec('settle_time', 0.2, 'after a ramp, cables not yet at their command count as '
                  'settled once their gap to it closed by less than a tenth over this long '
                  '(noise, friction; a cable over 2 mm off: up to '
                  '1 s); only then is the tip error judged, s', 0.0, 10.0),
        ParamSpec('settled_cable_error', 1e-6, 'cables count as settled when every measured '
                  'length is this close to its command, m (the tip moves ~L/r times as '
                  'much)', 0.0, 0.01),
        ParamSpec('max_corrections', 10, 'closed-loop corrections per goal before it fails',
                  0, 1000),
        ParamSpec('min_tension', 0.0, 'every cable is commanded at least this tension, so '
                  'antagonists stay taut (the tendon stiffness of the robot file turns it '
                  'into length), N (0: slack antagonists, as ideal cables)', 0.0, 1e4),
        ParamSpec('use_measured_tip', True, 'judge and correct goals on tip_pose_measured '
                  '(a tracker, registered by calibrate) while it is fresh, else on the '
                  'tip_pose of the model'),
        ParamSpec('tracker_max_disagreement', 0.0, 'tip_pose_measured (a tracker) is set '
                  'aside for the rest of a goal when it is further than this from the model '
                  'tip, and the corrections of a goal add up to at most this, m (0: a tenth '
                  'of the rod length; raise it for a robot not calibrated yet)', 0.0, 10.0),
        ParamSpec('cable_driver_name', 'cable_driver', 'node name of the cable_driver in '
                  'this namespace: its /diagnostics status tells when it refuses commands '
                  '(goals then wait, fail or are rejected, naming the reason)',
                  read_only=True),
        ParamSpec('tip_wrench_timeout', TIP_WRENCH_TIMEOUT, 'a tip_wrench older than this is '
                  'replaced by zero (a tip_wrench_estimate is kept, with a warning), s (0: '
                  'never expires)', 0.0, 3600.0),
        ParamSpec('tip_wrench_source', 'topic', 'where the tip load comes from: topic '
                  '(tip_wrench, a force sensor or your estimator) or estimate '
                  '(tip_wrench_estimate, from the tip_load_estimator node)', read_only=True,
                  check=_check_wrench_source),
        ParamSpec('clearance', FILE_CLEARANCE, 'how far the whole body keeps from every '
                  'obstacle (robot file and obstacles topic) on the way to a tip goal, m (-1: '
                  "the robot file's clearance, 0 when it gives none)", -1.0, 1.0,
                  check=check_clearance),
        ParamSpec('stop_on_contact', False, 'a goal running when tip_contact turns true '
                  '(the tip_load_estimator felt a contact) stops there and fails, naming it'),
        ParamSpec('max_state_age', 0.5, 'cable_states and tip_pose older than this mean a '
                  'dead driver or statics: goals are rejected or fail, s', 0.01, 60.0),
        ParamSpec('state_wait', 3.0, 'a goal that arrives while cable_states or tip_pose '
                  'is missing or older than max_state_age (start-up, a restarted driver) '
                  'waits this long for fresh state before it is rejected, s', 0.0, 60.0),
        ParamSpec('tip_average_time', 1.0, 'longest time the tip is averaged after the '
                  'cables settled (noisy measurements: the mean must be known well inside '
                  'the tolerance before the goal is judged), s', 0.0, 60.0),
        ParamSpec('max_tip_speed', 0.05, 'fastest tip speed of teleoperation (tip_twist), m/s',
                  1e-4, 1.0),
        ParamSpec('max_tip_rate', 0.5, 'fastest turn of the tip direction in teleoperation '
                  '(goal_orientation: direction), rad/s', 1e-3, 10.0),
        ParamSpec('twist_timeout', 0.5, 'dead-man: teleoperation stops (cables hold) when no '
                  'tip_twist came for this long, s', 0.01, 10.0),
        ParamSpec('dedicated_intake_thread', True, 'serve tip_pose, backbone, cable_states '
                  'and tip_wrench from a thread of their own instead of the executor',
                  read_only=True),
        max_stamp_offset_spec(),
    ] + tip_wrench_limit_specs()


def cable_driver_parameters():
    """Return the cable_driver node's ParamSpecs."""
    return [
        robot_file_spec('cable names, length limits'),
        diagnostics_rate_spec(),
        ParamSpec('backend', 'sim', 'cable actuator backend: sim, dynamixel, canopen, '
                  'ros2_control, an entry point of group continuum_statics.cable_backends, '
                  'or module:Class', read_only=True, check=_check_backend),
        ParamSpec('publish_rate', 200.0, 'cable_states publish rate, Hz', 1.0, 2000.0),
        ParamSpec('command_timeout', 0.5, 'hold position when no command arrives for this '
                  'long, s (0: never)', 0.0, 3600.0),
        ParamSpec('length_margin', 0.002, 'commands outside the length limits by at most '
                  'this are clamped, further out rejected, m', 0.0, 0.1),
        ParamSpec('home_file', '', 'YAML of the actuator positions at the straight pose '
                  '(written by ~/set_home, loaded at start; empty: none)', read_only=True),
        ParamSpec('home_tolerance', 0.002, '~/set_home is refused while a cable reads '
                  'further than this from its straight length (the robot is bent, or the '
                  'previous home is off), m', 1e-5, 1.0),
        ParamSpec('home_force', False, '~/set_home takes the current positions as the '
                  'straight pose whatever they read (a first homing, a known-bad home)'),
        ParamSpec('autostart', True, 'configure and activate at start-up (false: wait for '
                  'the lifecycle transitions, e.g. from a lifecycle manager)', read_only=True),
        ParamSpec('reconnect_max_interval', 2.0, 'longest wait between two reconnection '
                  'attempts after a lost port or bus, s', 0.1, 60.0),
        ParamSpec('sim_tip_wrench', [0.0] * 6, 'sim backend: a tip load [fx, fy, fz, mx, my, '
                  'mz] (N, N m, base frame) on the simulated robot that no other node is told '
                  'about (also the WrenchStamped topic sim_tip_wrench)', check=_six_finite),
    ]


def tip_load_estimator_parameters():
    """Return the tip_load_estimator node's ParamSpecs."""
    return [
        robot_file_spec('rod, cables, tendon model, tip_marker'),
        diagnostics_rate_spec(),
        ParamSpec('rate', 100.0, 'most estimates per second (each on the newest '
                  'measurements), Hz', 1.0, 1000.0, read_only=True),
        ParamSpec('noise_length', 20e-6, 'standard deviation of a measured cable length '
                  '(encoder, spool), m', 1e-9, 0.01),
        ParamSpec('noise_tension', 0.05, 'standard deviation of a measured tension '
                  '(cable_states effort), N', 1e-6, 100.0),
        ParamSpec('noise_tension_percent', 0.0, 'tension noise as a percentage of each '
                  'reading instead (0: noise_tension in N)', 0.0, 100.0),
        ParamSpec('noise_tip_position', 0.5e-3, 'standard deviation of tip_pose_measured '
                  '(the tracker), m', 1e-9, 0.1),
        ParamSpec('noise_tip_angle', 0.01, "standard deviation of the tracker's "
                  'orientation, rad', 1e-9, 1.0),
        ParamSpec('use_tip_pose', True, 'use tip_pose_measured when it is fresh'),
        ParamSpec('use_tip_orientation', False, "also use the tracker's orientation (a "
                  'rigid-body tracker; a single marker gives position only)'),
        ParamSpec('estimate_moment', False, 'estimate the tip moment too (needs a tracked '
                  "orientation or many cables to be seen); the same as load_model 'wrench'",
                  read_only=True),
        ParamSpec('load_model', 'force', "what the tip load is: 'weight' (a payload hung on "
                  "the tip: one unknown, its mass along the robot file's gravity, on "
                  "/diagnostics as mass_kg), 'force' (3 unknowns), 'wrench' (force and "
                  "moment), 'direction' (the force's size along load_direction)",
                  read_only=True, check=_check_load_model),
        ParamSpec('load_direction', [0.0, 0.0, -1.0], "load_model 'direction': the force's "
                  'direction [dx, dy, dz], base frame (normalised)', read_only=True,
                  check=_direction),
        ParamSpec('input_timeout', 0.5, 'cable_states and tip_pose_measured older than this '
                  'are not used, s', 0.001, 60.0),
        *contact_specs(),
        max_stamp_offset_spec(),
    ]
