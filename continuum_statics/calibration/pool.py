"""Worker processes for the finite-difference Jacobian columns of a fit.

Forked workers share the fitted model without pickling it. Where ``fork`` is not available
(Windows, or a caller that asks for one worker) the columns run one after the other in this
process: the same results, only slower.
"""
from concurrent.futures import ProcessPoolExecutor
import contextlib
import gc
import multiprocessing
import os


class SerialPool:
    """The fallback: ``map`` in this process."""

    @staticmethod
    def map(function, items):
        """Apply ``function`` to each item, in order."""
        return map(function, items)


def default_workers():
    """Workers of a fit: every core, at most 8."""
    return min(os.cpu_count() or 1, 8)


@contextlib.contextmanager
def fork_pool(workers):
    """Yield a pool of ``workers`` forked processes that never collect the parent's garbage.

    A reference cycle the parent left behind (an rclpy node of an earlier test or tool in the
    same process) collected in a fork runs its DDS finalizers there and segfaults the worker;
    so the parent collects first and freezes what is left out of every later collection until
    the pool is closed. Yields a :class:`SerialPool` when forking is unavailable or
    ``workers`` is 1.
    """
    if workers <= 1 or 'fork' not in multiprocessing.get_all_start_methods():
        yield SerialPool()
        return
    gc.collect()
    gc.freeze()
    try:
        with ProcessPoolExecutor(max_workers=workers,
                                 mp_context=multiprocessing.get_context('fork')) as pool:
            yield pool
    finally:
        gc.unfreeze()
