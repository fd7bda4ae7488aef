"""Compile every numba kernel at process start, before anything is served.

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

A cold cache (a fresh clone, CI, a new ``NUMBA_CACHE_DIR``): :func:`warm_up` compiles the kernels
in two processes at once into the shared cache (:data:`WORKER_JOBS`: a new process follows the
solvers' chain ``integrate_batch`` -> ``probe`` -> ``track``/``goal_solve``, this one meanwhile
compiles the kernels off that chain, then the tendon solver), then loads whatever it did not
compile itself from the cache (~22 s instead of ~40 s on two idle cores). A kernel is compiled by
one process only: each kernel's compile holds a lock file next to its cache index
(:func:`install_compile_locks`), so a second process waits and loads it from the cache instead of
compiling it again or writing the same index at the same time. Every kernel has one type
specialisation (:data:`SPECIALISATIONS`): call sites pass the same types (no ``Literal`` constants
from compiled callers; writable float64 C arrays: a :class:`Shape`'s read-only ones are copied).
"""
import contextlib
import os
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
#: Kernels that may have more than one type specialisation, at most this many, and why; every
#: other kernel has one (none: ``inline='always'``, compiled into its callers). A call site that
#: passes other types (a ``Literal`` constant, an 'A' or read-only array, an int for a float)
#: adds one, seconds of cold compile: ``test/core/test_warmup.py`` fails.
SPECIALISATIONS = {}
#: The statics warm-up's jobs on a cold cache: the first in a new process, the other in this
#: one meanwhile (see module doc).
WORKER_JOBS = ('chain', 'off_chain')
#: Environment variable: worker processes of a cold warm-up (0 or 1: compile in this process).
WORKERS_VARIABLE = 'CONTINUUM_STATICS_WARMUP_WORKERS'


def warm_up(robot=None, log=None, workers=None, dynamics=False, per_kernel=False):
    """Compile (or load from the cache) every kernel a node or tool can call; once per process.

    :param robot: the caller's :class:`~continuum_statics.core.robot.Robot`; a robot without
        cables is complemented by a small robot with cables, so the cable kernels are ready too
    :param log: callable(str) for one line saying how long it took, and on a cold cache one
        saying what the compiles cost (None: silent)
    :param workers: processes compiling a cold cache in parallel (None:
        ``$CONTINUUM_STATICS_WARMUP_WORKERS``, else 2 when a kernel has no cache index and the
        machine has 2 cores or more; 0 or 1: none, this process compiles)
    :param dynamics: also :func:`warm_up_dynamics` (compiled by a third job in the workers)
    :param per_kernel: log one line per compiled kernel too: its compile time, wall and CPU
    :returns: seconds spent (0.0 when already done in this process, without ``dynamics``)
    """
    global _DONE
    with _LOCK:
        if _DONE:
            return warm_up_dynamics(log) if dynamics else 0.0
        start = time.perf_counter()
        install_compile_locks()
        if workers is None:
            workers = default_workers()
        reports, failed = [], None
        if workers > 1:
            try:  # the first job in new processes, the others here meanwhile
                reports = compile_in_workers(WORKER_JOBS[:1], workers - 1, WORKER_JOBS[1:] + (
                    ('dynamics',) if dynamics else ()))
            except Exception as error:  # noqa: BLE001 - this process then compiles what is left
                failed = 'the worker processes failed (%s: %s); compiled here' % (
                    type(error).__name__, error)
        with record_compiles() as here:
            robots = [] if robot is None else [robot]
            if robot is None or not robot.cable_names:
                robots.append(_bundled_robot())
            for each in robots:
                _exercise(each)
            if dynamics:
                warm_up_dynamics()
        reports.append(here)
        _DONE = True
        elapsed = time.perf_counter() - start
    if log is not None:
        if failed:
            log(failed)
        lines = compile_report(reports)
        for line in lines if per_kernel else lines[-1:]:
            log(line)
        log('kernels ready in %.2f s (%s)' % (elapsed, 'compiled or loaded from the numba cache'
                                              if workers <= 1 else
                                              'compiled in %d processes' % workers))
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
    _exercise_off_chain(robot, robot.solve_ivp(np.zeros(3)))
    _exercise_chain(robot)


