"""Declare node parameters from a table, with descriptors, ranges and validation on set."""
from dataclasses import dataclass
import math

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.parameter import Parameter

# ROS-free path helpers, re-exported for the nodes' imports
from continuum_statics.config_paths import (  # noqa: F401
    PACKAGE,
    check_robot_file,
    default_robot_file,
    load_robot_file,
    resolve_config_path,
    share_dir,
)


@dataclass(frozen=True)
class ParamSpec:
    """One node parameter.

    :param name: parameter name (dots make YAML sub-keys: ``sim.max_speed``)
    :param default: default value; its Python type sets the parameter type
    :param description: shown by ``ros2 param describe``; state the unit
    :param low: inclusive lower bound for numbers (None: unbounded)
    :param high: inclusive upper bound for numbers (None: unbounded)
    :param read_only: True where a change needs a restart
    :param check: callable(value) -> None or a reason string, for rules a range cannot express
    """

    name: str
    default: object
    description: str
    low: float = None
    high: float = None
    read_only: bool = False
    check: object = None

    def descriptor(self):
        """Return the rcl_interfaces ParameterDescriptor."""
        descriptor = ParameterDescriptor(name=self.name, description=self.description,
                                         read_only=self.read_only)
        if isinstance(self.default, float) and (self.low is not None or self.high is not None):
            low = -math.inf if self.low is None else self.low
            high = math.inf if self.high is None else self.high
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
            descriptor.additional_constraints = 'finite, in [%g, %g]' % (low, high)
        elif isinstance(self.default, int) and not isinstance(self.default, bool) and (
                self.low is not None or self.high is not None):
            low = -2 ** 31 if self.low is None else int(self.low)
            high = 2 ** 31 - 1 if self.high is None else int(self.high)
            descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
            descriptor.additional_constraints = 'in [%d, %d]' % (low, high)
        return descriptor

    def reason(self, value):
        """Return why ``value`` is not acceptable, or None."""
        if isinstance(self.default, float):
            if not isinstance(value, float) or not math.isfinite(value):
                return '%s must be a finite number, got %r' % (self.name, value)
        if isinstance(self.default, (int, float)) and not isinstance(self.default, bool):
            if self.low is not None and value < self.low:
                return '%s must be >= %g, got %r' % (self.name, self.low, value)
            if self.high is not None and value > self.high:
                return '%s must be <= %g, got %r' % (self.name, self.high, value)
        if self.check is not None:
            return self.check(value)
        return None


class ParameterTable:
    """Declares a node's parameters and validates every later set against the table.

    ``on_change(name, value)`` is called for each accepted change, after validation of the
    whole set (so a set is applied entirely or not at all).
    """

    def __init__(self, node, specs, on_change=None):
        self._specs = {spec.name: spec for spec in specs}
        self.on_change = on_change
        self.values = {}
        for spec in specs:
            value = node.declare_parameter(spec.name, spec.default, spec.descriptor()).value
            reason = spec.reason(value)
            if reason is not None:
                raise ValueError('parameter %s: %s' % (spec.name, reason))
            self.values[spec.name] = value
        node.add_on_set_parameters_callback(self._on_set)

    def __getitem__(self, name):
        return self.values[name]

    def _on_set(self, parameters):
        for parameter in parameters:
            spec = self._specs.get(parameter.name)
            if spec is None:
                continue
            if spec.read_only:
                return SetParametersResult(
                    successful=False, reason='%s is read-only: restart the node to change it'
                    % parameter.name)
            if parameter.type_ == Parameter.Type.NOT_SET:
                return SetParametersResult(successful=False,
                                           reason='%s cannot be undeclared' % parameter.name)
            reason = spec.reason(parameter.value)
            if reason is not None:
                return SetParametersResult(successful=False, reason=reason)
        if self.on_change is not None:
            for parameter in parameters:
                if parameter.name in self._specs:
                    try:
                        self.on_change(parameter.name, parameter.value)
                    except ValueError as error:
                        return SetParametersResult(successful=False, reason=str(error))
        for parameter in parameters:
            if parameter.name in self._specs:
                self.values[parameter.name] = parameter.value
        return SetParametersResult(successful=True)


def robot_file_spec(purpose):
    """Return the read-only ``robot_file`` parameter; ``purpose`` says what the node reads."""
    return ParamSpec('robot_file', default_robot_file(), 'robot description YAML (%s)' % purpose,
                     read_only=True, check=check_robot_file)


def diagnostics_rate_spec():
    """Return the ``diagnostics_rate`` parameter every node declares (default 1 Hz)."""
    return ParamSpec('diagnostics_rate', 1.0, '/diagnostics publish rate, Hz', 0.1, 50.0,
                     read_only=True)


def tip_wrench_limit_specs():
    """Return the ``max_tip_force`` / ``max_tip_torque`` parameters (0: derived from the rod)."""
    return [
        ParamSpec('max_tip_force', 0.0, 'largest plausible tip_wrench force, N; larger ones are '
                  'rejected as a bad tip_wrench (0: 10 E I / L^2 of the rod, a load that bends '
                  'it far beyond 90 degrees)', 0.0, 1e9),
        ParamSpec('max_tip_torque', 0.0, 'largest plausible tip_wrench torque, N m (0: '
                  '2 pi E I / L of the rod, a moment that curls it into a full circle)',
                  0.0, 1e9),
    ]


def tip_wrench_limits(robot, params):
    """Return (force N, torque N m) limits: the parameters, or the rod's defaults where 0.

    The defaults are :func:`~continuum_statics.core.estimation.load_estimation.plausible_tip_load`.
    """
    from continuum_statics.core.estimation.load_estimation import plausible_tip_load
    force, torque = plausible_tip_load(robot)
    return params['max_tip_force'] or force, params['max_tip_torque'] or torque


def tip_wrench_topic(params, robot=None):
    """Return the topic a node takes its tip load from (``tip_wrench_source``).

    statics passes its ``robot``: with the file's ``load_model`` it estimates the load itself
    (and publishes tip_wrench_estimate), so a known extra load may come on tip_wrench only.
    """
    if robot is not None and robot.load_model is not None:
        return 'tip_wrench'
    return 'tip_wrench_estimate' if params['tip_wrench_source'] == 'estimate' else 'tip_wrench'


def backend_options(node, backend_cls):
    """Declare a backend's options as the parameters ``<backend>.<option>``.

    :returns: (the :class:`ParameterTable` of them, {option: value} for the backend)
    """
    prefix = backend_cls.name + '.'
    specs = [ParamSpec(prefix + o.name, o.default, o.description, o.low, o.high, o.read_only)
             for o in backend_cls.options_spec]
    table = ParameterTable(node, specs)  # a table of its own: validated with the backend's
    return table, {spec.name[len(prefix):]: table[spec.name] for spec in specs}
