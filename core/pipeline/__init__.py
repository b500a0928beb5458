"""The whole pipeline in simulation: teach, spawn, sense, detect, correct, grasp, plan, execute, measure.

Every stage calls the configured plugin through its role interface only;
hooks announce each stage (progress bars, reporters). A stage that fails ends
the run as a *result*: ``report.json`` records the stage and the reason, and
everything written so far stays valid (all writes are atomic).

Frames and units: world frame z up, metres and radians inside; reports in mm
and degrees. ``T_A_B`` is B's pose in A's frame; errors of the achieved
assembly are measured in A's frame from the simulator's poses.

The package, one module a step: :mod:`.run` (:func:`run_pipeline`, the order
of the stages), :mod:`.stage` (the run's state, each stage's timing and
record, :class:`StageFailed`), :mod:`.teach`, :mod:`.detect` (spawn, sense,
detect), :mod:`.plan` (grasps, plan, look again), :mod:`.execute` (execution,
its trace, the animation), :mod:`.measure` (the achieved assembly, success)
and :mod:`.report` (clocks, figures, report.json and report.html).
"""

from __future__ import annotations

from asmteach.core.pipeline.run import run_pipeline
from asmteach.core.pipeline.stage import StageFailed

__all__ = ["StageFailed", "run_pipeline"]
