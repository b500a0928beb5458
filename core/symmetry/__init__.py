"""Symmetries of a rigid part: the proper rotations that map its surface onto itself.

The one symmetry module of asmteach; every stage uses it:

* :func:`part_symmetries`: the part's symmetry group (part frame, about the
  centre of mass). A pose of a symmetric part is only defined up to these
  rotations: a detector may return any of them, and an assembly is right
  when it matches the taught one up to them.
* :class:`SymmetryFinder`: the order of the cyclic symmetry about one axis
  (a placement looks the same after a turn by ``2 pi / m`` about the table
  normal); :func:`symmetry_yaws` lists those turns.
* :func:`principal_frame`: the principal axes of inertia as a right-handed
  rotation (a new array: trimesh's own arrays are read-only).

How a rotation is tested: :mod:`.finder`; the candidates of the whole group:
:mod:`.group`.

Units: metres, radians; frames: the part frame.
"""

from __future__ import annotations

from asmteach.core.symmetry.finder import SymmetryFinder, axis_rotations, symmetry_yaws
from asmteach.core.symmetry.group import (
    equivalent_transforms,
    part_symmetries,
    principal_frame,
)

__all__ = [
    "SymmetryFinder",
    "axis_rotations",
    "equivalent_transforms",
    "part_symmetries",
    "principal_frame",
    "symmetry_yaws",
]
