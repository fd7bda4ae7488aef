"""``python -m continuum_statics warmup [--robot FILE]``: compile the kernels into the numba cache.

The venv setup runs it once, so that no node compiles at first use
(:func:`continuum_statics.core.warmup.warm_up` does the work).
"""
import argparse

from continuum_statics.core.warmup import warm_up, warm_up_dynamics


def main(argv=None):
    """Fill the kernel cache for the bundled robot files (or ``--robot FILE``); return 0."""
    from continuum_statics.core.robot import load_robot

    parser = argparse.ArgumentParser(prog='python -m continuum_statics warmup',
                                     description='compile the kernels into the numba cache')
    parser.add_argument('--robot', default=None, help='robot file (default: the bundled one)')
    options = parser.parse_args(argv)
    robot = None if options.robot is None else load_robot(options.robot)
    log = lambda line: print('warmup: %s' % line, flush=True)  # noqa: E731
    warm_up(robot, log=log)
    warm_up_dynamics(log=log)
    return 0
