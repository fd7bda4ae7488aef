"""Sensors a robot carries besides its cables, and the model's own error (robot file, no ROS).

A robot file may list ``sensors:`` (a tip tracker, EM coils at disks, a point of an FBG fibre)
and ``model_uncertainty:`` (the model's error as unmodelled loads, written by ``calibrate``);
:mod:`continuum_statics.core.estimation.state_estimation` fuses both into the shape estimate. This
module
holds their validated records and the readings and verdicts that pass through the API.
"""
from dataclasses import dataclass
import math
from typing import NamedTuple

import numpy as np

from continuum_statics.core.description.inputs import mapping

#: What a sensor measures: its point (m), or its point and orientation.
SENSOR_KINDS = ('position', 'pose')
#: Default standard deviations of a sensor (an optical tracker's): m and rad.
DEFAULT_SENSOR_NOISE = {'position': 5.0e-4, 'angle': 0.01}
_SENSOR_KEYS = {'name', 'at', 'offset', 'kind', 'noise', 'frame_id', 'covariance'}
_UNCERTAINTY_KEYS = ('tip_force', 'section_moment', 'cable_length', 'base_position',
                     'correlation_time', 'drift', 'drift_time', 'point_noise')


@dataclass(frozen=True, eq=False)
class Sensor:
    """One sensor of the robot file.

    :ivar name: its name (topic ``sensors/<name>``)
    :ivar s: arc length of the point it sits at (m, unstretched)
    :ivar offset: (3,) m, in the rod's frame at ``s``
    :ivar kind: ``position`` or ``pose``
    :ivar position_sigma: m
    :ivar angle_sigma: rad
    :ivar frame_id: frame of its messages (None: the robot's base frame)
    :ivar at_tip: it sits at the tip (the tip tracker: ``tip_pose_measured`` answers for it)
    :ivar covariance: it publishes geometry_msgs/PoseWithCovarianceStamped, whose position
        covariance (when positive) is the reading's own noise, in place of ``position_sigma``
    """

    name: str
    s: float
    offset: np.ndarray
    kind: str = 'position'
    position_sigma: float = DEFAULT_SENSOR_NOISE['position']
    angle_sigma: float = DEFAULT_SENSOR_NOISE['angle']
    frame_id: str = None
    at_tip: bool = False
    covariance: bool = False

    @property
    def size(self):
        """Scalar measurements in one reading: 3 (position) or 6 (position and angle)."""
        return 6 if self.kind == 'pose' else 3


@dataclass(frozen=True)
class ModelUncertainty:
    """The model's own error as unmodelled loads (standard deviations) and their persistence.

    :ivar tip_force: N, of an unmodelled tip force (each base-frame axis)
    :ivar section_moment: N m, of an unmodelled moment at the tip (each base-frame axis);
        bending errors inside the rod enter through their cables' ``cable_length``
    :ivar cable_length: m, of an unmodelled motor-to-path length error per cable
    :ivar base_position: m, of an offset of the whole backbone (each base-frame axis)
    :ivar correlation_time: s, how long an unmodelled error persists
    :ivar drift: m, of a smoothly varying offset of the whole backbone (each base-frame axis):
        the error that follows the robot's motion from one measurement to the next (friction
        history, hysteresis), which the slowly varying loads above cannot
    :ivar drift_time: s, the time over which that offset changes (its Matern 3/2 length scale)
    :ivar point_noise: m, of the model's error at the tip that none of the above explains and
        that changes from one configuration to the next (white): added to each backbone point's
        covariance, growing as s / L along the rod, and to a sensor's noise at its point
    """

    tip_force: float = 0.0
    section_moment: float = 0.0
    cable_length: float = 0.0
    base_position: float = 0.0
    correlation_time: float = 10.0
    drift: float = 0.0
    drift_time: float = 5.0
    point_noise: float = 0.0

    @property
    def any(self):
        """Whether any unmodelled load has a nonzero standard deviation."""
        return max(self.tip_force, self.section_moment, self.cable_length,
                   self.base_position, self.drift) > 0.0