def _exercise_off_chain(robot, shape):
    """Run the kernels off the solvers' chain: sampling, quaternions, loads, the Jacobian.

    ``shape``: any shape of ``robot`` (one made without a kernel in the ``off_chain`` worker).
    """
    from continuum_statics.core.estimation.state_estimation import move_states
    from continuum_statics.core.rod.backbone_sampling import BackboneSampler
    from continuum_statics.core.rod.rotations import rotation_to_quaternion

    sampler = BackboneSampler(shape.s, 20)
    sampler.sample(shape.positions, shape.rotations)
    rotation_to_quaternion(shape.rotations)
    rotation_to_quaternion(shape.rotations[:1])
    rotation_to_quaternion(shape.tip_rotation)
    move_states(shape.states.copy(), np.zeros((len(shape.s), 3, 1)),  # a fused estimate's
                 np.zeros((len(shape.s), 3, 1)), np.zeros(1))  # shape
    if robot.cable_names:
        robot.loads(robot.passive_state())  # loads_from_state, section_tensions
        robot.cable_lengths(shape)
    robot.jacobian(np.zeros(3))


def _exercise_chain(robot):
    """integrate_batch -> probe -> track, goal_solve, the tendon solver, in the nodes' order."""
    from continuum_statics.core.estimation.shape_estimation import Tracking

    load = np.zeros(6)  # the nodes pass slices of a 6-vector as tip force and moment
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


def _worker_job(job):
    """Run one of :data:`WORKER_JOBS` (or ``dynamics``), recording its compiles; its report.

    ``chain``: :func:`_exercise_chain` (its kernels one after the other). ``off_chain``: the
    kernels the chain needs late or not at all, compiled meanwhile: the solvers' step, sampling
    and quaternions of a shape made without a kernel, the Jacobian, then the tendon solver
    (``chord``, ``path_stretch``: the chain's last part) from its start.
    Whatever the other process compiles first is loaded from the cache here. Run in this
    process too (:func:`compile_in_workers`' ``here``).
    """
    from continuum_statics.core.description.layout import ROTATION, STATE_SIZE

    install_compile_locks()
    wall, cpu = time.perf_counter(), time.process_time()
    with record_compiles() as report:
        if job == 'dynamics':
            warm_up_dynamics()
        else:
            robot = _bundled_robot()
            if job == 'chain':
                _exercise_chain(robot)
            else:
                from continuum_statics.core.rod.least_squares import constrained_step

                # the solvers' step (track and goal_solve call it): its types, ~3.5 s CPU
                constrained_step(np.ones(2), np.eye(2), np.zeros(1), np.ones((1, 2)), 1e-3)
                states = np.zeros((len(robot.s_grid), STATE_SIZE))
                states[:, ROTATION] = np.eye(3).ravel()  # a straight rod's rotations
                shape = robot.make_shape(robot.passive_state(), np.zeros(3), states)
                _exercise_off_chain(robot, shape)
                lengths = robot.cable_lengths(robot.solve_ivp([1.0, 0.0, 0.0]))
                first = robot.solve_lengths(lengths)
                robot.solve_lengths(lengths - 1e-4, warm_start=first)
    report['job'] = job
    report['wall'], report['cpu'] = time.perf_counter() - wall, time.process_time() - cpu
    return report


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

    install_compile_locks()
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

    Each kernel under the module that defines it (not where another module imports it).

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
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                counts['%s.%s' % (name, attribute)] = len(value.signatures)
    return counts


