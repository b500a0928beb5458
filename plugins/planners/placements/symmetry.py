"""Placement symmetry lives in the core's one symmetry module, :mod:`asmteach.core.symmetry`.

Kept only so imports of this module's old names keep working while the
placements planner moves to the core names.
"""

from asmteach.core.symmetry import SymmetryFinder, _within, axis_rotations, symmetry_yaws

__all__ = ["SymmetryFinder", "_within", "axis_rotations", "symmetry_yaws"]
