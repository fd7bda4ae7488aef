"""Compiled kernels release the GIL: a node's other threads run beside a long solve.

A node's intake thread, its executor and, in one bringup process, the other nodes are Python
threads. A kernel that kept the GIL for a whole tip-goal solve (milliseconds) stalled them all
(the statics intake of one process once waited 0.5 s behind a burst of goals).
The one exception keeps it on purpose, said in its own comment: the rod in motion's time step,
called a thousand times a second, which would otherwise wait for the GIL after every step.
"""
import ast
from pathlib import Path
import threading
import time

import numpy as np

from continuum_statics import load_robot

PACKAGE = Path(__file__).resolve().parents[2] / 'continuum_statics'
#: Kernels that keep the GIL, declared ``nogil=False`` with the reason beside them.
HOLDS_THE_GIL = {'core/rod/dynamics_kernel.py:advance'}


def test_every_compiled_function_is_declared_nogil():
    missing = []
    for path in PACKAGE.rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef):
                continue
            for decorator in node.decorator_list:
                if isinstance(decorator, ast.Call) and ast.unparse(decorator.func) in (
                        'numba.njit', 'njit', 'numba.jit'):
                    flags = {k.arg: ast.unparse(k.value) for k in decorator.keywords}
                    name = '%s:%s' % (path.relative_to(PACKAGE), node.name)
                    expected = 'False' if name in HOLDS_THE_GIL else 'True'
                    if flags.get('nogil') != expected:
                        missing.append(name)
    assert not missing


def test_a_python_thread_runs_while_a_long_kernel_call_runs():
    robot = load_robot(PACKAGE.parent / 'config' / 'two_section_robot.yaml')
    batch = 3000  # ~25 us each: tens of ms inside one compiled call
    n = len(robot.cable_names)
    args = (np.zeros((batch, 3)), np.tile([1.0, 0.5, 0.0], (batch, 1)),
            np.zeros((batch, len(robot.sections), 3)), np.full((batch, n), 0.3))
    robot.model.integrate(*(a[:1] for a in args))  # compiled, warm
    stamps, stop = [], threading.Event()

    def count():
        while not stop.is_set():
            stamps.append(time.perf_counter())

    counter = threading.Thread(target=count)
    counter.start()
    try:
        while len(stamps) < 1000:  # the counter is running
            pass
        begin = time.perf_counter()
        robot.model.integrate(*args)
        end = time.perf_counter()
    finally:
        stop.set()
        counter.join()
    during = [t for t in stamps if begin < t < end]
    # with the GIL held the counter could only run once the call has returned (the GIL is handed
    # over at the first bytecode after it): its first stamp would come at the end
    assert during and during[0] - begin < 0.25 * (end - begin)
