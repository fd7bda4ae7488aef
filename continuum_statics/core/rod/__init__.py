"""Floor 2, the rod: the special Cosserat rod of the paper, its compiled kernels and the shape.

- :mod:`.model`: :class:`Model`, the one place Python calls each compiled kernel
- compiled kernels (numba): :mod:`.kernel` (the IVP, paper eqs. 1-10, and its probe),
  :mod:`.tendon_kernel` (cable paths and tensions), :mod:`.tracking` (shape from lengths),
  :mod:`.goal_tracking` (tip goals), :mod:`.length_tracking` (length-driven tendon statics),
  :mod:`.dynamics_kernel` (the rod in motion, one time step)
- :mod:`.least_squares`, :mod:`.rotations`: the small numerics they share
- :mod:`.shape`, :mod:`.backbone_sampling`: the solved shape a user reads, sampled along s
"""
from continuum_statics.core.rod.model import Model
from continuum_statics.core.rod.shape import Shape

__all__ = ['Model', 'Shape']
