"""Stable placements of a part on a table and the placement corrector.

Modules, one job each:

* :mod:`.facets` - convex hull and clustering of coplanar hull faces into support facets;
* :mod:`.stability` - centre-of-mass margin test, toppling graph and probabilities;
* :mod:`.symmetry` - rotational symmetry of a placement about the table normal;
* :mod:`.planner` - :func:`compute_placements` (part -> list of :class:`~asmteach.core.models.Placement`);
* :mod:`.table` - table frame from a :class:`~asmteach.core.models.TablePlane`, plane fitting;
* :mod:`.planar_icp` - x, y, yaw refinement of a model against an observed cloud;
* :mod:`.corrector` - the ``stable_placements`` corrector (paper, Alg. "Noise correction");
* :mod:`.contact_sheet`, :mod:`.commands`, :mod:`.experiment` - PNG, CLI and the trimesh comparison.
"""
