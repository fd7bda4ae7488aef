"""Timers on the steady clock for the nodes' own machinery (control loop, diagnostics, markers).

A node timer runs on ROS time by default: with ``use_sim_time`` and no ``/clock`` (a simulator
not started yet, a bag not playing) it never fires, and a goal then hangs until its service
deadline. The control loop and the periodic reports measure real elapsed time (monotonic
clocks throughout), so their timers run on the steady clock; message stamps stay ROS time.
"""
from rclpy.clock import Clock, ClockType


def steady_timer(node, period, callback, callback_group=None):
    """Create a timer of ``node`` on the steady clock; ``period`` in s."""
    clock = getattr(node, '_steady_clock', None)
    if clock is None:
        clock = node._steady_clock = Clock(clock_type=ClockType.STEADY_TIME)
    return node.create_timer(period, callback, callback_group=callback_group, clock=clock)
