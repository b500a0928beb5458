"""ArUco teaching: multi-marker PnP per part, robust fusion over frames, learned insertion direction.

Modules, one job each: :mod:`.markers` (dictionaries, marker object points),
:mod:`.detect` (marker detection per frame), :mod:`.pnp` (per-part pose from
all visible markers), :mod:`.fusion` (rotation / translation averaging),
:mod:`.insertion` (``v_a`` from the approach, python-fcl check, geometric
fallback), :mod:`.teacher` (the ``aruco`` Teacher plugin), :mod:`.camera`
(intrinsics files), :mod:`.render` and :mod:`.scene` (synthetic
demonstrations), :mod:`.calibrate` (ChArUco), :mod:`.commands` (CLI) and
:mod:`.experiment` (precision sweeps).
"""
