"""Start nodes with the executor each needs, and stop them cleanly on Ctrl-C (Jazzy and Kilted).

Each node class names the executor it wants in ``EXECUTOR``: ``'single'`` or ``'multi'`` (several
threads, for nodes whose service callbacks wait on topics). Several nodes in one process (bringup)
each get their own executor and thread, so a busy node never delays another.

rclpy's experimental ``EventsExecutor`` (Kilted) is not used: in rclpy 9.1 its ``spin()``
busy-loops at 100 % CPU and does not return on SIGINT.
"""
import signal
import sys
import threading

import rclpy
from rclpy.executors import (
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.signals import SignalHandlerOptions

#: Threads of a multi-threaded executor: waiting service calls each hold one.
MULTI_THREADS = 8


def make_executor(kind, context=None):
    """Return a new executor of ``kind`` ('single' or 'multi')."""
    if kind == 'multi':
        return MultiThreadedExecutor(num_threads=MULTI_THREADS, context=context)
    return SingleThreadedExecutor(context=context)


def run_nodes(factories, args=None, context=None):
    """Create the nodes, spin them until SIGINT or SIGTERM and clean up; return the exit code.

    Every executor spins in a thread of its own; the main thread only waits for a signal. The
    signals are handled here rather than by rclpy so that the executors are stopped while the
    context is still valid: callbacks in flight finish normally instead of failing to publish.

    :param factories: callables returning a Node (usually the node classes)
    :param args: command-line arguments for ``rclpy.init`` (None: ``sys.argv``)
    :returns: 0 after a normal shutdown, 1 if a node could not start or failed
    """
    rclpy.init(args=args, context=context, signal_handler_options=SignalHandlerOptions.NO)
    context = context or rclpy.get_default_context()
    stop = threading.Event()
    previous = {signum: signal.signal(signum, lambda *_: stop.set())
                for signum in (signal.SIGINT, signal.SIGTERM)}
    nodes, executors, threads, failures = [], [], [], []
    try:
        try:
            for factory in factories:
                nodes.append(factory())
        except Exception as error:  # bad robot file or parameter: report it, no traceback
            print('continuum_statics: cannot start: %s' % error, file=sys.stderr)
            return 1
        for node in nodes:
            executor = make_executor(getattr(node, 'EXECUTOR', 'single'), context)
            executor.add_node(node)
            executors.append(executor)
            thread = threading.Thread(target=_spin, args=(executor, context, failures),
                                      name='spin_' + node.get_name(), daemon=True)
            thread.start()
            threads.append(thread)
        while not stop.wait(0.1):
            if not context.ok() or not all(thread.is_alive() for thread in threads):
                break
    finally:
        for node in nodes:
            release = getattr(node, 'release_waiters', None)
            if release is not None:
                release()
        for executor in executors:
            executor.shutdown(timeout_sec=2.0)
        for thread in threads:
            thread.join(timeout=2.0)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    for error in failures:
        print('continuum_statics: a node stopped: %r' % error, file=sys.stderr)
    return 1 if failures else 0


def _spin(executor, context, failures):
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as error:
        if context.ok():
            failures.append(error)
