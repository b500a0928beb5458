"""CVFH + CRH + ICP depth detector (``cvfh_icp``; paper: "Rough detection using point cloud").

Modules, one job each: :mod:`.segment` (input checks, table plane, clusters),
:mod:`.views` (the cached 42-view database), :mod:`.refine` (ICP and
hypothesis verification, shared with ``fpfh_ransac``), :mod:`.detector` (the
plugin), :mod:`.scenes` (synthetic table scenes), :mod:`.commands`
(``asmteach detect``), :mod:`.experiment` (``detection_precision``). The
descriptors (VFH, CVFH, CRH) live in :mod:`.descriptors`.
"""