class SensorReading(NamedTuple):
    """One reading of a sensor, base frame (after registration).

    :ivar position: (3,) m
    :ivar rotation: (3, 3) or None (a position sensor, or a pose sensor's angle not used)
    :ivar stamp: s, or None (the estimate's own stamp)
    :ivar sigma: m, the position noise the device reported with this reading, or None (the
        robot file's ``noise.position``): the device's own figure wins (nmea_navsat_driver's
        habit)
    """

    position: np.ndarray
    rotation: np.ndarray = None
    stamp: float = None
    sigma: float = None


class SensorVerdict(NamedTuple):
    """What the estimator made of one sensor's reading.

    :ivar used: fused into the estimate
    :ivar chi2: normalised innovation squared (its degrees of freedom: 3 or 6)
    :ivar reason: why it was set aside ('' when used)
    """

    used: bool
    chi2: float
    reason: str = ''


def _number(value, field, positive=False, allow_zero=True):
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise ValueError('%s must be a number, got %r' % (field, value)) from None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value):
        raise ValueError('%s must be a finite number, got %r' % (field, value))
    if positive and (value < 0.0 or (value == 0.0 and not allow_zero)):
        raise ValueError('%s must be %s, got %g' % (field, '>= 0' if allow_zero else '> 0',
                                                     value))
    return float(value)


def _arc_length(at, length, guides, field):
    """Arc length (m) of ``at``: 'tip', a number, or {disk: i}; and whether it is the tip."""
    if at == 'tip':
        return float(length), True
    if isinstance(at, dict):
        if set(at) != {'disk'} or isinstance(at['disk'], bool) or not isinstance(at['disk'],
                                                                                    int):
            raise ValueError('%s must be tip, an arc length in m or {disk: i}, got %r'
                             % (field, at))
        disk = at['disk']
        if not 0 <= disk < len(guides):
            raise ValueError('%s: disk %d does not exist (the robot has guide disks 0 to %d)'
                             % (field, disk, len(guides) - 1))
        s = float(guides[disk])
        return s, abs(s - length) < 1e-12
    s = _number(at, field)
    if not 0.0 < s <= length:
        raise ValueError('%s: arc length %g m is outside the rod (0, %g]' % (field, s, length))
    return s, abs(s - length) < 1e-12


def parse_sensors(data, length, guides, tip_marker):
    """Validate the robot file's ``sensors`` list into a tuple of :class:`Sensor`.

    ``guides``: every guide disk's arc length (m); ``tip_marker``: the default offset of a tip
    sensor (m, tip frame).
    """
    if data is None:
        return ()
    if not isinstance(data, list):
        raise ValueError('sensors must be a list of sensors, got %r' % (data,))
    sensors, names = [], set()
    for i, entry in enumerate(data):
        field = 'sensors[%d]' % i
        mapping(entry, field, _SENSOR_KEYS)
        name = entry.get('name')
        if not isinstance(name, str) or not name or not name.replace('_', 'a').isalnum():
            raise ValueError('%s.name must be a topic name (letters, digits, _), got %r'
                             % (field, name))
        if name in names:
            raise ValueError('%s.name %r is used twice' % (field, name))
        names.add(name)
        s, at_tip = _arc_length(entry.get('at', 'tip'), length, guides, '%s.at' % field)
        default_offset = tip_marker if at_tip else (0.0, 0.0, 0.0)
        offset = entry.get('offset', list(default_offset))
        if not isinstance(offset, (list, tuple)) or len(offset) != 3:
            raise ValueError('%s.offset must be a list of 3 numbers (m), got %r'
                             % (field, offset))
        offset = np.array([_number(x, '%s.offset[%d]' % (field, k))
                           for k, x in enumerate(offset)])
        kind = entry.get('kind', 'position')
        if kind not in SENSOR_KINDS:
            raise ValueError('%s.kind must be one of %s, got %r'
                             % (field, ', '.join(SENSOR_KINDS), kind))
        noise = entry.get('noise', {})
        if not isinstance(noise, dict) or set(noise) - set(DEFAULT_SENSOR_NOISE):
            raise ValueError('%s.noise must be a mapping of %s, got %r'
                             % (field, ', '.join(DEFAULT_SENSOR_NOISE), noise))
        sigma = {key: _number(noise.get(key, default), '%s.noise.%s' % (field, key),
                              positive=True, allow_zero=False)
                 for key, default in DEFAULT_SENSOR_NOISE.items()}
        covariance = entry.get('covariance', False)
        if not isinstance(covariance, bool):
            raise ValueError('%s.covariance must be true or false (it publishes '
                             'PoseWithCovarianceStamped), got %r' % (field, covariance))
        frame_id = entry.get('frame_id')
        if frame_id is not None and (not isinstance(frame_id, str) or not frame_id):
            raise ValueError('%s.frame_id must be a frame name, got %r' % (field, frame_id))
        offset.setflags(write=False)
        sensors.append(Sensor(name, s, offset, kind, sigma['position'], sigma['angle'],
                              frame_id, at_tip, covariance))
    return tuple(sensors)


