"""Cable actuator backend interface: what ``cable_driver`` needs from any actuator.

The node owns everything ROS (topics, parameters, validation of messages, the command watchdog,
diagnostics); a backend owns only the actuators. A backend receives target cable lengths that are
already validated, finite and inside the robot's length limits, in ``cable_names`` order, and
reports measured lengths (m), and where it knows them velocities (m/s) and tensions (N).

A real actuator backend subclasses :class:`CableBackend`, and is selected with the node's
``backend`` parameter either by a short name registered under the entry-point group
``continuum_statics.cable_backends`` or by a ``'package.module:ClassName'`` spec, so it plugs
in without touching the node.
"""
import abc
from dataclasses import dataclass, field
import importlib
import importlib.metadata

import numpy as np

#: Entry-point group for third-party backends (``name = package.module:ClassName``).
ENTRY_POINT_GROUP = 'continuum_statics.cable_backends'

#: Diagnostic levels, same numbers as diagnostic_msgs/DiagnosticStatus (no ROS import here).
OK, WARN, ERROR = 0, 1, 2

#: Backends shipped with the package: name -> 'module:Class' (imported only when selected, so
#: a missing SDK only matters to the backend that needs it).
BUILTIN_BACKENDS = {
    'sim': 'continuum_statics.drivers.sim:SimulatedCableBackend',
    'dynamixel': 'continuum_statics.drivers.dynamixel:DynamixelCableBackend',
    'canopen': 'continuum_statics.drivers.canopen_drive:CanopenCableBackend',
    'ros2_control': 'continuum_statics.drivers.ros2_control:Ros2ControlCableBackend',
}


class ConnectionLost(OSError):
    """The port or bus is gone (adapter unplugged, bus off): the node reconnects with backoff.

    Raised by ``start``, ``command``, ``hold`` and ``read``; the message names the port or bus.
    """


@dataclass(frozen=True)
class BackendOption:
    """One backend option; the node declares it as the parameter ``<backend name>.<name>``.

    :param name: option name
    :param default: default value (its type is the parameter type)
    :param description: what it does, with the unit
    :param low: inclusive lower bound for numbers, or None
    :param high: inclusive upper bound for numbers, or None
    :param read_only: True if a change needs a restart (otherwise ``set_option`` applies it)
    """

    name: str
    default: object
    description: str
    low: float = None
    high: float = None
    read_only: bool = False


@dataclass(frozen=True)
class CableReading:
    """One measurement of every cable, in the backend's ``cable_names`` order.

    :param lengths: measured cable lengths, m, shape (n_cables,)
    :param velocities: cable speeds, m/s, shape (n_cables,), or None when unknown
    :param tensions: cable tensions, N, shape (n_cables,), or None when unknown
    """

    lengths: np.ndarray
    velocities: np.ndarray = None
    tensions: np.ndarray = None


@dataclass(frozen=True)
class BackendStatus:
    """Health of the actuators for diagnostics: a level (OK/WARN/ERROR), a message, key/values."""

    level: int = OK
    message: str = 'ok'
    values: dict = field(default_factory=dict)


