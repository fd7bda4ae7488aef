"""The physics, without ROS, in floors; each imports only from the floors below it.

=============  ==========================================================================
floor          what it holds
=============  ==========================================================================
description/   the robot file, cable routing, real tendons, sensors, the named layouts
rod/           the model object (the one call site of every compiled kernel), the kernels
statics/       IVP/BVP, length and tension statics, tip goals, cable commands, workspace
estimation/    shape from lengths, the fused state (sensors), the tip load
dynamics/      the rod in motion and what a response says (settling, overshoot, spectrum)
robot.py       the facade: ``load_robot`` and :class:`~continuum_statics.core.robot.Robot`
warmup.py      compiles every kernel a node calls, before it serves
=============  ==========================================================================

``test/package/test_layer_contracts.py`` ranks the floors (:data:`FLOORS` there): an import
from a higher floor fails it. Users import ``from continuum_statics import load_robot``.
"""
