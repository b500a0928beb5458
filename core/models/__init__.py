"""Data contracts shared by every stage, as pydantic v2 models.

All models forbid unknown keys and round-trip through JSON
(``Model.model_validate_json(m.model_dump_json())``). Poses are ``(4, 4)``
numpy arrays inside and 4x4 row-major nested lists in JSON; in hand-written
YAML a pose may also be given as ``{xyz: [m, m, m], rpy_deg: [deg, deg, deg]}``.
Units: metres, radians, kilograms, seconds; millimetres and degrees only in
report fields whose names say so (``*_mm``, ``*_deg``).

The package, one module a subject: :mod:`.base` (:class:`StrictModel` and the
array field types), :mod:`.parts` (part specs and their markers),
:mod:`.task` (the taught assembly task, the camera), :mod:`.detection` (table
plane, detections, corrections, resting placements), :mod:`.grasp` (the
gripper and its grasps), :mod:`.plan` (trajectories, gripper events, plans)
and :mod:`.report` (stage outcomes, the run report).
"""

from __future__ import annotations

from asmteach.core.models.base import FloatArray, Mat3, Mat4, StrictModel, Unit, Vec3
from asmteach.core.models.detection import Correction, Detection, Placement, TablePlane
from asmteach.core.models.grasp import Grasp, HandSpec
from asmteach.core.models.parts import MarkerSpec, PartSpec, Primitive, SolidSpec, resolve_relative
from asmteach.core.models.plan import GripperEvent, Plan, PlanSegment, Trajectory
from asmteach.core.models.report import RunReport, StageOutcome
from asmteach.core.models.task import AssemblyTask, CameraIntrinsics, TeachingEvidence

__all__ = [
    "AssemblyTask",
    "CameraIntrinsics",
    "Correction",
    "Detection",
    "FloatArray",
    "Grasp",
    "GripperEvent",
    "HandSpec",
    "MarkerSpec",
    "Mat3",
    "Mat4",
    "PartSpec",
    "Placement",
    "Plan",
    "PlanSegment",
    "Primitive",
    "RunReport",
    "SolidSpec",
    "StageOutcome",
    "StrictModel",
    "TablePlane",
    "TeachingEvidence",
    "Trajectory",
    "Unit",
    "Vec3",
    "resolve_relative",
]
