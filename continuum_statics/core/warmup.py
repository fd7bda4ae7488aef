"""Compile every numba kernel at process start, on one thread, before anything is served.

numba compiles a kernel the first time it is called with a new set of argument types, in whatever
thread calls it: seconds per kernel on a cold cache, and two threads compiling at once have
crashed the process (segfault, LLVM assertion). A node therefore calls :func:`warm_up` in its
constructor, before it creates a subscription, a service or a thread; tools call it before they
start work. It runs the same public calls the nodes and tools make (so the same argument types:
array layouts included), once per process; later calls return at once.

Compiled code is cached on disk (``cache=True``): next to the sources when that directory is
writable (the venv route: ``__pycache__`` in the source tree), else in numba's per-user cache
directory (``~/.cache/numba`` or ``$XDG_CACHE_HOME/numba``, colcon/apt installs), or wherever
``NUMBA_CACHE_DIR`` points. With a warm cache the whole warm-up takes ~0.1-0.3 s.
"""
import sys
import threading
import time

import numpy as np

_LOCK = threading.Lock()
_DONE = False
#: The kernels Python calls (the others are compiled into them): each must have a signature
#: after the warm-up (``test/core/test_warmup.py``).
ENTRY_POINTS = (
    'continuum_statics.core.rod.kernel.integrate_batch',
    'continuum_statics.core.rod.kernel.integrate_passive',
    'continuum_statics.core.rod.kernel.cable_lengths_batch',
    'continuum_statics.core.rod.kernel.loads_from_state',
    'continuum_statics.core.rod.kernel.probe',
    'continuum_statics.core.rod.kernel.tip_jacobian',
    'continuum_statics.core.rod.tracking.track',
    'continuum_statics.core.rod.goal_tracking.goal_solve',
    'continuum_statics.core.rod.length_tracking.chord',
    'continuum_statics.core.rod.length_tracking.jacobian_pieces',
    'continuum_statics.core.rod.least_squares.constrained_step',
    'continuum_statics.core.rod.rotations._quaternions',
    'continuum_statics.core.estimation.state_estimation.move_states',
    'continuum_statics.core.rod.backbone_sampling._sample',
    'continuum_statics.core.rod.tendon_kernel.path_stretch',
    'continuum_statics.core.rod.kernel.section_tensions',
)
#: Modules whose numba dispatchers the warm-up must cover (see :func:`kernel_signatures`).
KERNEL_MODULES = (
    'continuum_statics.core.rod.kernel',
    'continuum_statics.core.rod.tracking',
    'continuum_statics.core.rod.goal_tracking',
    'continuum_statics.core.rod.length_tracking',
    'continuum_statics.core.rod.least_squares',
    'continuum_statics.core.rod.rotations',
    'continuum_statics.core.rod.backbone_sampling',
    'continuum_statics.core.rod.tendon_kernel',
    'continuum_statics.core.estimation.state_estimation',
    'continuum_statics.core.rod.dynamics_kernel',
)


def warm_up(robot=None, log=None):
    """Compile (or load from the cache) every kernel a node or tool can call; once per process.

    :param robot: the caller's :class:`~continuum_statics.core.robot.Robot`; a robot without
        cables is complemented by a small robot with cables, so the cable kernels are ready too
    :param log: callable(str) for one line saying how long it took (None: silent)
    :returns: seconds spent (0.0 when already done in this process)
    """
    global _DONE
    with _LOCK:
        if _DONE:
            return 0.0
        start = time.perf_counter()
        robots = [] if robot is None else [robot]
        if robot is None or not robot.cable_names:
            robots.append(_bundled_robot())
        for each in robots:
            _exercise(each)
        _DONE = True
        elapsed = time.perf_counter() - start
    if log is not None:
        log('kernels ready in %.2f s (%s)' % (elapsed, 'compiled or loaded from the numba cache'))
    return elapsed


#: A small one-section robot with cables: the cable kernels of a passive caller's process.
_CABLE_ROBOT = {
    'name': 'warmup',
    'rod': {'length': 0.3, 'diameter': 2e-3, 'youngs_modulus': 58e9, 'poisson_ratio': 0.33,
            'density': 6450.0},
    'base': {'frame_id': 'base_link', 'position': [0, 0, 0], 'orientation': [0, 0, 0, 1]},
    'gravity': [0.0, 0.0, -9.81],
    'cables': [{'name': 'c%d' % i, 'offset': offset, 'length_limits': [0.27, 0.33]}
               for i, offset in enumerate(([0.01, 0, 0], [0, 0.01, 0], [-0.01, 0, 0]))],
    'guides': [0.1, 0.2, 0.3],
    'solver': {'steps': 12},
}


def _bundled_robot():
    from continuum_statics.core.description.robot_file import parse_robot_description
    from continuum_statics.core.robot import Robot

    return Robot(parse_robot_description(_CABLE_ROBOT, 'warm-up robot'))


