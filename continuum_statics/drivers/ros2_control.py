"""Bridge to hardware that already has a ros2_control driver (no rclpy in this module).

Commands go out as std_msgs/Float64MultiArray on ``<controller>/commands`` (a
``forward_command_controller`` / ``position_controllers/JointGroupPositionController`` of the
``joints``, in that order), readings come from ``joint_states`` (joint_state_broadcaster). The
node owns the topics: it calls :meth:`attach_ros` with a function that publishes one command and
feeds every JointState to :meth:`on_joint_state`. Joint positions are spool angles in rad by
default (``counts_per_rev`` = 2 pi), converted with the shared spool formula; joint efforts (N m)
become tensions.

The joint states are the connection: until every joint has been heard, or when they stop for
``state_timeout`` s, ``start``/``read`` raise :class:`ConnectionLost` naming the silent joints.
"""
import math
import threading
import time

import numpy as np

from continuum_statics.drivers.base import (
    OK,
    BackendOption,
    BackendStatus,
    CableReading,
    ConnectionLost,
    RosTopicBackend,
)
from continuum_statics.drivers.spool import Spool, per_cable


class Ros2ControlCableBackend(RosTopicBackend):
    """Cable spools behind a ros2_control forward position controller."""

    name = 'ros2_control'
    zero_option = 'zero_positions'
    options_spec = (
        BackendOption('controller', 'forward_position_controller', 'controller name; '
                      'commands go to <controller>/commands', read_only=True),
        BackendOption('joints', ['spool_0', 'spool_1', 'spool_2', 'spool_3'],
                      "joint per cable, robot-file order (the controller's joint order)",
                      read_only=True),
        BackendOption('joint_states_topic', 'joint_states', 'JointState topic of the joints',
                      read_only=True),
        BackendOption('spool_radius', 0.01, 'spool radius, m', 1e-4, 1.0, read_only=True),
        BackendOption('directions', [1], '+1/-1 per cable (one value: all); +1 = rising '
                      'position lengthens the cable', read_only=True),
        BackendOption('zero_positions', [0.0], 'joint position at the straight pose per '
                      'cable (one value: all; home_file overrides)', read_only=True),
        BackendOption('counts_per_rev', 2.0 * math.pi, 'joint position units per spool '
                      'revolution (2 pi: rad)', 1e-9, 1e12, read_only=True),
        BackendOption('gear_ratio', 1.0, 'joint revolutions per spool revolution', 1e-6, 1e6,
                      read_only=True),
        BackendOption('state_timeout', 0.5, 'joint_states older than this: connection lost, s',
                      0.01, 60.0),
    )

    def __init__(self, cable_names, length_limits, initial_lengths, **options):
        super().__init__(cable_names, length_limits, initial_lengths, **options)
        merged = self.options
        n = len(self.cable_names)
        self.joints = [str(j) for j in merged['joints']]
        if len(self.joints) != n or len(set(self.joints)) != n or '' in self.joints:
            raise ValueError('joints must be %d distinct joint names (one per cable), got %s'
                             % (n, self.joints))
        self.spool = Spool.from_options(
            self.initial_lengths, merged['directions'],
            per_cable('zero_positions', merged['zero_positions'], n), merged['spool_radius'],
            float(merged['counts_per_rev']), float(merged['gear_ratio']))
        controller = str(merged['controller']).strip('/')
        if not controller:
            raise ValueError('controller must be a controller name')
        self.command_topic = controller + '/commands'
        self.state_topic = str(merged['joint_states_topic'])
        self.state_timeout = float(merged['state_timeout'])
        self._send = None
        self._lock = threading.Lock()
        self._positions = np.full(n, np.nan)
        self._velocities = np.full(n, np.nan)
        self._efforts = np.full(n, np.nan)
        self._heard = np.full(n, -math.inf)  # monotonic time each joint was last heard
        self._last_good = None

    def attach_ros(self, send):
        """Take the node's publisher: ``send(positions)`` publishes one command."""
        self._send = send

    def on_joint_state(self, names, positions, velocities, efforts, now):
        """Store the joints of one JointState (others ignored); ``now`` is monotonic s."""
        index = {name: k for k, name in enumerate(names)}
        with self._lock:
            for j, joint in enumerate(self.joints):
                k = index.get(joint)
                if k is None or k >= len(positions) or not math.isfinite(positions[k]):
                    continue
                self._positions[j] = positions[k]
                self._velocities[j] = velocities[k] if k < len(velocities) else math.nan
                self._efforts[j] = efforts[k] if k < len(efforts) else math.nan
                self._heard[j] = now

    def _check(self, now):
        if self._send is None:
            raise ConnectionLost('ros2_control: no ROS node attached')
        silent = [j for j, heard in enumerate(self._heard)
                  if now - heard > self.state_timeout]
        if silent:
            raise ConnectionLost('no %s for joint(s) %s in the last %g s' % (
                self.state_topic, ', '.join('%s (%s)' % (self.joints[j], self.cable_names[j])
                                            for j in silent), self.state_timeout))

    def start(self, now):
        """Succeed once every joint has been heard recently (the controller is up)."""
        with self._lock:
            self._check(time.monotonic())

    def command(self, target_lengths, now):
        """Publish the joint positions for ``target_lengths`` (m)."""
        if self._send is None:
            raise ConnectionLost('ros2_control: no ROS node attached')
        self._send(self.spool.positions(target_lengths))

    def hold(self, now):
        """Command the joint positions last heard."""
        with self._lock:
            positions = self._positions.copy()
        if self._send is not None and np.all(np.isfinite(positions)):
            self._send(positions)

    def read(self, now):
        """Lengths (and speeds, tensions where the joints report them) from joint_states."""
        with self._lock:
            self._check(time.monotonic())
            positions = self._positions.copy()
            velocities = self._velocities.copy()
            efforts = self._efforts.copy()
        self._last_good = positions
        speeds = self.spool.speeds(velocities) if np.all(np.isfinite(velocities)) else None
        tensions = self.spool.tensions(efforts * self.spool.gear_ratio) \
            if np.all(np.isfinite(efforts)) else None
        return CableReading(lengths=self.spool.lengths(positions), velocities=speeds,
                            tensions=tensions)

    def status(self):
        """OK while the joints are heard (a silence is a ConnectionLost from ``read``)."""
        values = {'command_topic': self.command_topic, 'state_topic': self.state_topic}
        if self._last_good is not None:
            values.update({'position_%s' % joint: '%.6g' % p
                           for joint, p in zip(self.joints, self._last_good)})
        return BackendStatus(OK, 'ros2_control: %d joints via %s' % (
            len(self.joints), self.command_topic), values)

    def set_home(self):
        """Make the joint positions last heard the straight pose; return them."""
        if self._last_good is None:
            raise ValueError('no joint_states read yet')
        zeros = [float(p) for p in self._last_good]
        self.spool = self.spool.with_zeros(zeros)
        return zeros

    def set_option(self, key, value):
        """``state_timeout`` changes at run time."""
        if key == 'state_timeout':
            self.state_timeout = float(value)
            self.options[key] = value
        else:
            super().set_option(key, value)
