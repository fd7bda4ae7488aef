"""``python -m continuum_statics warmup [--robot FILE]``: compile the kernels into the numba cache.

The venv setup runs it once, so that no node compiles at first use
(:func:`continuum_statics.core.warmup.warm_up` does the work: on a cold cache in two worker
processes, the rod-in-motion kernels as a third job). It prints each kernel it compiled with its
compile time (wall and CPU, and which process), then the total.
"""
import argparse

from continuum_statics.core.warmup import warm_up


def main(argv=None):
    """Fill the kernel cache for the bundled robot files (or ``--robot FILE``); return 0."""
    from continuum_statics.core.robot import load_robot

    parser = argparse.ArgumentParser(prog='python -m continuum_statics warmup',
                                     description='compile the kernels into the numba cache')
    parser.add_argument('--robot', default=None, help='robot file (default: the bundled one)')
    parser.add_argument('--workers', type=int, default=None,
                        help='processes compiling a cold cache (default: 2 on a cold cache with '
                             '2 cores or more; 0: this process alone)')
    options = parser.parse_args(argv)
    robot = None if options.robot is None else load_robot(options.robot)
    log = lambda line: print('warmup: %s' % line, flush=True)  # noqa: E731
    warm_up(robot, log=log, workers=options.workers, dynamics=True, per_kernel=True)
    return 0
