"""Floor 1, the description of a robot: what the robot file says, validated (no numerics).

- :mod:`.robot_file`: read and validate the YAML robot file (every key, its errors by name)
- :mod:`.routing`: the cable holes along the rod (straight, helical, per-disk offsets)
- :mod:`.tendons`: real tendons (stretch, pretension, capstan friction, zero offsets)
- :mod:`.sensors`: the robot file's sensors, their readings and verdicts, model uncertainty
- :mod:`.obstacles`: obstacles around the robot (the file's ``obstacles:``), signed distances
- :mod:`.layout`: the named layouts of every array a kernel reads or writes
- :mod:`.inputs`: argument checks shared by the API (vectors of a length, finite)
"""
from continuum_statics.core.description.robot_file import read_robot_description
from continuum_statics.core.description.routing import Routing
from continuum_statics.core.description.sensors import (
    ModelUncertainty,
    SensorReading,
    SensorVerdict,
)
from continuum_statics.core.description.tendons import Tendons

__all__ = ['read_robot_description', 'Routing', 'Tendons', 'SensorReading', 'SensorVerdict',
           'ModelUncertainty']
