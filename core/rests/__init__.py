"""Stable rests of a part on a table: the one computation every planner, corrector and detector uses.

:mod:`.facets` (convex hull, coplanar hull faces merged into support facets),
:mod:`.stability` (centre-of-mass margin ``d / h``, toppling, landing
probabilities) and :mod:`.placements` (:func:`~.placements.compute_placements`:
one :class:`~asmteach.core.models.Placement` per stable facet with its
rotational symmetry; :func:`~.placements.resting_poses` for random start poses
and resting hypotheses); :mod:`.drops` (trimesh's drop probabilities, from which seeded random scenes
draw a rest). Part frame, metres.
"""