def default_workers():
    """Return the worker processes of a cold warm-up.

    ``$CONTINUUM_STATICS_WARMUP_WORKERS``, else 2 when a statics kernel has no cache index yet
    (a fresh cache) and there are 2 cores or more, else 0 (a warm cache loads in ~0.2 s).
    """
    value = os.environ.get(WORKERS_VARIABLE)
    if value:
        return max(0, int(value))
    if (os.cpu_count() or 1) < 2:
        return 0
    dispatchers = _dispatchers(sorted({name.rsplit('.', 1)[0] for name in ENTRY_POINTS}))
    return 2 if any(not _has_cache(dispatchers[name]) for name in ENTRY_POINTS) else 0


def _dispatchers(modules=KERNEL_MODULES):
    """{kernel name: numba dispatcher} of the kernels defined in ``modules`` (imported)."""
    import importlib

    from numba.core.registry import CPUDispatcher

    found = {}
    for name in modules:
        module = importlib.import_module(name)
        for attribute, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                found['%s.%s' % (name, attribute)] = value
    return found


def _index_path(dispatcher):
    """Return the file of ``dispatcher``'s numba cache index (None: no on-disk cache)."""
    cache_file = getattr(getattr(dispatcher, '_cache', None), '_cache_file', None)
    return getattr(cache_file, '_index_path', None)


def _has_cache(dispatcher):
    """Return True if ``dispatcher`` has an on-disk cache index of its current source."""
    cache_file = getattr(getattr(dispatcher, '_cache', None), '_cache_file', None)
    try:  # numba's index of an edited source file reads as empty
        return cache_file is None or bool(cache_file._load_index())
    except Exception:  # noqa: BLE001 - unreadable: as good as none
        return False


#: the ``kernels`` dicts of the :func:`record_compiles` blocks open in this process
_RECORDS = []
_FRAMES = []  # per nested compile: [children's wall, children's CPU]


@contextlib.contextmanager
def record_compiles():
    """Record each kernel compiled meanwhile in this process.

    Yields a report dict whose ``kernels`` maps kernel name -> (wall s, CPU s) of its own
    compile: the kernels it calls and waits for another process's compile excluded, numba's
    library code it needs (``np.linalg``, array functions) included.
    """
    report = {'kernels': {}, 'pid': os.getpid()}
    _RECORDS.append(report['kernels'])
    try:
        yield report
    finally:
        _RECORDS.remove(report['kernels'])


@contextlib.contextmanager
def _file_lock(path):
    import fcntl

    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:  # a read-only cache directory: numba will not write there either
        yield
        return
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)  # releases the lock


def install_compile_locks():
    """Make each kernel's load-or-compile exclusive across processes (idempotent).

    The dispatcher's ``compile`` (what numba runs for a call with new types, from Python or
    from another kernel) holds numba's compiler lock, then a lock file next to the kernel's cache
    index (``<index>.lock``) while it loads the kernel from the cache or compiles and saves it.
    Processes warming up at once then compile each kernel once: the others wait and load it.
    Locks are taken caller before callee (numba compiles callees inside their caller), and
    kernels never call each other in a cycle: no deadlock.
    """
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.sigutils import normalize_signature

    for name, dispatcher in _dispatchers().items():
        if getattr(dispatcher, '_continuum_locked', False):
            continue
        path = _index_path(dispatcher)
        if path is None:
            continue

        def compile(sig, _original=dispatcher.compile, _dispatcher=dispatcher, _name=name,
                    _lock=path + '.lock'):
            if tuple(normalize_signature(sig)[0]) in _dispatcher.overloads:
                return _original(sig)
            with global_compiler_lock:
                wall, cpu = time.perf_counter(), time.thread_time()
                with _file_lock(_lock):
                    waited = time.perf_counter() - wall
                    misses = sum(_dispatcher._cache_misses.values())
                    _FRAMES.append([0.0, 0.0])
                    try:
                        return _original(sig)
                    finally:
                        children = _FRAMES.pop()
                        wall = time.perf_counter() - wall
                        cpu = time.thread_time() - cpu
                        if _FRAMES:
                            _FRAMES[-1][0] += wall
                            _FRAMES[-1][1] += cpu
                        if sum(_dispatcher._cache_misses.values()) > misses:
                            for record in _RECORDS:
                                total = record.get(_name, (0.0, 0.0))
                                record[_name] = (total[0] + wall - waited - children[0],
                                                 total[1] + cpu - children[1])

        dispatcher.compile = compile
        dispatcher._continuum_locked = True


