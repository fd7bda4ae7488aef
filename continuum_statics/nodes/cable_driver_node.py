"""cable_driver: bridge between ``cable_commands`` and the cable actuators (simulated by default).

Subscribes ``cable_commands`` (sensor_msgs/JointState, target cable lengths in m by name) and
publishes ``cable_states`` (measured lengths in m, speeds in m/s, tensions in N where the backend
knows them) at ``publish_rate``. The actuators sit behind a :class:`~continuum_statics.drivers.
CableBackend`, chosen with the read-only ``backend`` parameter (``sim``, ``dynamixel``,
``canopen``, ``ros2_control``, an entry point or ``module:Class``); its options are the
parameters ``<backend>.<option>``.

- Bad commands (unknown or repeated names, NaN, sizes that do not match) are dropped with a
  throttled warning and counted on diagnostics. A length outside the robot's limits by at most
  ``length_margin`` is clamped (encoder quantisation, rounding); further out the whole command is
  rejected with the reason: a clamped set of lengths is a shape nobody asked for.
- When no command arrives for ``command_timeout`` s the watchdog makes the backend hold
  position; the next valid command moves again.
- A lost port or bus (the backend raises :class:`~continuum_statics.drivers.ConnectionLost`) is
  ERROR on /diagnostics naming it; no cable_states are published until the backend reads again;
  the node reconnects with a backoff doubling up to ``reconnect_max_interval`` and then holds
  where the cables are until a new command.
- Commands are refused (with the reason) while the port is lost or an actuator is faulted;
  ``~/reset`` (std_srvs/Trigger) clears faults through the backend's ``reset()``.
- ``~/set_home`` (std_srvs/Trigger) makes the current actuator positions the straight pose and
  writes them to ``home_file`` (YAML), which is loaded at start.
- A robot file without cables: the node says so once and stays up without publishing.
- Simulated backend only: ``sim_tip_wrench`` (parameter [fx, fy, fz, mx, my, mz] and a
  geometry_msgs/WrenchStamped topic of that name, base frame) is a tip load on the simulated
  robot that no other node is told about (tensions change under it; the motors hold).
- Simulated backend: ``sim/tip_pose_true`` (geometry_msgs/PoseStamped, base frame) with every
  reading: with ``sim.dynamics`` the rod moving behind the motors in real time (real-time factor
  on /diagnostics), else the real tendons' equilibrium at the motors' lengths (file's obstacles).
"""
import sys
from types import SimpleNamespace

from geometry_msgs.msg import PoseStamped, WrenchStamped
import numpy as np
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from continuum_statics.control.actuators import Actuators
from continuum_statics.control.command_gate import CommandGate
from continuum_statics.control.health import DriverHealth
from continuum_statics.core.rod.rotations import rotation_to_quaternion
from continuum_statics.drivers import backend_class
from continuum_statics.drivers.home_file import home_option, write_home_file
from continuum_statics.nodes import diagnostics_util as diag
from continuum_statics.nodes.dedicated_intake import PeriodicThread
from continuum_statics.nodes.joint_state_parser import parse_joint_state
from continuum_statics.nodes.node_params import (
    ParameterTable,
    backend_options,
    load_robot_file,
)
from continuum_statics.nodes.node_runner import RunnerHooks, run_nodes
from continuum_statics.nodes.parameter_tables import cable_driver_parameters
from continuum_statics.nodes.qos import COMMAND_QOS
from continuum_statics.nodes.ros_conversions import (
    cable_index,
    joint_positions,
    joint_state,
    set_pose,
    tip_load,
)
from continuum_statics.nodes.ros_topic_backend import lend_topics
from continuum_statics.nodes.timers import steady_timer
from continuum_statics.nodes.transition_failures import TransitionFailures


