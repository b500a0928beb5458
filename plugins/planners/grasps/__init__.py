"""Antipodal parallel-jaw grasp planning, filtering at a pose, and a physical hold check.

Modules, one job each: :mod:`.sampling` (contact pairs by ray casting),
:mod:`.antipodal` (friction cones and force closure; the hand's boxes and
collision are :mod:`asmteach.core.hand_geometry`), :mod:`.checks` (input validation), :mod:`.planner`
(the ``antipodal`` plugin), :mod:`.filtering` (IK and collision at a part
pose), :mod:`.render` (PNGs), :mod:`.hold_check` (PyBullet lift-and-shake),
:mod:`.commands` (``asmteach grasps``) and :mod:`.experiment` (``grasp_hold``).
"""
