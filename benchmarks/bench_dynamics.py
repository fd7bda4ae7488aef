"""Benchmark of the rod in motion: real-time factor and step times, beside PyElastica.

``python -m benchmarks.bench_dynamics`` (part of ``make bench``). Per robot: the
motors move between random targets 4 mm apart every 0.5 s at the simulated driver's 0.05 m/s,
for 3 simulated s at the robot file's dt (1 ms), one core; the figures are the step's median,
p99 and max and the real-time factor (simulated s per CPU s). The baseline, in the same run:
PyElastica 1.0 (explicit position Verlet, Gazzola et al. 2018) on the same single-section rod
(30 elements, gravity, clamped, a 0.1 N tip load ramped over 50 ms, a linear damper of 1/s) at
steps about its stability limit (an element's rotation against its shear stiffness, ~0.3 us
for this Nitinol rod), each said whether its tip stayed near the rod.
"""
import sys
import time

import numpy as np

from continuum_statics import load_robot
from continuum_statics.config_paths import config_file

#: (robot file, what it is)
ROBOTS = (('tendon_robot_dynamic.yaml', 'single section, real tendons, 5 % damping'),
          ('three_section_robot_real_tendons.yaml', 'three sections, real tendons, undamped'))
DURATION = 3.0  # simulated s per robot
MOVE_EVERY = 0.5  # s between motor targets
MOTOR_SPEED = 0.05  # m/s, the simulated driver's default


def bench_robot(robot, seed=36):
    """Step times (s) of one robot's motion (the module docstring) after a warm-up start."""
    sim = robot.dynamics()
    lengths = robot.straight_cable_lengths.copy()
    sim.start(lengths=lengths)
    sim.step(lengths=lengths)  # compiled (or loaded from the cache) before the clock runs
    rng = np.random.default_rng(seed)
    times, failed = [], 0
    target = lengths
    per_step = MOTOR_SPEED * sim.dt
    for i in range(int(round(DURATION / sim.dt))):
        if i % int(round(MOVE_EVERY / sim.dt)) == 0:
            target = robot.straight_cable_lengths + rng.uniform(-0.004, 0.004, len(lengths))
        lengths = lengths + np.clip(target - lengths, -per_step, per_step)
        began = time.perf_counter()
        state = sim.step(lengths=lengths)
        times.append(time.perf_counter() - began)
        failed += not state.converged
    return np.array(times), sim, failed


def pyelastica_rate(robot, dt, duration):
    """PyElastica on ``robot``'s rod at step ``dt`` (s): (real-time factor, tip stayed near).

    "Near": within two rod lengths of the base at the end (its tip's static deflection under
    the 0.1 N is 20 mm).
    """
    import elastica as ea

    rod_data = robot.description.rod

    class Simulator(ea.BaseSystemCollection, ea.Constraints, ea.Forcing, ea.Damping):
        pass

    simulator = Simulator()
    rod = ea.CosseratRod.straight_rod(
        30, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), robot.length,
        rod_data.diameter / 2.0, rod_data.density, youngs_modulus=rod_data.youngs_modulus,
        shear_modulus=rod_data.shear_modulus)
    simulator.append(rod)
    simulator.constrain(rod).using(ea.OneEndFixedBC, constrained_position_idx=(0,),
                                   constrained_director_idx=(0,))
    simulator.add_forcing_to(rod).using(ea.GravityForces,
                                        acc_gravity=np.asarray(robot.gravity, dtype=float))
    simulator.add_forcing_to(rod).using(ea.EndpointForces, np.zeros(3),
                                        np.array([0.1, 0.0, 0.0]), ramp_up_time=0.05)
    simulator.dampen(rod).using(ea.AnalyticalLinearDamper, uniform_damping_constant=1.0,
                                time_step=dt)
    simulator.finalize()
    stepper = ea.PositionVerlet()
    now = 0.0
    stepper.step(simulator, now, dt)  # compiled before the clock runs
    steps = int(round(duration / dt))
    began = time.perf_counter()
    for _ in range(steps):
        now = stepper.step(simulator, now, dt)
    elapsed = time.perf_counter() - began
    tip = rod.position_collection[:, -1]
    near = bool(np.all(np.isfinite(tip)) and np.linalg.norm(tip) < 2.0 * robot.length)
    return steps * dt / elapsed, near


def main(argv=None):
    """Print the figures (the module docstring)."""
    print('rod in motion: %g simulated s per robot, motors to a new target every %g s'
          % (DURATION, MOVE_EVERY))
    single = None
    for name, what in ROBOTS:
        robot = load_robot(config_file(name))
        single = single or robot
        times, sim, failed = bench_robot(robot)
        print('  %-40s dt %g s, %d segments: step median %.0f us, p99 %.0f us, max %.0f us; '
              'real-time factor %.1f; %d failed steps (%s)'
              % (name, sim.dt, sim.segments, 1e6 * np.median(times),
                 1e6 * np.percentile(times, 99), 1e6 * times.max(),
                 DURATION / times.sum(), failed, what))
    try:
        import elastica  # noqa: F401
    except ImportError:
        print('  PyElastica: not installed (pip install pyelastica): no baseline')
        return 1
    rod = single.description.rod
    # an explicit step must resolve an element's rotation against its shear stiffness:
    # omega = sqrt(G A / (rho I)) = sqrt(G / rho) / r_g, r_g = d / 4 (under a microsecond)
    limit = rod.diameter / 4.0 / np.sqrt(rod.shear_modulus / rod.density)
    print('  PyElastica 1.0, the same rod in 30 elements (explicit: dt under ~r_g / shear wave '
          'speed = %.2g s):' % limit)
    for dt in (1e-6, 3e-7, 1e-7):
        rate, near = pyelastica_rate(single, dt, 0.02)
        print('    dt %.2g s: real-time factor %.4f; after 0.02 s the tip %s' % (
            dt, rate, 'is near the rod' if near else 'has left the rod (unstable)'))
    return 0


if __name__ == '__main__':
    sys.exit(main())
