"""Joint-space motion planners on OMPL 2: T-RRT (written here) and OMPL's RRTConnect.

Modules: :mod:`.space` (OMPL state space and validity from python callables),
:mod:`.query` (settings, query checks and path finishing every planner here shares),
:mod:`.trrt` (Transition-based RRT) with :mod:`.tree` (its trees and batched checks),
:mod:`.shortcut` (batched path shortening), :mod:`.ompl_planners` (OMPL's own planners),
:mod:`.toyworld` (joint-space box/sphere worlds for tests and benchmarks). Interpolation, batching
and time parametrisation are the core's (:mod:`asmteach.core.trajectory`), shared with the other planners.

The planners never see a robot: validity and cost come as callables (with an
optional ``.batch``), which an assembly planner builds on the
:class:`~asmteach.core.robot.PlanningScene` value of the motion (the regrasp
planner's ``motions.Checker``), so a query answers for that scene whatever
else has been asked meanwhile.
"""
