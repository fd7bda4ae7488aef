"""Motor commands for a model shape with real tendons: tensions, stretch, limits (no ROS).

A controller plans in the model's unknowns (section moments); the motors hold lengths. For a
planned shape each section's cables must apply its moment: the least-norm tensions t >= t_min
(``min_tension``, so antagonists stay taut when asked) with sum_j t_j (e3 x l_j) = the section's
moment; each cable's motor then holds the free length that spans its path at that tension,
Lf = p / (1 + t / EA) (:mod:`continuum_statics.core.description.tendons`), converted to the
motor-side length.
Ideal cables (inextensible) with ``min_tension`` 0 command exactly the paths, as before. The
tensions are checked against ``tension_limits``: a shape that needs more is refused, naming the
cable. Friction is left to the closed loop (the frictionless stretch is commanded); with the
distributed model the extra tension of ``min_tension`` compresses the rod slightly, which the
planned shape does not include (sub-micrometre for tensions of a few N on a typical backbone).
"""
from dataclasses import dataclass

import numpy as np

from continuum_statics.core.rod.kernel import DISTRIBUTED


@dataclass(frozen=True, eq=False)
class Command:
    """Motor-side lengths (m) and the tensions (N) they give, ``robot.cable_names`` order."""

    lengths: np.ndarray
    tensions: np.ndarray


def shape_tensions(robot, shape, min_tension=0.0):
    """Return cable tensions (N) that hold a model shape.

    Each is at least ``min_tension`` and the low end of its ``tension_limits`` (N).
    """
    return state_tensions(robot, shape.state, getattr(shape, 'fixed_tensions', None),
                          min_tension)


def state_tensions(robot, state, fixed_tensions=None, min_tension=0.0):
    """Return the tensions (N) of :func:`shape_tensions` of a solver state.

    ``fixed_tensions`` (N) are the state's fixed tensions (None: zero).
    """
    fixed = robot.tensions_or_zero(fixed_tensions)
    moments, implied = robot.loads(state, fixed)
    tensions = np.zeros(len(robot.cable_names))
    arms = np.cross([0.0, 0.0, 1.0], robot.cable_offsets)
    floor = np.maximum(min_tension, robot.tendons.tension_limits[:, 0])
    for k, section in enumerate(robot.sections):
        cables = np.array(section.cable_indices, dtype=np.int64)
        if not cables.size:
            continue
        if robot.model_code == DISTRIBUTED:
            moment = arms[cables].T @ implied[cables]  # the state's tensions, as a moment
        else:
            moment = moments[k]
        # t = floor + s, s >= 0 least-norm with A s = m - A floor (the kernel's routine)
        rest = moment - arms[cables].T @ floor[cables]
        extra = np.zeros(len(robot.cable_names))
        robot.model.section_tensions(np.ascontiguousarray(rest[:2]), cables, extra)
        tensions[cables] = floor[cables] + extra[cables]
    return tensions


def command_for(robot, shape, min_tension=0.0):
    """Motor-side lengths that hold ``shape`` (a model shape) and their tensions.

    :raises ValueError: a tension above a cable's ``tension_limits`` (the reason names it)
    """
    return command_for_state(robot, shape.state, robot.cable_lengths(shape),
                             getattr(shape, 'fixed_tensions', None), min_tension)


def command_for_state(robot, state, paths, fixed_tensions=None, min_tension=0.0):
    """Return :func:`command_for` of a solver state whose cable paths (m) are known."""
    tendons = robot.tendons
    if tendons.is_ideal and min_tension <= 0.0 and not np.any(tendons.tension_limits[:, 0]):
        return Command(paths, state_tensions(robot, state, fixed_tensions))
    tensions = state_tensions(robot, state, fixed_tensions, min_tension)
    high = tendons.tension_limits[:, 1]
    over = np.flatnonzero(tensions > high)
    if over.size:
        raise ValueError('needs more tension than tension_limits allow: %s' % ', '.join(
            '%s %.3g N > %.3g N' % (robot.cable_names[j], tensions[j], high[j])
            for j in over))
    free = paths / (1.0 + tensions * tendons.compliance)
    return Command(tendons.lengths_for(free, robot.straight_cable_lengths), tensions)
