"""A broken ROS install must fail loudly: one message between two separate processes."""
import os
import subprocess
import sys
import time

import pytest

rclpy = pytest.importorskip('rclpy')
from std_msgs.msg import String  # noqa: E402

pytestmark = pytest.mark.ros  # starts DDS or a process

PUBLISHER = """
import sys, rclpy
from rclpy.node import Node
from std_msgs.msg import String

rclpy.init()
node = Node('smoke_publisher')
pub = node.create_publisher(String, 'smoke_chatter', 10)
msg = String(data='hello from ' + str(__import__('os').getpid()))
timer = node.create_timer(0.05, lambda: pub.publish(msg))
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
"""


def test_message_crosses_processes():
    context = rclpy.Context()
    rclpy.init(context=context)
    proc = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=os.environ.copy())
    try:
        node = rclpy.create_node('smoke_listener', context=context)
        received = []
        node.create_subscription(String, 'smoke_chatter', lambda m: received.append(m.data), 10)
        executor = rclpy.executors.SingleThreadedExecutor(context=context)
        executor.add_node(node)
        deadline = time.monotonic() + 20.0
        while not received and time.monotonic() < deadline and proc.poll() is None:
            executor.spin_once(timeout_sec=0.1)
        assert received, 'no message from the publisher process within 20 s'
        assert received[0] == 'hello from %d' % proc.pid
    finally:
        proc.terminate()
        proc.wait(timeout=10)
        rclpy.shutdown(context=context)
