"""Joint-path tools every planner and robot shares.

Batched per-configuration checks and cost maps (:mod:`.batch`), interpolation
(:mod:`.interpolate`), time parametrisation (:mod:`.timing`, rest to rest;
:mod:`.blended`, time-optimal through the corners :mod:`.blended_path` rounds).
Joint values in radians, times in seconds.
"""
