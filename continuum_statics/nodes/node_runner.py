"""Start nodes with the executor each needs, and stop them cleanly on Ctrl-C (Jazzy and Kilted).

Each node class names the executor it wants in ``EXECUTOR``: ``'single'`` or ``'multi'`` (several
threads, for nodes whose service callbacks wait on topics), one of the :class:`RunnerHooks` it
inherits (a plain rclpy node gets their defaults). Several nodes in one process (bringup)
each get their own executor and thread, so a busy node never delays another.

rclpy's experimental ``EventsExecutor`` (Kilted) is not used: in rclpy 9.1 its ``spin()``
busy-loops at 100 % CPU and does not return on SIGINT.
"""
import os
import signal
import sys
import threading
import time

import rclpy
from rclpy.executors import (
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.signals import SignalHandlerOptions

from continuum_statics.config_paths import share_dir

#: Threads of a multi-threaded executor: waiting service calls each hold one.
MULTI_THREADS = 8
#: How often a node whose callback raised is spun again before it is given up, per process.
#: A callback that fails on every message would otherwise restart forever; five is enough for
#: rare failures and stops a node that fails on each input within a second.
MAX_RESTARTS = 5
#: At shutdown, how long the executors keep running after the goals were released so that
#: every active goal (action, service) sends its result, s.
SHUTDOWN_GRACE = 3.0
#: A goal's result is sent just after its callback returns: the time given to that, s.
RESULT_SEND_TIME = 0.2


class RunnerHooks:
    """What :func:`run_nodes` asks of a node, declared once with its defaults.

    The package's nodes inherit it and override what they use; any other rclpy node runs with
    these defaults (a single-threaded executor, nothing to count or release).
    """

    #: The executor the node needs: ``'single'`` or ``'multi'``.
    EXECUTOR = 'single'

    def on_node_failure(self, text):
        """Count a callback of this node that raised (``text`` says which) on diagnostics."""

    def release_waiters(self):
        """At shutdown: end every goal that waits, so that each gets its result."""

    def goals_in_flight(self):
        """Return how many goals still have a result to send."""
        return 0


_DEFAULT_HOOKS = RunnerHooks()


def hooks(node):
    """Return the :class:`RunnerHooks` of ``node`` (the defaults for a plain rclpy node)."""
    return node if isinstance(node, RunnerHooks) else _DEFAULT_HOOKS


def make_executor(kind, context=None):
    """Return a new executor of ``kind`` ('single' or 'multi')."""
    if kind == 'multi':
        return MultiThreadedExecutor(num_threads=MULTI_THREADS, context=context)
    return SingleThreadedExecutor(context=context)


def use_fast_discovery_profile():
    """Point Fast DDS at the shipped quick-discovery profile unless the user chose one.

    Every node command, not only bringup: a node restarted alone found its peers 0.9-2.0 s
    later without it.
    """
    if 'FASTDDS_DEFAULT_PROFILES_FILE' not in os.environ:
        profile = share_dir() / 'config' / 'fastdds_fast_discovery.xml'
        if profile.is_file():
            os.environ['FASTDDS_DEFAULT_PROFILES_FILE'] = str(profile)


def run_nodes(factories, args=None, context=None):
    """Create the nodes, spin them until SIGINT or SIGTERM and clean up; return the exit code.

    Every executor spins in a thread of its own; the main thread only waits for a signal. The
    signals are handled here rather than by rclpy so that the executors are stopped while the
    context is still valid: callbacks in flight finish normally instead of failing to publish.

    :param factories: callables returning a Node (usually the node classes)
    :param args: command-line arguments for ``rclpy.init`` (None: ``sys.argv``)
    :returns: 0 after a normal shutdown, 1 if a node could not start or failed
    """
    use_fast_discovery_profile()
    rclpy.init(args=args, context=context, signal_handler_options=SignalHandlerOptions.NO)
    context = context or rclpy.get_default_context()
    stop = threading.Event()
    previous = {signum: signal.signal(signum, lambda *_: stop.set())
                for signum in (signal.SIGINT, signal.SIGTERM)}
    nodes, executors, threads, failures = [], [], [], []
    restarts = {}
    try:
        try:
            for factory in factories:
                nodes.append(factory())
        except Exception as error:  # bad robot file or parameter: report it, no traceback
            print('continuum_statics: cannot start: %s' % error, file=sys.stderr)
            return 1
        for node in nodes:
            executor = make_executor(hooks(node).EXECUTOR, context)
            executor.add_node(node)
            executors.append(executor)
            thread = threading.Thread(target=_spin, args=(executor, context, failures,
                                                          node.get_name()),
                                      name='spin_' + node.get_name(), daemon=True)
            thread.start()
            threads.append(thread)
        while not stop.wait(0.1) and context.ok():
            for index, thread in enumerate(threads):
                if not thread.is_alive() and restarts.get(index, 0) <= MAX_RESTARTS:
                    threads[index] = _restart(nodes[index], executors[index], context,
                                              failures, restarts, index)
    finally:
        _release_goals(nodes, threads)
        for executor in executors:
            executor.shutdown(timeout_sec=2.0)
        for thread in threads:
            thread.join(timeout=2.0)
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    return 1 if failures else 0


def _restart(node, executor, context, failures, restarts, index):
    """Report the failure of a node's executor and spin it again (or say why not)."""
    name = node.get_name()
    error = next((error for who, error in reversed(failures) if who == name),
                 'its executor stopped')
    restarts[index] = restarts.get(index, 0) + 1
    if restarts[index] > MAX_RESTARTS:
        text = ('continuum_statics: node %r failed %d times (last: %r): not restarted; the '
                'other nodes go on' % (name, MAX_RESTARTS + 1, error))
        thread = threading.Thread(target=lambda: None)
    else:
        text = ('continuum_statics: a callback of node %r failed: %r; its state is kept and '
                'it spins again (restart %d of %d)' % (name, error, restarts[index],
                                                      MAX_RESTARTS))
        thread = threading.Thread(target=_spin, args=(executor, context, failures, name),
                                  name='spin_' + name, daemon=True)
    print(text, file=sys.stderr)
    node.get_logger().error(text)
    hooks(node).on_node_failure(text)  # counted on the node's diagnostics
    thread.start()
    return thread


def _release_goals(nodes, threads):
    """End every active goal and let the executors send their results (shutdown)."""
    for node in nodes:
        hooks(node).release_waiters()
    deadline = time.monotonic() + SHUTDOWN_GRACE
    while time.monotonic() < deadline and any(
            hooks(node).goals_in_flight() for node, thread in zip(nodes, threads)
            if thread.is_alive()):
        time.sleep(0.01)
    time.sleep(RESULT_SEND_TIME)


def _spin(executor, context, failures, name):
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as error:
        if context.ok():
            failures.append((name, error))