def compile_in_workers(jobs, processes, here=()):
    """Run ``jobs`` (:func:`_worker_job` names), each in a new process, ``processes`` at a time.

    ``here``: jobs this process runs meanwhile, one after the other (it would wait otherwise).
    Returns the reports of ``here`` and ``jobs``, in that order. A new interpreter per job (not
    ``multiprocessing``: a fork would copy a node's DDS threads half-way, and a spawn re-imports
    the caller's ``__main__``, a script without a main guard runs again). The jobs share this
    process's numba cache and package (``NUMBA_CACHE_DIR`` inherited, this copy first). Raises
    ``RuntimeError`` when a job fails (its output's tail said).
    """
    import json
    import subprocess
    import tempfile

    # this package's copy, whatever put it on this process's path (its cache is per source file)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    code = ('import sys; sys.path.insert(0, %r); '
            'from continuum_statics.core.warmup import _worker_main; _worker_main()' % root)
    waiting, running, reports = list(enumerate(jobs)), [], {}
    try:
        local = []
        while waiting or running:
            while waiting and len(running) < max(1, processes):
                index, job = waiting.pop(0)
                output = tempfile.TemporaryFile('w+')  # a pipe could fill up: numba's warnings
                running.append((index, job, output, subprocess.Popen(
                    [sys.executable, '-c', code, job], stdin=subprocess.DEVNULL, stdout=output,
                    stderr=subprocess.STDOUT, text=True)))
            if len(local) < len(here):
                local.append(_worker_job(here[len(local)]))
                continue
            time.sleep(0.02)
            for entry in [entry for entry in running if entry[3].poll() is not None]:
                running.remove(entry)
                index, job, output, process = entry
                output.seek(0)
                lines = output.read().splitlines()
                output.close()
                if process.returncode != 0 or not lines:
                    raise RuntimeError('warm-up job %s exited with %s: %s' % (
                        job, process.returncode, ' | '.join(lines[-5:])))
                reports[index] = json.loads(lines[-1])
    finally:
        for _, _, output, process in running:  # an error, or this process interrupted
            process.kill()
            process.wait()
            output.close()
    return local + [_worker_job(job) for job in here[len(local):]] + [
        reports[index] for index in range(len(jobs))]


def _worker_main():
    """``python -c``: run the job ``sys.argv[1]``; its report as JSON on the last line."""
    import json

    report = _worker_job(sys.argv[1])
    print(json.dumps(report), flush=True)


def compile_report(reports):
    """Return lines for the log: each compiled kernel's compile time and where, then the sums.

    Slowest (CPU) first; wall and CPU seconds of each kernel's own compile, the process (a
    worker job, or ``here``). No lines when nothing was compiled (a warm cache).
    """
    rows = []
    for report in reports:
        where = report.get('job', 'here')
        for name, (wall, cpu) in report['kernels'].items():
            rows.append((cpu, wall, name, where))
    if not rows:
        return []
    lines = ['compiled %-55s %7.2f s wall %7.2f s CPU  (%s)'
             % (name.replace('continuum_statics.core.', ''), wall, cpu, where)
             for cpu, wall, name, where in sorted(rows, reverse=True)]
    lines.append('compiled %d kernels: %.2f s CPU in all%s' % (
        len(rows), sum(row[0] for row in rows), ''.join(
            '; %s process %.2f s wall %.2f s CPU' % (report['job'], report['wall'], report['cpu'])
            for report in reports if 'job' in report)))
    return lines
