"""Shared helpers of the node tests: a private rclpy context, deadlines, subprocess control."""
import math
import threading
import time
import uuid

import numpy as np
import rclpy
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from continuum_statics.nodes.node_runner import make_executor
from continuum_statics.tools.processes import stop as stop_process  # noqa: F401 (re-export)

#: What late joiners use for the latched outputs (backbone, tip_pose).
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)


def wait_until(predicate, timeout, what):
    """Poll ``predicate`` every 10 ms until it is true; fail with ``what`` after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError('timed out after %g s waiting for %s' % (timeout, what))
        time.sleep(0.01)


def wait_matched(publisher, node, timeout=10.0):
    """Wait until ``publisher`` and the subscription of ``node`` on its topic see each other.

    A reliable message sent before the reader side has matched is resent only at the next
    heartbeat (seconds), so tests wait for both sides.
    """
    topic = publisher.topic_name
    subscriptions = [s for s in node.subscriptions if s.topic_name == topic]
    assert subscriptions, '%s has no subscription on %s' % (node.get_name(), topic)

    def matched():
        counts = [getattr(s, 'get_publisher_count', lambda: node.count_publishers(topic))()
                  for s in subscriptions]
        return publisher.get_subscription_count() >= 1 and min(counts) >= 1

    wait_until(matched, timeout, 'a match on %s' % topic)


def publish_until(publisher, msg, predicate, timeout, what, period=0.05):
    """Publish ``msg`` every ``period`` s until ``predicate`` holds (discovery-proof)."""
    deadline = time.monotonic() + timeout
    while True:
        publisher.publish(msg)
        end = time.monotonic() + period
        while time.monotonic() < end:
            if predicate():
                return
            time.sleep(0.005)
        if time.monotonic() > deadline:
            raise AssertionError('timed out after %g s waiting for %s' % (timeout, what))


class Harness:
    """A private context; every node spins in an executor and thread of its own, as in bringup.

    Every test gets its own namespace, so nodes of different tests never talk to each other.
    """

    def __init__(self):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.namespace = '/t' + uuid.uuid4().hex[:10]
        self.nodes = []
        self._spinning = []  # (executor, thread)
        #: what raised in a node while the test ran (a callback, the intake thread): the test
        #: fails at close with it (before, a raising callback ended its node's executor in
        #: silence, and the test timed out or passed without that node)
        self.failures = []
        self._closing = False

    def _spin(self, node, kind):
        executor = make_executor(kind, self.context)
        executor.add_node(node)

        def spin():
            try:
                executor.spin()
            except Exception as error:  # the context is shut down at the end of the test
                if not self._closing and self.context.ok():
                    self.failures.append('%s: %r' % (node.get_name(), error))

        thread = threading.Thread(target=spin, daemon=True)
        thread.start()
        self._spinning.append((executor, thread))

    def add(self, node_class, **overrides):
        """Create a node of ``node_class`` in the test namespace with parameter overrides."""
        overrides.setdefault('diagnostics_rate', 20.0)  # quick diagnostics: short tests
        if node_class.__name__ == 'TipControllerNode':
            # every node of a harness shares one process (one GIL) with the test: under a CPU
            # hog its driver or statics went 0.51-0.54 s without publishing and goals failed
            # "no tip_pose for 0.54 s" (max_state_age 0.5 s); separate processes, as in use and
            # in the cross-process tests, keep the default
            overrides.setdefault('max_state_age', 2.0)
        parameters = [Parameter(name, value=value) for name, value in overrides.items()]
        node = node_class(namespace=self.namespace, context=self.context,
                          parameter_overrides=parameters)
        counted = getattr(node, 'on_node_failure', None)
        if counted is not None:  # what a node counts itself (its intake thread's failures)
            def on_node_failure(text, node=node, counted=counted):
                self.failures.append('%s: %s' % (node.get_name(), text))
                counted(text)
            node.on_node_failure = on_node_failure
        self.nodes.append(node)
        self._spin(node, getattr(node, 'EXECUTOR', 'single'))
        return node

    def client(self, name='test_client'):
        """Return a plain node for the test's own publishers, subscriptions and clients."""
        node = rclpy.create_node(name, namespace=self.namespace, context=self.context)
        self.nodes.append(node)
        self._spin(node, 'single')
        return node

    def close(self, check=True):
        """Stop spinning, destroy the nodes and shut the context down.

        Then raise AssertionError naming what raised in a node during the test (``check``).
        """
        self._closing = True
        for node in self.nodes:
            release = getattr(node, 'release_waiters', None)
            if release is not None:
                release()
        # Nodes out first, so no new work starts; rclpy's shutdown() does not wait for the work
        # in flight, which would then trigger the executor's destroyed guard condition.
        for (executor, _), node in zip(self._spinning, self.nodes):
            executor.remove_node(node)
        time.sleep(0.05)
        for executor, thread in self._spinning:
            executor.shutdown(timeout_sec=2.0)
            thread.join(timeout=2.0)
        for node in self.nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)
        if check and self.failures:
            raise AssertionError('raised in a node during the test: %s' % '; '.join(
                self.failures))


class Collector:
    """Keeps every message of a subscription (thread-safe enough for appends and reads)."""

    def __init__(self, node, msg_type, topic, qos):
        self.messages = []
        self.subscription = node.create_subscription(msg_type, topic, self.messages.append, qos)

    def __len__(self):
        return len(self.messages)

    @property
    def last(self):
        """The newest message (None before the first)."""
        return self.messages[-1] if self.messages else None


def diagnostic_values(collector, name_suffix):
    """Key/values of the newest status whose name ends with ``name_suffix`` (or None)."""
    for array in reversed(collector.messages):
        for status in array.status:
            if status.name.endswith(name_suffix):
                return {kv.key: kv.value for kv in status.values}, status
    return None


def call(client, request, timeout):
    """Call a service and wait for the answer (the executor spins in the background)."""
    future = client.call_async(request)
    wait_until(future.done, timeout, 'an answer from %s' % client.srv_name)
    return future.result()


def goal_request(frame_id, goal, tolerance):
    """Return a tip_goal request (nav_msgs/GetPlan) for ``goal`` (m) in ``frame_id``."""
    from nav_msgs.srv import GetPlan

    request = GetPlan.Request(tolerance=float(tolerance))
    request.goal.header.frame_id = frame_id
    p = request.goal.pose.position
    p.x, p.y, p.z = (float(v) for v in goal)
    return request


def all_finite_path(path):
    """Return True if every number of a Path is finite."""
    return all(math.isfinite(v) for p in path.poses for v in (
        p.pose.position.x, p.pose.position.y, p.pose.position.z, p.pose.orientation.x,
        p.pose.orientation.y, p.pose.orientation.z, p.pose.orientation.w))


def pose_xyz(pose):
    """Position of a Pose as an array."""
    return np.array([pose.position.x, pose.position.y, pose.position.z])


def client_node(name, namespace):
    """Return (context, executor, node): a client node in a context of its own, spun by the test.

    For tests whose nodes run in other processes; end with ``executor.shutdown()``,
    ``node.destroy_node()`` and ``rclpy.try_shutdown(context=context)``.
    """
    from rclpy.executors import SingleThreadedExecutor

    context = rclpy.Context()
    rclpy.init(context=context)
    executor = SingleThreadedExecutor(context=context)
    node = rclpy.create_node(name, namespace=namespace, context=context)
    executor.add_node(node)
    return context, executor, node
