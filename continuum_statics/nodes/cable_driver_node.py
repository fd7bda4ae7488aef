"""cable_driver: bridge between ``cable_commands`` and the cable actuators (simulated by default).

Subscribes ``cable_commands`` (sensor_msgs/JointState, target cable lengths in m by name) and
publishes ``cable_states`` (measured lengths in m, speeds in m/s, tensions in N where the backend
knows them) at ``publish_rate``. The actuators sit behind a :class:`~continuum_statics.drivers.
CableBackend`, chosen with the read-only ``backend`` parameter.

Bad commands (unknown or repeated names, NaN, sizes that do not match) are dropped with a throttled
warning and counted on diagnostics; lengths outside the robot's limits are clamped with a warning.
When no command arrives for ``command_timeout`` s the watchdog makes the backend hold position.
"""
import sys
import threading
import time

import numpy as np
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import JointState

from continuum_statics.drivers import backend_class
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.dedicated_intake import PeriodicThread
from continuum_statics.nodes.node_params import (
    ParameterTable,
    ParamSpec,
    diagnostics_rate_spec,
    load_robot_file,
    robot_file_spec,
)
from continuum_statics.nodes.ros_conversions import cable_index, joint_positions, joint_state

#: Commands and goals: reliable, depth 10 (ARCHITECTURE.md, ROS interfaces).
COMMAND_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
THROTTLE_S = 2.0


def _check_backend(value):
    try:
        backend_class(value)
    except ValueError as error:
        return str(error)
    return None


