"""Joint-path tools every planner and robot shares: batched per-configuration checks and cost maps
(:mod:`.batch`), interpolation (:mod:`.interpolate`), time parametrisation (:mod:`.timing`, rest to rest;
:mod:`.blended`, time-optimal through blended corners). Joint values in radians, times in seconds."""
