"""Fit the rod's bending damping to a recorded step or release (``calibrate --fit damping``).

The run (CSV or bag, as any recorded run: timestamps, the motors' cable lengths, the measured
tip) starts at rest. Its motor lengths, monotone cubic between samples, drive
:class:`~continuum_statics.core.dynamics.rod_dynamics.RodDynamics` from the static equilibrium at
the first
sample; the Kelvin-Voigt bending damping B (N m^2 s, ``rod.damping.bending``) minimises the
root-mean-square distance between the measured tips and the simulated tip displacements from
that first sample plus the constant offset that fits best (a tracker registered up to a
translation is enough; its rotation must be the base frame's). One parameter, searched on
log B between damping ratios 1e-4 and 2 of the first bending mode (zeta = B omega_1 / (2 E I),
Euler-Bernoulli's omega_1), by golden section.
"""
from dataclasses import dataclass, replace
import math

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import minimize_scalar

from continuum_statics.core.robot import Robot

#: the damping ratios the search spans on the first mode
ZETA_RANGE = (1e-4, 2.0)


@dataclass(frozen=True)
class DampingFit:
    """Result of :func:`fit_damping`: B (N m^2 s), its first-mode ratio, the tip errors (m)."""

    bending: float
    zeta: float
    rms_before: float
    rms_after: float
    evaluations: int
    samples: int


def with_damping(robot, bending):
    """Return ``robot`` with the rod's bending damping ``bending`` (N m^2 s)."""
    rod = replace(robot.description.rod, bending_damping=float(bending))
    return Robot(replace(robot.description, rod=rod))


def simulated_displacements(robot, run):
    """Tip displacements (T, 3) m from the first sample of ``robot`` driven by the run."""
    sim = robot.dynamics()
    sim.start(lengths=run.lengths[0])
    start = sim.state.tip_position.copy()
    times = run.times - run.times[0]
    # the motors between samples: monotone cubic (a motor's lag is smooth; straight lines
    # between 250 Hz samples biased B by -2 % in the synthetic recovery)
    motors = PchipInterpolator(times, run.lengths, axis=0, extrapolate=True)
    out = np.zeros((len(times), 3))
    now, row = 0.0, 1
    while row < len(times):
        now += sim.dt
        state = sim.step(lengths=motors(now))
        if not state.converged:
            raise ValueError('the rod in motion found no step at t = %.3f s of %s'
                             % (now, run.source))
        while row < len(times) and times[row] <= now + 1e-12:
            out[row] = state.tip_position - start
            row += 1
    return out


def fit_damping(robot, run):
    """Fit the bending damping to a recorded step or release (the module docstring)."""
    if robot.tendons.is_ideal:
        raise ValueError("--fit damping replays the motors' lengths through real tendons: "
                         'the robot file needs a tendons block')
    if len(run) < 10:
        raise ValueError('%s: %d samples; a step or release needs its swing sampled'
                         % (run.source, len(run)))
    omega, ei = robot.description.rod.first_mode, robot.c[0]

    def rms(log_b):
        model = simulated_displacements(with_damping(robot, math.exp(log_b)), run)
        residual = run.tips - model
        residual -= residual.mean(axis=0)  # the tracker's offset: fitted, in closed form
        return float(np.sqrt(np.mean(np.sum(residual ** 2, axis=1))))

    bounds = [math.log(2.0 * zeta * ei / omega) for zeta in ZETA_RANGE]
    before_b = robot.description.rod.bending_damping
    before = rms(math.log(before_b)) if before_b > 0.0 else rms(bounds[0])
    result = minimize_scalar(rms, bounds=bounds, method='bounded',
                             options={'xatol': 1e-3, 'maxiter': 40})
    bending = math.exp(result.x)
    return DampingFit(bending, bending * omega / (2.0 * ei), before, float(result.fun),
                      int(result.nfev) + 1, len(run))


def calibrate_damping(robot_file, data_file, column_map, output=None,
                      tip_topic='tip_pose_measured'):
    """Run the fit on a file and write the robot file with ``rod.damping``; return a summary."""
    from continuum_statics import load_robot
    from continuum_statics.calibration.robot_writer import write_robot_file
    from continuum_statics.calibration.runs import read_run

    robot = load_robot(robot_file)
    run = read_run(data_file, robot, column_map, tip_topic)
    fit = fit_damping(robot, run)
    if output:
        write_robot_file(output, robot_file, with_damping(robot, fit.bending), ('damping',), (
            'rod.damping.bending fitted to the step or release %s (%d samples): tip '
            'displacement rms %.3f mm -> %.3f mm, first-mode damping ratio %.4f'
            % (data_file, fit.samples, 1e3 * fit.rms_before, 1e3 * fit.rms_after, fit.zeta),))
    return {'data': str(data_file), 'samples': fit.samples, 'evaluations': fit.evaluations,
            'fitted': {'damping': {'before': robot.description.rod.bending_damping,
                                   'after': fit.bending, 'unit': 'N m^2 s',
                                   'first_mode_damping_ratio': fit.zeta}},
            'rms_before': fit.rms_before, 'rms_after': fit.rms_after,
            'output': output}
