"""Floor 4, dynamics: the rod in motion (Till et al. 2019) and what its response says.

- :mod:`.rod_dynamics`: :class:`RodDynamics`, start and step the rod in time
- :mod:`.response`: settling time, overshoot and spectrum peaks of a recorded response
"""
from continuum_statics.core.dynamics.rod_dynamics import RodDynamics

__all__ = ['RodDynamics']
