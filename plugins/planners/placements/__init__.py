"""Stable placements of a part on a table and the placement corrector.

Modules, one job each:

* the placements themselves are computed in core (:mod:`asmteach.core.rests`: hull facets,
  stability, probabilities, symmetry), shared with the grasp and regrasp planners and the detectors;
* :mod:`.drop_test` - PyBullet drops and tilted releases that check the stability rule (in :mod:`.drop_world`);
* :mod:`.table` - table frame from a :class:`~asmteach.core.models.TablePlane`, plane fitting;
* :mod:`.planar_icp` - x, y, yaw refinement of a model against an observed cloud;
* :mod:`.corrector` - the ``stable_placements`` corrector (paper, Alg. "Noise correction");
* :mod:`.contact_sheet`, :mod:`.commands`, :mod:`.experiment` - PNG, CLI and the trimesh comparison.
"""
