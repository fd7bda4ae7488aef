"""``python -m continuum_statics teleop``: drive the tip from the keyboard (``tip_twist``).

Keys (as teleop_twist_keyboard): ``w``/``s`` +x/-x, ``a``/``d`` +y/-y, ``r``/``f`` +z/-z,
``+``/``-`` faster/slower, space stops, ``q`` quits. A key sets the tip velocity, which is
published at ``--rate`` Hz as geometry_msgs/TwistStamped in the robot's base frame until another
key changes it; the controller's dead-man (``twist_timeout``) stops the robot when this tool
stops publishing. Needs a terminal (stdin a TTY).
"""
import argparse
import os
import select
import sys
import termios
import tty

import numpy as np

KEYS = {'w': (1, 0, 0), 's': (-1, 0, 0), 'a': (0, 1, 0), 'd': (0, -1, 0), 'r': (0, 0, 1),
        'f': (0, 0, -1)}
HELP = ('tip teleoperation: w/s +x/-x, a/d +y/-y, r/f +z/-z, +/- speed, space stop, q quit')


def velocity_for(key, direction, speed):
    """Return the new (direction, speed) after ``key``; None direction on quit."""
    if key in KEYS:
        return np.array(KEYS[key], dtype=float), speed
    if key == ' ':
        return np.zeros(3), speed
    if key == '+':
        return direction, speed * 1.5
    if key == '-':
        return direction, speed / 1.5
    if key in ('q', '\x03'):
        return None, speed
    return direction, speed


def main(argv=None):
    """Run the keyboard teleoperation; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m continuum_statics teleop',
                                     description=HELP)
    parser.add_argument('--namespace', default='continuum', help='robot namespace')
    parser.add_argument('--frame', default='base_link', help="the robot's base frame")
    parser.add_argument('--speed', type=float, default=0.005, help='tip speed, m/s')
    parser.add_argument('--rate', type=float, default=20.0, help='publish rate, Hz')
    options = parser.parse_args(argv)
    if not os.isatty(sys.stdin.fileno()):
        print('teleop: stdin is not a terminal', file=sys.stderr)
        return 2
    from geometry_msgs.msg import TwistStamped
    import rclpy

    from continuum_statics.nodes.qos import COMMAND_QOS

    rclpy.init()
    node = rclpy.create_node('tip_teleop', namespace=options.namespace)
    publisher = node.create_publisher(TwistStamped, 'tip_twist', COMMAND_QOS)
    direction, speed = np.zeros(3), options.speed
    saved = termios.tcgetattr(sys.stdin)
    print(HELP, flush=True)
    try:
        tty.setcbreak(sys.stdin.fileno())
        period = 1.0 / options.rate
        while True:
            ready, _, _ = select.select([sys.stdin], [], [], period)
            if ready:
                direction, speed = velocity_for(sys.stdin.read(1), direction, speed)
                if direction is None:
                    break
                print('\rtip velocity %s mm/s   ' % np.round(direction * speed * 1e3, 2),
                      end='', flush=True)
            msg = TwistStamped()
            msg.header.frame_id = options.frame
            msg.header.stamp = node.get_clock().now().to_msg()
            msg.twist.linear.x, msg.twist.linear.y, msg.twist.linear.z = (
                float(v) for v in direction * speed)
            publisher.publish(msg)
    finally:
        termios.tcsetattr(sys.stdin, termios.TCSADRAIN, saved)
        print()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
