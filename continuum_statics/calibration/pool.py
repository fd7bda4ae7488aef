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
import pickle


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


class Background:
    """``function(*args)`` run in one forked process while this one goes on; :meth:`result`.

    What the calibration needs but nothing waits for (the robot file's own errors on the run,
    a whole serial replay) fills the core the fit's serial steps leave idle. Runs at
    :meth:`result` in this process where forking is unavailable or ``workers`` is 1. The
    fork takes the garbage precautions of :func:`fork_pool`.
    """

    def __init__(self, function, *args, workers=2):
        self.call, self.process = (function, args), None
        if workers <= 1 or 'fork' not in multiprocessing.get_all_start_methods():
            return
        context = multiprocessing.get_context('fork')
        self.receiver, sender = context.Pipe(duplex=False)
        gc.collect()
        gc.freeze()
        try:
            self.process = context.Process(target=_send_result, args=(sender, function, args),
                                           daemon=True)
            self.process.start()
        finally:
            gc.unfreeze()
        sender.close()

    def result(self):
        """Return the function's value (its exception raised here)."""
        if self.process is None:
            function, args = self.call
            return function(*args)
        try:
            ok, value = self.receiver.recv()
        except EOFError:  # the process died without an answer: do it here
            ok, value = True, self.call[0](*self.call[1])
        finally:
            self.receiver.close()
            self.process.join()
        self.process = None
        if not ok:
            raise value
        return value

    def close(self):
        """End the process if its result was not taken (the calibration stopped early)."""
        if self.process is not None:
            self.process.terminate()
            self.process.join()
            self.receiver.close()
            self.process = None


def _send_result(sender, function, args):
    try:
        message = (True, function(*args))
    except Exception as error:  # noqa: BLE001 (raised again in the parent)
        try:  # an exception whose __init__ takes other arguments does not unpickle
            pickle.loads(pickle.dumps(error))
        except Exception:  # noqa: BLE001
            error = RuntimeError(repr(error))
        message = (False, error)
    sender.send(message)
    sender.close()
