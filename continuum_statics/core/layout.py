"""The array layouts shared by the kernels and their Python callers, stated once.

Node state (one row of ``kernel.integrate_batch``'s output, :data:`STATE_SIZE` = 21), SI units:
r (3, m), R row-major (9), the stretch v - e3 (3; kept instead of v so ~1e-5 axial strains keep
full precision), the bending u (3, 1/m), M (3, N m: the moment of every load beyond s, after any
point moment at the node).

Rows of ``kernel.probe``'s values (and its Jacobian): tip position (3, m), tip z axis (3),
cable lengths (n_cables, m), tip moment balance (3, (M_end - tau) L / (E I), zero at equilibrium).
"""
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

# node state
POSITION = slice(0, 3)
ROTATION = slice(3, 12)
STRETCH = slice(12, 15)
BENDING = slice(15, 18)
MOMENT = slice(18, 21)
STATE_SIZE = 21


@dataclass(frozen=True)
class ProbeRows:
    """Row blocks of ``kernel.probe`` for a robot with ``n_cables`` cables."""

    n_cables: int

    tip = slice(0, 3)
    axis = slice(3, 6)

    @property
    def lengths(self):
        """Cable lengths, m."""
        return slice(6, 6 + self.n_cables)

    @property
    def balance(self):
        """Tip moment balance (zero at equilibrium)."""
        return slice(6 + self.n_cables, 9 + self.n_cables)

    @property
    def size(self):
        """Number of rows."""
        return 9 + self.n_cables


class SectionArrays(NamedTuple):
    """The robot's index tables, built once per robot, in the order the kernels take them.

    ``kernel.probe`` and ``tracking.track`` end their argument lists with these (a test checks
    the names), so callers pass ``*robot.arrays`` and numba still receives flat arrays.
    """

    section_state_index: np.ndarray  # (S,) first solver-state column of each section, or -1
    section_bases: np.ndarray  # (S, 3, 2) orthonormal bases of the moments a section can apply
    section_ranks: np.ndarray  # (S,) columns of each basis used (0, 1 or 2)
    section_cables: np.ndarray  # (S, width) cable indices of each section, -1 padded
    section_cable_count: np.ndarray  # (S,) cables of each section
    cable_offsets: np.ndarray  # (n_cables, 3) hole positions in the rod's local frame, m
    guide_nodes: np.ndarray  # (G,) integration node of each guide disk (0: the base disk)
    cable_last_guide: np.ndarray  # (n_cables,) guide index of each cable's end disk
    cable_end_node: np.ndarray  # (n_cables,) node of each cable's end disk
    section_end_node: np.ndarray  # (S,) node of each section's end disk
