"""The roles of the pipeline as small abstract classes.

A plugin is a subclass of one of these, registered under the role's
entry-point group (see :mod:`asmteach.core.registry`). Each plugin declares
its own pydantic ``Settings`` model (unknown keys forbidden); the config names
the plugin and carries those settings, and the registry builds the plugin as
``PluginClass(settings, seed=seed)``.

Frames: ``T_world_*`` poses are in the world frame (z up, metres); parts are
described in their own part frame (see :class:`PartModel`).

One module a role family: :mod:`~asmteach.core.interfaces.plugin` (the base),
:mod:`~asmteach.core.interfaces.part_model`, :mod:`~asmteach.core.interfaces.perception`
(Teacher, Detector, Corrector), :mod:`~asmteach.core.interfaces.planning` (GraspPlanner,
MotionPlanner, AssemblyPlanner and their values), :mod:`~asmteach.core.interfaces.robot`
(Robot, IKResult, Obstacle). This package gathers them and the registry's :data:`ROLES`.
"""

from __future__ import annotations

from asmteach.core.interfaces.part_model import PartModel
from asmteach.core.interfaces.perception import Corrector, Detector, Teacher
from asmteach.core.interfaces.planning import (
    AssemblyPlanner,
    AssemblyProblem,
    AssemblyResult,
    GraspPlanner,
    MotionPlanner,
    MotionResult,
)
from asmteach.core.interfaces.plugin import NoSettings, Plugin
from asmteach.core.interfaces.robot import IKResult, Obstacle, Robot

__all__ = [
    "ROLES",
    "AssemblyPlanner",
    "AssemblyProblem",
    "AssemblyResult",
    "Corrector",
    "Detector",
    "GraspPlanner",
    "IKResult",
    "MotionPlanner",
    "MotionResult",
    "NoSettings",
    "Obstacle",
    "PartModel",
    "Plugin",
    "Robot",
    "Teacher",
]


ROLES: dict[str, type[Plugin]] = {
    "teachers": Teacher,
    "detectors": Detector,
    "correctors": Corrector,
    "grasp_planners": GraspPlanner,
    "motion_planners": MotionPlanner,
    "robots": Robot,
    "assembly_planners": AssemblyPlanner,
}
"""Entry-point group suffix (``asmteach.<suffix>``) -> the interface its plugins implement."""