def parse_model_uncertainty(data):
    """Validate the robot file's ``model_uncertainty`` into a :class:`ModelUncertainty`."""
    if data is None:
        return None
    if not isinstance(data, dict):
        raise ValueError('model_uncertainty must be a mapping, got %r' % (data,))
    unknown = sorted(set(data) - set(_UNCERTAINTY_KEYS))
    if unknown:
        raise ValueError('model_uncertainty has unknown keys %s (allowed: %s)'
                         % (unknown, ', '.join(_UNCERTAINTY_KEYS)))
    values = {key: _number(value, 'model_uncertainty.%s' % key, positive=True,
                           allow_zero=key not in ('correlation_time', 'drift_time'))
              for key, value in data.items()}
    return ModelUncertainty(**values)


def as_reading(sensor, reading):
    """Check one reading of ``sensor`` (a :class:`SensorReading` or a bare (3,) position)."""
    if not isinstance(reading, SensorReading):
        reading = SensorReading(reading)
    position = np.asarray(reading.position, dtype=float)
    if position.shape != (3,) or not np.all(np.isfinite(position)):
        raise ValueError('sensor %s: position must be 3 finite numbers (m), got %r'
                         % (sensor.name, reading.position))
    rotation = reading.rotation
    if rotation is not None:
        rotation = np.asarray(rotation, dtype=float)
        if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)) or not np.allclose(
                rotation @ rotation.T, np.eye(3), atol=1e-6):
            raise ValueError('sensor %s: rotation must be a 3x3 rotation matrix' % sensor.name)
    if reading.stamp is not None and not math.isfinite(float(reading.stamp)):
        raise ValueError('sensor %s: stamp must be finite (s), got %r'
                         % (sensor.name, reading.stamp))
    sigma = reading.sigma
    if sigma is not None and not (math.isfinite(float(sigma)) and float(sigma) > 0.0):
        raise ValueError('sensor %s: sigma must be a finite standard deviation > 0 (m), got %r'
                         % (sensor.name, sigma))
    return SensorReading(position, rotation if sensor.kind == 'pose' else None,
                         None if reading.stamp is None else float(reading.stamp),
                         None if sigma is None else float(sigma))


def default_model_uncertainty(bending_stiffness, length):
    """Return the stand-in :class:`ModelUncertainty` of a robot file with sensors but none.

    A tenth of the loads that visibly bend the rod (E I / L^2 of tip force, E I / L of moment:
    about 3 % of L at the tip), 0.5 % of L of cable and 1 % of L of offset: until
    ``calibrate`` measures them from a recorded run (N, N m, m; 10 s).
    """
    return ModelUncertainty(tip_force=0.1 * bending_stiffness / length ** 2,
                            section_moment=0.1 * bending_stiffness / length,
                            cable_length=0.005 * length, base_position=0.01 * length,
                            correlation_time=10.0)
