"""Joint-space motion planners on OMPL 2: T-RRT (written here), OMPL's RRTConnect, and time parametrisation.

Modules: :mod:`.space` (OMPL state space and validity from python callables),
:mod:`.trrt` (Transition-based RRT), :mod:`.ompl_planners` (OMPL's own planners),
:mod:`.blended` (time-optimal timing through all waypoints with toppra, corners blended within the checked band),
:mod:`.timing` (the rest-to-rest trapezoid at every waypoint: the old timing, kept as reference and fall-back),
:mod:`.interpolate` (path densification and re-checking), :mod:`.toyworld`
(joint-space box/sphere worlds for tests and benchmarks).
"""