class CableBackend(abc.ABC):
    """Base class of every cable actuator backend.

    :param cable_names: cable names, in the order of every array passed in or out
    :param length_limits: (n_cables, 2) array of [min, max] cable lengths, m
    :param initial_lengths: (n_cables,) lengths to assume before the first reading, m
    :param options: backend-specific options (from the node's ``<backend>.*`` parameters)
    """

    #: Short name of the backend (the ``backend`` parameter value).
    name = 'abstract'
    #: Whether :meth:`start` (a connection or a reconnection) switches the power stage / torque
    #: on. The lifecycle driver clears it before configure (connect and read only) and sets it
    #: on activate, so a reconnection while inactive never powers the actuators.
    power = True
    #: The backend's options (:class:`BackendOption`), declared by the node as parameters.
    options_spec = ()
    #: True: the node passes ``robot=`` (its :class:`~continuum_statics.core.robot.Robot`) to
    #: the constructor (the simulated robot needs the model).
    wants_robot = False
    #: True for a :class:`RosTopicBackend`: the node lends it a command publisher and a
    #: subscription (the backend itself imports no ROS).
    ros_topics = False
    #: True when the backend takes a hidden tip load (:meth:`set_tip_wrench`, simulation).
    takes_tip_wrench = False

    def __init__(self, cable_names, length_limits, initial_lengths, **options):
        self.cable_names = tuple(cable_names)
        n_cables = len(self.cable_names)
        self.length_limits = np.array(length_limits, dtype=float).reshape(n_cables, 2)
        self.initial_lengths = np.array(initial_lengths, dtype=float).reshape(n_cables)
        # every option of :attr:`options_spec`, the defaults where not given (merged here once)
        defaults = {option.name: option.default for option in self.options_spec}
        unknown = set(options) - set(defaults)
        if unknown:
            raise ValueError('unknown option(s) for the %s backend: %s (known: %s)' % (
                self.name, ', '.join(sorted(unknown)), ', '.join(sorted(defaults)) or 'none'))
        self.options = dict(defaults, **options)

    @abc.abstractmethod
    def start(self, now) -> None:
        """Connect to the actuators and read them (power on if :attr:`power`); now: monotonic s."""

    def enable(self, now) -> None:
        """Power stage / torque on, holding where the actuators are (lifecycle activate)."""
        self.power = True

    def disable(self, now) -> None:
        """Hold where the actuators are, then power stage / torque off (lifecycle deactivate)."""
        self.power = False
        self.hold(now)

    @abc.abstractmethod
    def command(self, target_lengths, now) -> None:
        """Move towards ``target_lengths`` (n_cables,) m; finite and inside the limits."""

    @abc.abstractmethod
    def hold(self, now) -> None:
        """Stop where the cables are now (command watchdog, shutdown)."""

    @abc.abstractmethod
    def read(self, now) -> 'CableReading':
        """Return the current :class:`CableReading`; ``now`` is a monotonic time in s."""

    def status(self) -> 'BackendStatus':
        """Return the actuators' :class:`BackendStatus` (override to report real health)."""
        return BackendStatus()

    #: Option holding the actuator positions of the straight pose (``set_home`` writes it).
    zero_option = None

    def reset(self) -> str:
        """Clear actuator faults (reboot, fault reset) and re-enable; return what was done."""
        return 'nothing to reset'

    def set_home(self) -> list:
        """Record the current actuator positions as the straight pose; return the new zeros.

        :returns: list of positions for :attr:`zero_option` (what the node writes to its home file)
        :raises ValueError: when the backend has no home
        """
        raise ValueError('backend %r has no homing' % self.name)

    def set_option(self, key, value) -> None:
        """Change one option at run time; raise ValueError if it cannot change while running."""
        raise ValueError('backend %r cannot change option %r while running' % (self.name, key))

    def set_tip_wrench(self, wrench) -> None:
        """Put a hidden tip load (6,) N, N m on a simulated robot (:attr:`takes_tip_wrench`)."""
        raise ValueError('backend %r has no simulated tip load' % self.name)

    @classmethod
    def knows_truth(cls, robot, options) -> bool:
        """Whether :attr:`true_tip_pose` can be known for ``robot`` with ``options`` (dict)."""
        return False

    @property
    def true_tip_pose(self):
        """The robot's true tip (position (3,) m, rotation (3, 3)) where the backend knows it.

        None for real actuators (only a simulated robot knows its truth); the driver publishes
        it on ``sim/tip_pose_true`` when it is not None (:meth:`knows_truth`).
        """
        return None

    def close(self) -> None:
        """Release the actuators (called once, when the node is destroyed)."""


class RosTopicBackend(CableBackend):
    """A backend whose actuators are reached through ROS topics the node owns (ros2_control).

    The node publishes each command on :attr:`command_topic` (std_msgs/Float64MultiArray) through
    the ``send(positions)`` it passes to :meth:`attach_ros`, and feeds every JointState of
    :attr:`state_topic` to :meth:`on_joint_state`. No ROS import here.
    """

    ros_topics = True
    #: Set by the subclass (usually from its options) before the node configures it.
    command_topic = ''
    state_topic = ''

    @abc.abstractmethod
    def attach_ros(self, send) -> None:
        """Take the node's publisher: ``send(positions)`` publishes one command."""

    @abc.abstractmethod
    def on_joint_state(self, names, positions, velocities, efforts, now) -> None:
        """Take one JointState of :attr:`state_topic`; ``now`` is monotonic s."""


def backend_class(spec) -> type:
    """Return the backend class for ``spec``: a built-in or entry-point name, or ``module:Class``.

    :raises ValueError: when no backend of that name exists (the message lists the known names)
    """
    spec = str(spec).strip()
    known = BUILTIN_BACKENDS
    if spec in known:
        return _load(known[spec], spec)
    try:
        entry_points = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    except TypeError:  # Python < 3.10 API; kept for old robot computers
        entry_points = importlib.metadata.entry_points().get(ENTRY_POINT_GROUP, [])
    for entry_point in entry_points:
        if entry_point.name == spec:
            return _check_backend(entry_point.load(), spec)
    if ':' in spec:
        return _load(spec, spec)
    names = sorted(set(known) | {entry_point.name for entry_point in entry_points})
    raise ValueError('unknown cable backend %r; known: %s, or a "module:Class" spec'
                     % (spec, ', '.join(names)))


def _load(target, spec):
    module_name, _, class_name = target.partition(':')
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as error:
        raise ValueError('cannot load cable backend %r: %s' % (spec, error)) from None
    return _check_backend(cls, spec)


def _check_backend(cls, spec):
    if not (isinstance(cls, type) and issubclass(cls, CableBackend)):
        raise ValueError('cable backend %r is not a CableBackend subclass' % spec)
    return cls
