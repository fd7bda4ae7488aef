"""Floor 3, statics: equilibria of the rod for given cable lengths, tensions or tip goals.

- :mod:`.bvp`: the boundary-value solves (loaded rod, tensions) over the IVP of the paper
- :mod:`.length_statics`: the length-driven statics of real tendons (slack, stretch, friction)
- :mod:`.contact`: the rod resting on frictionless obstacles (Signorini contact forces)
- :mod:`.tip_goal`: cable lengths that put the tip at a goal (the numerical Jacobian's use)
- :mod:`.tendon_commands`: the motor-side lengths that hold a shape
- :mod:`.attempts`: solvers as ordered lists of named attempts
- :mod:`.workspace`: reachable tips, sampled
"""
from continuum_statics.core.statics.bvp import ConvergenceError
from continuum_statics.core.statics.length_statics import solve_lengths
from continuum_statics.core.statics.tendon_commands import command_for

__all__ = ['ConvergenceError', 'solve_lengths', 'command_for']