class CableDriverNode(Node):
    """Cable actuator bridge: commands in, measured cable lengths out."""

    EXECUTOR = 'single'

    def __init__(self, node_name='cable_driver', **kwargs):
        super().__init__(node_name, **kwargs)
        specs = [
            robot_file_spec('cable names, length limits'),
            diagnostics_rate_spec(),
            ParamSpec('backend', 'sim', 'cable actuator backend: sim, an entry point of group '
                      'continuum_statics.cable_backends, or module:Class', read_only=True,
                      check=_check_backend),
            ParamSpec('publish_rate', 200.0, 'cable_states publish rate, Hz', 1.0, 2000.0),
            ParamSpec('command_timeout', 0.5, 'hold position when no command arrives for this '
                      'long, s (0: never)', 0.0, 3600.0),
        ]
        self._params = ParameterTable(self, specs)
        self.robot = load_robot_file(self._params['robot_file'])
        self._backend_cls = backend_class(self._params['backend'])
        prefix = self._backend_cls.name + '.'
        option_specs = [ParamSpec(prefix + o.name, o.default, o.description, o.low, o.high,
                                  o.read_only) for o in self._backend_cls.options_spec]
        # Declared after the backend is known; one table per group keeps validation simple.
        self._options = ParameterTable(self, option_specs)
        options = {spec.name[len(prefix):]: self._options[spec.name] for spec in option_specs}
        self.cable_names = tuple(self.robot.cable_names)
        self._limits = np.asarray(self.robot.cable_length_limits, dtype=float)
        self.backend = self._backend_cls(self.cable_names, self._limits,
                                         self.robot.straight_cable_lengths, **options)
        self.backend.start(time.monotonic())

        self._targets = np.array(self.robot.straight_cable_lengths, dtype=float)
        self._last_reading = None
        self._last_command_time = None
        self._holding = True
        self._problems = diag.Problems()
        self._clamped = 0
        self._commands = 0
        self._backend_error = ''
        self._rate = diag.RateMeter()
        self._state_msg = JointState()
        self._lock = threading.Lock()  # backend calls come from the executor and the loop

        self._publisher = self.create_publisher(JointState, 'cable_states',
                                                qos_profile_sensor_data)
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        self.create_subscription(JointState, 'cable_commands', self._on_command, COMMAND_QOS)
        # cable_states from a thread of its own: steadier and ~10x cheaper than a 200 Hz timer.
        self._loop = PeriodicThread(self, self._params['publish_rate'], self._on_timer,
                                    'cable_driver_publish')
        self.create_timer(1.0 / self._params['diagnostics_rate'], self._publish_diagnostics)
        # Applied only after everything above exists.
        self._params.on_change = self._on_parameter_change
        self._options.on_change = self._on_option_change
        self._loop.start()
        self.get_logger().info('cable_driver: backend %s, %d cables (%s), %g Hz' % (
            self._backend_cls.name, len(self.cable_names), ', '.join(self.cable_names),
            self._params['publish_rate']))

    def _on_parameter_change(self, name, value):
        if name == 'publish_rate':
            self._loop.rate = value

    def _on_option_change(self, name, value):
        with self._lock:
            self.backend.set_option(name.split('.', 1)[1], value)

    def _reject(self, kind, reason):
        self._problems.add(kind, reason)
        self.get_logger().warning('dropped %s: %s' % (kind, reason),
                                  throttle_duration_sec=THROTTLE_S)

    def _on_command(self, msg):
        try:
            index = cable_index(msg.name, self.cable_names, require_all=False)
            lengths = joint_positions(msg, len(index))
        except ValueError as error:
            self._reject('cable_commands', error)
            return
        low, high = self._limits[index, 0], self._limits[index, 1]
        clamped = np.clip(lengths, low, high)
        if np.any(clamped != lengths):
            self._clamped += 1
            bad = np.flatnonzero(clamped != lengths)
            self.get_logger().warning(
                'clamped cable command(s) to the length limits: %s' % ', '.join(
                    '%s %.4f m -> %.4f m' % (msg.name[i], lengths[i], clamped[i]) for i in bad),
                throttle_duration_sec=THROTTLE_S)
        with self._lock:
            now = time.monotonic()
            targets = self._targets.copy()  # stored only once the backend took it
            if self._holding and self._last_reading is not None:
                # After a hold, cables not named in this command stay where they are.
                targets = self._last_reading.copy()
            targets[index] = clamped
            try:
                self.backend.command(targets, now)
            except Exception as error:  # a real backend may fail; the node stays up
                self._backend_failure('command', error)
                return
            self._targets = targets
            self._commands += 1
            self._last_command_time = now
            self._holding = False

    def _backend_failure(self, what, error):
        self._backend_error = '%s failed: %s' % (what, error)
        self.get_logger().error('backend %s' % self._backend_error,
                                throttle_duration_sec=THROTTLE_S)

    def _on_timer(self):
        now = time.monotonic()
        timeout = self._params['command_timeout']
        try:
            with self._lock:
                if (not self._holding and timeout > 0.0 and self._last_command_time is not None
                        and now - self._last_command_time > timeout):
                    self.backend.hold(now)
                    self._holding = True
                    self.get_logger().info('no cable command for %.3g s: holding position'
                                           % timeout)
                reading = self.backend.read(now)
            joint_state(self.cable_names, reading.lengths, self.get_clock().now().to_msg(),
                        reading.velocities, reading.tensions, msg=self._state_msg)
        except Exception as error:  # ValueError on NaN from a backend, or a hardware error
            self._backend_failure('read', error)
            return
        self._backend_error = ''
        self._last_reading = np.asarray(reading.lengths, dtype=float)
        self._publisher.publish(self._state_msg)
        self._rate.tick()

    def _publish_diagnostics(self):
        with self._lock:
            status = self.backend.status()
        level, message = status.level, status.message
        if self._backend_error:
            level, message = diag.ERROR, self._backend_error
        elif self._problems.recent(2.0):
            level, message = max(level, diag.WARN), 'rejected ' + self._problems.last_reason
        elif self._holding:
            message = '%s; holding position (no command)' % message
        values = {
            'backend': self._backend_cls.name,
            'publish_rate_hz': self._rate.report(),
            'commands_accepted': self._commands,
            'commands_clamped': self._clamped,
            'holding': self._holding,
        }
        values.update(self._problems.values())
        values.update(status.values)
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))

    def destroy_node(self):
        """Stop publishing, hold and release the actuators, then destroy the node."""
        self._loop.stop()
        try:
            self.backend.hold(time.monotonic())
            self.backend.close()
        except Exception as error:
            self.get_logger().error('backend shutdown failed: %s' % error)
        return super().destroy_node()


def main(args=None):
    """Run the cable_driver node (``ros2 run continuum_statics cable_driver``)."""
    from continuum_statics.nodes.node_runner import run_nodes
    return run_nodes([CableDriverNode], args)


if __name__ == '__main__':
    sys.exit(main())
