"""Real-time Cosserat-rod statics for cable/tendon-driven continuum robots.

The numeric core (no ROS imports): ``load_robot(path)`` returns a :class:`Robot` with
``solve_ivp``, ``solve_bvp``, ``cable_lengths``, ``jacobian``, ``cable_jacobian``,
``estimate_shape`` and ``solve_tip_goal``. The records a caller builds are here too: a
sensor's :class:`SensorReading` and a tracking node's :class:`Tracking` (the public names do not
move when ``core/`` does).
"""
from continuum_statics.core.description.sensors import SensorReading
from continuum_statics.core.estimation.shape_estimation import Tracking
from continuum_statics.core.robot import Robot, load_robot
from continuum_statics.core.rod.shape import Shape
from continuum_statics.core.statics.bvp import ConvergenceError

__all__ = ['load_robot', 'Robot', 'Shape', 'ConvergenceError', 'SensorReading', 'Tracking']
