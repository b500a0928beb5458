"""Antipodal parallel-jaw grasp planning, filtering at a pose, and a physical hold check.

Modules, one job each: :mod:`.sampling` (contact pairs by ray casting),
:mod:`.antipodal` (friction cones and force closure), :mod:`.contact` (the
soft-pad contact model), :mod:`.checks` (input validation), :mod:`.settings`
(the planner's settings), :mod:`.selection` (buckets by approach and resting
pose, round robin, duplicates and collisions), :mod:`.planner` (the
``antipodal`` plugin), :mod:`.filtering` (IK and collision at a part pose),
:mod:`.render` (PNGs), :mod:`.hold_check` (PyBullet lift-and-shake),
:mod:`.commands` (``asmteach grasps``) and :mod:`.experiment`
(``grasp_hold``). The hand's boxes and collider are
:mod:`asmteach.core.hand_geometry`; the resting poses :mod:`asmteach.core.rests`.
"""
