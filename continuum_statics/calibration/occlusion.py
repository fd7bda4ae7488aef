"""What a tip tracker buys on a recorded run: the run replayed with the tracker occluded in blocks.

The protocol of issue 35 (and of the hidden robot's score): the robot file (calibrated on
another run, with its ``model_uncertainty``) estimates every row of a held-out run from the
motor positions, in time order, through ``Robot.estimate_shape`` with the tip tracker as a
sensor that is seen on blocks of rows and occluded on the blocks between. On the occluded rows
it reports the error of the fused estimate, of the model alone (the same replay without the
tracker: ``solve_lengths`` row by row) and of the simple baseline (the model plus the last seen
residual, decayed with a 10 s time constant), and how many occluded rows the estimate's 95 %
ellipsoid holds (the marker point's covariance plus the tracker's noise). The run's other
sensors (``run.points``: a coil on the body) are read with the tracker on the rows it sees and
occluded with it, as ``calibrate`` measured the model's error.
"""
from dataclasses import dataclass
import math
import time

import numpy as np

from continuum_statics.calibration.model_uncertainty import seen_mask
from continuum_statics.calibration.replay import replay
from continuum_statics.core.description.sensors import SensorReading
from continuum_statics.core.estimation.gates import chi2_quantile
from continuum_statics.core.estimation.state_estimation import point_covariance

#: The baseline's decay (s): the last tracker residual added to the model, fading.
BASELINE_DECAY = 10.0
#: The ellipsoid whose coverage is reported.
COVERAGE = 0.95


@dataclass(frozen=True)
class Occluded:
    """Errors (m) on the occluded rows of one pattern, and what the estimate said of them."""

    seen: int
    hidden: int
    rows: int
    fused: float  # RMS
    model: float
    baseline: float
    coverage: float  # fraction of occluded rows inside the 95 % ellipsoid
    median_us: float  # one estimate_shape call with the tracker, median
    max_us: float


def tip_sensor(robot):
    """Return the robot file's tip tracker (the sensor at the tip), or raise ValueError."""
    for sensor in robot.sensors:
        if sensor.at_tip and np.allclose(sensor.offset, robot.tip_marker):
            return sensor
    raise ValueError('the robot file has no sensor at the tip with the tip_marker offset '
                     '(sensors: - {name: tip_tracker, at: tip})')


def occlusion_replay(robot, run, seen, hidden, model_points=None):
    """Replay ``run`` with the tip tracker seen ``seen`` rows, then occluded ``hidden``."""
    sensor = tip_sensor(robot)
    others = [other for other in robot.sensors if other.name in run.points and other is not sensor]
    if model_points is None:
        model_points = replay(robot, run)[0]
    mask = seen_mask(len(run), seen, hidden)
    gate = chi2_quantile(COVERAGE, 3)
    fused, model, baseline, inside, durations = [], [], [], 0, []
    previous, last = None, None
    for i, lengths in enumerate(run.lengths):
        stamp = float(run.times[i])
        readings = None
        if mask[i]:
            readings = {sensor.name: SensorReading(run.tips[i], stamp=stamp)}
            readings.update((other.name, SensorReading(run.points[other.name][i], stamp=stamp))
                            for other in others if np.all(np.isfinite(run.points[other.name][i])))
        began = time.perf_counter()
        estimate = robot.estimate_shape(lengths, warm_start=previous, exact=True,
                                        sensors=readings, stamp=stamp)
        durations.append(time.perf_counter() - began)
        previous = estimate
        shape = estimate.shape
        point = shape.tip_position + shape.tip_rotation @ sensor.offset
        if mask[i]:
            last = (run.tips[i] - model_points[i], stamp)
            continue
        error = run.tips[i] - point
        fused.append(error)
        model.append(run.tips[i] - model_points[i])
        if last is not None:
            fade = math.exp(-(stamp - last[1]) / BASELINE_DECAY)
            baseline.append(run.tips[i] - model_points[i] - fade * last[0])
        spread = (point_covariance(estimate, sensor)
                  + sensor.position_sigma ** 2 * np.eye(3))
        inside += float(error @ np.linalg.solve(spread, error)) <= gate
    durations = np.array(durations) * 1e6
    return Occluded(seen, hidden, len(fused), _rms(fused), _rms(model), _rms(baseline),
                    inside / max(len(fused), 1), float(np.median(durations)),
                    float(np.max(durations)))


def _rms(errors):
    errors = np.asarray(errors, dtype=float).reshape(-1, 3)
    return float(np.sqrt(np.mean(np.sum(errors ** 2, axis=1)))) if len(errors) else math.nan
