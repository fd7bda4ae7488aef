"""tip_controller's obstacles and ``clearance``: what its goals keep the body clear of.

The controller subscribes ``obstacles`` as statics does (:class:`~continuum_statics.nodes.
obstacle_topic.ObstacleTopic`: the robot file's merged with the topic's, base frame) and hands
every new set to its run (``GoalRun.obstacles``, under the control's lock), so the next goal is
solved with the body clear of them.

Parameter ``clearance`` (m): how far the whole body keeps from every obstacle on the way to a
tip goal; -1 (the default) is the robot file's ``clearance`` (0 when it gives none). The run
reads it as ``RunSettings.clearance``: None for the robot file's, else metres.
"""
from continuum_statics.nodes.obstacle_topic import ObstacleTopic

#: The ``clearance`` parameter's value for "the robot file's".
FILE_CLEARANCE = -1.0


def check_clearance(value):
    """Return why a ``clearance`` value is refused, or None (-1 or a distance >= 0 m)."""
    return None if value == FILE_CLEARANCE or value >= 0.0 else (
        "must be -1 (the robot file's) or a distance >= 0 m, got %r" % value)


def control_value(name, value):
    """Return a parameter's value as the control reads it: ``clearance`` -1 -> None."""
    if name == 'clearance':
        return None if value < 0.0 else float(value)
    return value


class ControlParameters:
    """The node's parameter table as :class:`TipControl` reads it (:func:`control_value`)."""

    def __init__(self, table):
        self._table = table

    def __getitem__(self, name):
        return control_value(name, self._table[name])


def follow_obstacles(node, control):
    """Subscribe ``obstacles`` for ``control`` (a TipControl); return the ObstacleTopic."""

    def changed(obstacles):
        with control.lock:  # the run solves goals under it: never half a set
            control.run.obstacles = obstacles

    return ObstacleTopic(node, control.robot, changed)