def _exercise(robot):
    """Make every call the nodes and tools make, with their argument types."""
    from continuum_statics.core.estimation.shape_estimation import Tracking
    from continuum_statics.core.estimation.state_estimation import move_states
    from continuum_statics.core.rod.backbone_sampling import BackboneSampler
    from continuum_statics.core.rod.rotations import rotation_to_quaternion

    zero = np.zeros(3)
    load = np.zeros(6)  # the nodes pass slices of a 6-vector as tip force and moment
    shape = robot.solve_ivp(np.zeros(3))
    sampler = BackboneSampler(shape.s, 20)
    sampler.sample(shape.positions, shape.rotations)
    rotation_to_quaternion(shape.rotations)
    rotation_to_quaternion(shape.rotations[:1])
    rotation_to_quaternion(shape.tip_rotation)
    move_states(shape.states.copy(), np.zeros((len(shape.s), 3, 1)),  # a fused estimate's
                 np.zeros((len(shape.s), 3, 1)), np.zeros(1))  # shape
    robot.jacobian(zero)
    robot.solve_bvp(tip_force=load[:3], tip_moment=load[3:])
    if not robot.cable_names:
        return
    u0 = np.full(3, 0.5 / robot.length)
    u0[2] = 0.0
    bent = robot.solve_ivp(u0)
    robot.cable_jacobian(u0)
    lengths = robot.cable_lengths(bent)
    estimate = robot.estimate_shape(lengths, tip_force=load[:3], tip_moment=load[3:])
    # tracking: warm start with the previous Jacobians (the compiled Broyden path)
    robot.estimate_shape(lengths + 1e-5, tip_force=load[:3], tip_moment=load[3:],
                         warm_start=estimate)
    robot.estimate_shape(lengths + 2e-5, tip_force=load[:3], tip_moment=load[3:],
                         warm_start=estimate, tracking=Tracking())  # statics' per-cycle call
    tensions = np.full(len(robot.cable_names), 0.1)
    robot.estimate_shape(lengths, tip_force=load[:3], tip_moment=load[3:], tensions=tensions,
                         warm_start=estimate)
    robot.solve_tensions(tensions)
    goal = robot.solve_tip_goal(bent.tip_position, tip_force=load[:3], tip_moment=load[3:],
                                warm_start=estimate)
    robot.solve_tip_goal(bent.tip_position, goal_direction=bent.tip_rotation[:, 2])
    robot.equilibrium_between(estimate, goal, 0.5, tip_force=load[:3], tip_moment=load[3:],
                              warm_start=estimate)
    _exercise_python_newton(robot, lengths)
    _exercise_tendons(robot, lengths, goal)


def _exercise_python_newton(robot, lengths):
    """Run the Python Gauss-Newton (an estimate's last resort) with its compiled step."""
    from continuum_statics.core.description.layout import ProbeRows
    from continuum_statics.core.rod.least_squares import constrained_gauss_newton

    rows, zero = ProbeRows(len(lengths)), np.zeros(3)

    def evaluate(x):
        probed = robot.probe(x, robot.state_size, zero, zero)
        values, jac = probed.values, probed.jacobian
        return (values[rows.lengths] - lengths, jac[rows.lengths], values[rows.balance],
                jac[rows.balance], probed.states)

    constrained_gauss_newton(evaluate, robot.passive_state(), 2, 1e-9, robot.length)


def _exercise_tendons(robot, lengths, goal):
    """Real tendons: solve_lengths (friction, chord steps), commands with min_tension."""
    import dataclasses

    from continuum_statics.core.description.tendons import Tendons
    from continuum_statics.core.robot import Robot
    from continuum_statics.core.statics.tendon_commands import command_for

    n = len(robot.cable_names)
    real = Robot(dataclasses.replace(robot.description, tendons=dataclasses.replace(
        Tendons.default(n), stiffness=np.full(n, 1e3), friction=np.full(n, 0.05))))
    other = 'point_moment' if robot.cable_model == 'distributed' else 'distributed'
    # Newton's tension columns are a compiled batch in the distributed model, from Python
    Robot(dataclasses.replace(robot.description, cable_model=other)).solve_lengths(lengths)
    for each in (robot, real):
        first = each.solve_lengths(lengths - 1e-4)
        second = each.solve_lengths(lengths - 2e-4, warm_start=first)  # compiled chord steps
        # Newton in Python with the friction of a known motion (a chord that gave up)
        each.solve_lengths(lengths - 3e-4, warm_start=dataclasses.replace(
            second, jacobian_parts=None))
        each.estimate_shape(lengths, warm_start=first)
        command_for(each, goal.shape, min_tension=0.1)


def warm_up_dynamics(log=None):
    """Compile the rod-in-motion kernels (a start and a step driven by lengths); return s.

    Not part of :func:`warm_up`: only the simulated driver with ``sim.dynamics``, ``simulate``
    and ``calibrate --fit damping`` step the rod; the venv setup fills the cache with both.
    """
    from continuum_statics.config_paths import config_file
    from continuum_statics.core.robot import load_robot

    start = time.perf_counter()
    robot = load_robot(config_file('tendon_robot_dynamic.yaml'))
    sim = robot.dynamics()
    sim.start(lengths=robot.straight_cable_lengths)
    sim.step(lengths=robot.straight_cable_lengths - 1e-4)
    seconds = time.perf_counter() - start
    if log is not None:
        log('dynamics kernels ready in %.2f s' % seconds)
    return seconds


def kernel_signatures():
    """Return {kernel name: number of compiled signatures} over :data:`KERNEL_MODULES`.

    A call after :func:`warm_up` that raises a count compiled at first use (the tests check that
    a node's normal work never does).
    """
    from numba.core.registry import CPUDispatcher

    counts = {}
    for name in KERNEL_MODULES:
        module = sys.modules.get(name)
        if module is None:
            continue
        for attribute, value in vars(module).items():
            if isinstance(value, CPUDispatcher):
                counts['%s.%s' % (name, attribute)] = len(value.signatures)
    return counts