class CableDriverNode(RunnerHooks, TransitionFailures, LifecycleNode):
    """Cable actuator bridge: commands in, measured cable lengths out; a lifecycle node.

    unconfigured -> configure (open the port or bus, read the positions; cable_states flow, the
    power stage / torque stays off) -> activate (torque on / operation enabled at the present
    positions; commands accepted) -> deactivate (hold, torque off; commands refused) -> cleanup
    (release the port or bus). ``autostart`` (default true) configures and activates at once.
    A lost connection is retried in any configured state; it never needs a restart.
    """

    EXECUTOR = 'single'

    def __init__(self, node_name='cable_driver', **kwargs):
        super().__init__(node_name, **kwargs)
        specs = cable_driver_parameters()
        self._params = ParameterTable(self, specs)
        self.robot = load_robot_file(self._params['robot_file'])
        self._backend_cls = backend_class(self._params['backend'])
        self._options, options = backend_options(self, self._backend_cls)  # once it is known
        self.cable_names = tuple(self.robot.cable_names)
        self._limits = np.asarray(self.robot.cable_length_limits, dtype=float).reshape(-1, 2)
        self._home_file = self._params['home_file']
        home = home_option(self._home_file, self._backend_cls, self.cable_names)
        if home:
            options.update(home)
            self.get_logger().info('home positions from %s: %s' % (self._home_file, home))

        self.health = DriverHealth(self._backend_cls.name, self._warn, bool(self.cable_names))
        self._problems = self.health.problems
        # lifecycle, connection and fault state, and what a command becomes (control/)
        self.gate = CommandGate(self.cable_names, self._limits, self.robot.straight_cable_lengths)
        # every backend call, under one lock (the executor and the publish loop both call in)
        self.actuators = Actuators(self.gate, self._backend_cls.name, self.get_logger())
        self.actuators.max_interval = self._params['reconnect_max_interval']
        self._state_msg = JointState()
        self._diagnostics = self.create_publisher(diag.DiagnosticArray, '/diagnostics', 10)
        steady_timer(self, 1.0 / self._params['diagnostics_rate'], self._publish_diagnostics)
        self._loop = None
        self._backend_options = options
        self._ros_topics = None  # the command sender lent to a ROS-topic backend
        if not self.cable_names:
            # A passive rod (no cables): say it once, stay up, publish only diagnostics.
            self.get_logger().warning(
                'robot %r has no cables: cable_driver has nothing to drive (a passive rod); '
                'it stays up and publishes no cable_states' % self.robot.name)
            self._params.on_change = self._on_parameter_change
            return

        self._publisher = self.create_publisher(JointState, 'cable_states',
                                                qos_profile_sensor_data)
        self._true_tip = None  # a simulated robot's true tip
        if self._backend_cls.knows_truth(self.robot, options):
            self._true_tip = self.create_publisher(PoseStamped, 'sim/tip_pose_true',
                                                   qos_profile_sensor_data)
            self._true_tip_msg = PoseStamped()
            self._true_tip_msg.header.frame_id = self.robot.base_frame_id
        # raw: a malformed or empty payload is then seen (and counted), not dropped by rclpy
        self.create_subscription(JointState, 'cable_commands', self._on_raw_command,
                                 COMMAND_QOS, raw=True)
        self.create_service(Trigger, '~/reset', self._on_reset)
        self._hidden_load = np.array(self._params['sim_tip_wrench'], dtype=float)
        if self._backend_cls.takes_tip_wrench:
            self.create_subscription(WrenchStamped, 'sim_tip_wrench', self._on_sim_tip_wrench,
                                     10)
        self.create_service(Trigger, '~/set_home', self._on_set_home)
        # cable_states from a thread of its own: steadier and ~10x cheaper than a 200 Hz timer.
        self._loop = PeriodicThread(self, self._params['publish_rate'], self._on_timer,
                                    'cable_driver_publish')
        # Applied only after everything above exists.
        self._params.on_change = self._on_parameter_change
        self._options.on_change = self._on_option_change
        self._loop.start()
        self.get_logger().info('cable_driver: backend %s, %d cables (%s), %g Hz' % (
            self._backend_cls.name, len(self.cable_names), ', '.join(self.cable_names),
            self._params['publish_rate']))
        configured = self._params['autostart'] and self.trigger_configure()
        if configured == TransitionCallbackReturn.SUCCESS:  # Jazzy raises for an activate
            self.trigger_activate()                         # from unconfigured

    # -- lifecycle --------------------------------------------------------------------------
    def on_configure(self, state):
        """Create the backend, open the port or bus and read (power off)."""
        if not self.cable_names:
            return TransitionCallbackReturn.SUCCESS
        try:
            extra = {'robot': self.robot} if self._backend_cls.wants_robot else {}
            backend = self._backend_cls(self.cable_names, self._limits,
                                        self.robot.straight_cable_lengths,
                                        **self._backend_options, **extra)
        except Exception as error:  # bad options a parameter check could not see
            return self._transition_failed('configure failed: %s' % error)  # /diagnostics too
        if backend.takes_tip_wrench:
            try:
                backend.set_tip_wrench(self._hidden_load)
            except ValueError as error:  # sim_tip_wrench beyond the rod: none
                self._problems.reject('sim_tip_wrench', error)
                self._hidden_load = np.zeros(6)
        self.actuators.configure(backend, self._lend_topics)
        return self._transition_done()

    def _lend_topics(self, backend):
        if backend.ros_topics:  # ros2_control: the node lends it topics (made once)
            self._ros_topics = self._ros_topics or lend_topics(self, lambda: self.backend)
            backend.attach_ros(self._ros_topics)

    @property
    def backend(self):
        """The configured :class:`~continuum_statics.drivers.CableBackend`, or None."""
        return self.actuators.backend

    def on_activate(self, state):
        """Torque on / operation enabled at the present positions; accept commands."""
        return self._switch_power(True)

    def on_deactivate(self, state):
        """Refuse commands, hold, torque off / power stage off."""
        return self._switch_power(False)

    def on_cleanup(self, state):
        """Release the actuators and the port or bus."""
        self.actuators.release()
        return self._transition_done()

    def on_shutdown(self, state):
        """Power off and release, from any state (finalized: no transition leads back)."""
        self.actuators.release()
        self.gate.finalized = True
        return TransitionCallbackReturn.SUCCESS

    def _switch_power(self, on):
        if not self.actuators.switch_power(on):
            return self._transition_failed(self.actuators.failure)
        self.get_logger().info('cable_driver %s' % ('active: torque on, commands accepted' if on
                                                    else 'inactive: torque off, holding'))
        return self._transition_done()

    # -- parameters ---------------------------------------------------------------------------
    def _on_parameter_change(self, name, value):
        if name == 'publish_rate' and self._loop is not None:
            self._loop.rate = value
        elif name == 'reconnect_max_interval':
            self.actuators.max_interval = value
        elif name == 'sim_tip_wrench':
            self._set_hidden_load(np.array(value, dtype=float))

    def _on_sim_tip_wrench(self, msg):
        try:
            wrench = tip_load(msg, self.robot.base_frame_id, what='sim_tip_wrench')
        except ValueError as error:
            self._problems.reject('sim_tip_wrench', error)
            return
        self._set_hidden_load(wrench)

    def _set_hidden_load(self, wrench):
        """Set the simulated robot's hidden tip load (6,), now and for the next configure."""
        if self._backend_cls.takes_tip_wrench:
            try:
                self.actuators.call(lambda backend: backend.set_tip_wrench(wrench))
            except ValueError as error:  # beyond the rod: the last load stays
                self._problems.reject('sim_tip_wrench', error)
                return
        self._hidden_load = wrench

    def _on_option_change(self, name, value):
        key = name.split('.', 1)[1]
        self.actuators.call(lambda backend: backend.set_option(key, value))
        self._backend_options[key] = value  # for the next configure

    # -- commands -----------------------------------------------------------------------------
    def _warn(self, text):
        self.get_logger().warning(text)

    def _on_raw_command(self, data):
        try:
            view = parse_joint_state(data)
        except ValueError as error:
            self.health.empty_payloads += len(data) == 0
            self._problems.reject('cable_commands', error)
            return
        self._on_command(SimpleNamespace(name=view.names, position=view.position,
                                         velocity=view.velocity, effort=view.effort))

    def _on_command(self, msg):
        try:
            index = cable_index(msg.name, self.cable_names, require_all=False)
            self.actuators.command(index, joint_positions(msg, len(index)),
                                   self._params['length_margin'])
        except ValueError as error:  # CommandRefused too
            self._problems.reject('cable_commands', error)

    # -- the loop ---------------------------------------------------------------------------
    def _on_timer(self):
        def fill(reading):  # ValueError on a non-finite reading: a failed read
            joint_state(self.cable_names, reading.lengths, self.get_clock().now().to_msg(),
                        reading.velocities, reading.tensions, msg=self._state_msg)

        if self.actuators.step(self._params['command_timeout'], fill) is not None:
            self._publisher.publish(self._state_msg)
            self.health.rate.tick()
            if self._true_tip is not None:
                self._publish_true_tip()

    def _publish_true_tip(self):
        pose = None if (backend := self.backend) is None else backend.true_tip_pose  # read once
        if pose is None:
            return
        position, rotation = pose
        msg = self._true_tip_msg
        msg.header.stamp = self._state_msg.header.stamp
        set_pose(msg.pose, [float(v) for v in position],
                 [float(v) for v in rotation_to_quaternion(rotation)])
        self._true_tip.publish(msg)

    # -- services -----------------------------------------------------------------------------
    def _on_reset(self, request, response):
        if self.backend is None:
            response.success, response.message = False, 'robot has no cables: nothing to reset'
            return response
        response.success, response.message = self.actuators.reset()
        self.get_logger().info('reset: %s' % response.message)
        return response

    def _on_set_home(self, request, response):
        if self.backend is None:
            response.success, response.message = False, 'robot has no cables: nothing to home'
            return response
        try:
            zeros = self.actuators.set_home(self._params['home_tolerance'],
                                            self._params['home_force'])
        except Exception as error:
            response.success, response.message = False, 'set_home failed: %s' % error
            return response
        option = self._backend_cls.zero_option
        message = '%s = %s' % (option, zeros)
        if self._home_file:
            try:
                write_home_file(self._home_file, self._backend_cls.name, option,
                                self.cable_names, zeros)
                message += ', written to %s' % self._home_file
            except OSError as error:
                response.success = False
                response.message = '%s, but home_file not written: %s' % (message, error)
                return response
        else:
            message += ' (not saved: home_file is empty)'
        response.success, response.message = True, message
        self.get_logger().info('set_home: %s' % message)
        return response

    # -- diagnostics --------------------------------------------------------------------------
    def _publish_diagnostics(self):
        # read by tip_controller: a goal fails at once, naming this, when commands are refused
        status = self.actuators.status()
        level, message, values = self._with_transition_failure(self.health.report(
            self.gate, status, self.actuators.reconnects))
        self._diagnostics.publish(diag.diagnostic_array(
            self.get_clock().now().to_msg(), self.get_fully_qualified_name().lstrip('/'),
            self.robot.name, level, message, values))

    def on_node_failure(self, text):
        """Count a restart by the runner after a callback raised (on diagnostics)."""
        self._problems.add('node', text)

    def destroy_node(self):
        """Stop publishing, hold and release the actuators, then destroy the node."""
        if getattr(self, '_loop', None) is not None:  # None or unset: __init__ failed early
            self._loop.stop()
        if getattr(self, 'actuators', None) is not None:
            self.actuators.release()
        return super().destroy_node()


def main(args=None):
    """Run the cable_driver node (``ros2 run continuum_statics cable_driver``)."""
    return run_nodes([CableDriverNode], args)


if __name__ == '__main__':
    sys.exit(main())
