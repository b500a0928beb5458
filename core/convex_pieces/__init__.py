"""Convex decomposition of any part, for physics engines: exact where it can be, measured always.

A physics engine collides convex shapes. Approximate decompositions (V-HACD)
fill a 0.5 mm-clearance hole and inflate faces by up to a millimetre, so a
peg can never enter its hole in simulation. This module is the one convex
decomposition of the project (PyBullet worlds, the grasp hold check); it
picks the first route that applies to a :class:`PartModel`:

``solid``
    A parametric solid ``union(add) - union(subtract)`` of boxes and
    cylinders has an exact decomposition: each added primitive ``P`` is
    convex, and for a convex cut ``C = {x : n_k . x <= d_k for all k}``

        P - C = union over k of (P and {n_k . x >= d_k})

    is a union of convex pieces (they overlap, which collision detection does
    not mind). Repeating this for every cut gives pieces whose union is
    exactly the solid (up to the cylinders' 64-sided polygons, which the
    part's mesh uses too). Pieces thinner than ``min_thickness`` are dropped.
``convex``
    A convex mesh is its own hull: one piece.
``plane_split``
    A mesh (STL/OBJ from CAD) is split recursively with manifold3d along the
    planes of its own faces until every piece is convex (:func:`split_convex`).
    Every cut runs along a face of the mesh, so the pieces' union *is* the
    mesh (to float32 rounding and the 0.2 um cut offset): no hole, slot or
    groove is filled. It is kept when its measured protrusion and uncovered
    distance are within ``tolerance`` (pieces it had to replace by their hull,
    float slivers mostly, are measured like every other).
``coacd``
    Otherwise (curved free-form meshes, whose split would need too many
    pieces) CoACD (collision-aware approximate convex decomposition) with a
    fixed seed; its concavity threshold is derived from ``tolerance`` and the
    part's size (CoACD works on the mesh normalised to its bounding box),
    bounded below by ``min_coacd_threshold`` to keep its run time in seconds.
    Its pieces that still protrude past ``tolerance`` are then cut again
    where they bridge a concavity (:mod:`.refine`), up to
    ``refine_max_pieces`` pieces.
    When the plane split, hulls and all, is closer to the mesh than CoACD's
    result (larger of protrusion and uncovered distance), it is kept.

Every result carries its measured fidelity (:func:`fidelity`), both ways:
the largest protrusion of the pieces outside the mesh (what closes a
clearance), the largest distance of the mesh (its surface and its inside)
from the pieces (``uncovered``: where a body would pass through the part),
the two-sided Hausdorff distance between the two solids (the larger of the
two) and the union's volume error, by seeded sampling (Open3D's nearest
triangle with an exact float64 point-triangle distance, Open3D ray casting
for inside/outside, vectorised).

Decompositions are cached on disk under ``convex_pieces`` in
:func:`asmteach.core.io.cache_root`, keyed by the mesh hash (and the solid
spec, for parametric parts) plus the settings; files are written atomically,
and a damaged or foreign file is rebuilt.

Planning does not use these pieces: its collision checks (FCL) test the exact
mesh's BVH (:mod:`asmteach.core.arm.collision`), which is
mesh-exact contact already. Only physics simulation needs convex pieces.

Units: metres, part frame.
The package: :mod:`.pieces` (settings, the result, hulls and OBJ text), :mod:`.solids` (the exact
route of parametric solids), :mod:`.meshes` (the plane split and CoACD), :mod:`.measure` (fidelity) and
:mod:`.refine` (cutting protruding pieces again) and :mod:`.route` (:func:`decompose`: the route taken, cached on
disk and in memory).
"""

from __future__ import annotations

from asmteach.core.convex_pieces.measure import fidelity, pieces_volume_error
from asmteach.core.convex_pieces.meshes import coacd_pieces, split_convex
from asmteach.core.convex_pieces.pieces import ConvexDecomposition, DecompositionSettings, pieces_obj
from asmteach.core.convex_pieces.route import CACHE_VERSION, decompose, default_cache_dir
from asmteach.core.convex_pieces.solids import primitive_halfspaces, solid_pieces

__all__ = [
    "CACHE_VERSION",
    "ConvexDecomposition",
    "DecompositionSettings",
    "coacd_pieces",
    "decompose",
    "default_cache_dir",
    "fidelity",
    "pieces_obj",
    "pieces_volume_error",
    "primitive_halfspaces",
    "solid_pieces",
    "split_convex",
]
