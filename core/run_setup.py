"""The one loader of a run: every object ``asmteach run`` needs, built and checked before any work starts.

``asmteach validate`` and ``asmteach run`` both call :func:`load_run` (the
pipeline calls :func:`prepare_run` on a config it is handed), so a config
that validates is a config whose run starts: the structure and both parts
(meshes in metres, closed, centre of mass inside), the markers, the camera
and the ``demo`` section (the teacher plugin's ``DemoSettings``, and its own
check of what a demonstration needs), the ``execution`` section
(:class:`~asmteach.core.config.ExecutionSettings`), the table and every
plugin's settings. Any problem is one :class:`UserError` line naming
the key path (exit 2).

Path rule, the same everywhere: a path is relative to the folder of the
file that names it (``structure``/``camera`` to the run config, ``part_a``
to the structure file, a ``mesh`` to its part file).

Table: ``table.center`` / ``table.size`` (world x, y, metres), when given
(not null), are handed to the robot plugin's ``table_center`` /
``table_size`` settings (and ``table.height`` to its ``table_height``), so
the simulated table, the collision checks and the run agree on one table;
left null, the robot's own table is the run's. :attr:`RunSetup.table` is the
one table plane every stage of the run uses. The parts' start region
(``execution.scene``) must lie on that table with room for the parts.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel

from asmteach.core import registry
from asmteach.core.config import ExecutionSettings, RunConfig, check_plugin_choices, load_run_config, validate_settings
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel, Teacher
from asmteach.core.models import AssemblyTask, TablePlane
from asmteach.core.parts import build_part, load_structure

__all__ = ["RunSetup", "load_run", "prepare_run", "table_of_robot"]


@dataclass
class RunSetup:
    """Everything a run is built from, checked (world frame, metres)."""

    cfg: RunConfig
    """The config, with the table handed to the robot's settings."""
    task: AssemblyTask
    """The true structure (ground truth of the simulated demonstration)."""
    part_a: PartModel
    part_b: PartModel
    execution: ExecutionSettings
    """The ``execution`` section (the same object as ``cfg.execution``)."""
    demo: BaseModel | None
    """The ``demo`` section as the teacher's own model; None when the teacher checks none."""
    camera_file: Path | None
    table: TablePlane
    """The table plane of the run (top at ``cfg.table.height``, world z, metres): every stage uses this one."""
    table_center: tuple[float, float] | None
    """The robot's table centre x, y (metres), when the robot plugin has one."""
    table_size: tuple[float, float] | None
    """The robot's table extent along x, y (metres), when the robot plugin has one."""

    def summary(self) -> str:
        """One line of what was loaded, for ``asmteach validate``."""
        parts = ", ".join(
            f"{p.name} ({1000 * float(max(p.mesh.extents)):.0f} mm, {1000 * p.mass:.0f} g, "
            f"{len(p.spec.markers)} markers)"
            for p in (self.part_a, self.part_b)
        )
        table = (
            f"table {self.table_size[0]:.2f} x {self.table_size[1]:.2f} m at ({self.table_center[0]:.2f}, "
            f"{self.table_center[1]:.2f})"
            if self.table_center and self.table_size
            else "the robot's table"
        )
        return f"structure {self.task.name}: {parts}; {table}, top at z = {self.table.height:.3f} m"


def load_run(path: str | Path, overrides: dict[str, Any] | None = None) -> RunSetup:
    """Read a run config and build everything its run needs (:func:`prepare_run`); errors name the file."""
    cfg = load_run_config(path, overrides=overrides)
    try:
        return prepare_run(cfg)
    except UserError as exc:
        msg = str(exc)
        raise UserError(msg if msg.startswith(str(path)) else f"{path}: {msg}") from None


def prepare_run(cfg: RunConfig) -> RunSetup:
    """Build and check every object of ``cfg``'s run; :class:`UserError` (one line) on the first problem.

    The config returned in :attr:`RunSetup.cfg` is a copy whose robot
    settings carry the table; ``cfg`` itself is not changed.
    """
    cfg = cfg.model_copy(deep=True)
    check_plugin_choices(cfg)  # plugins and their settings (load_run_config does so too, if asked)
    execution = cfg.execution
    _check_scene(execution)

    structure = cfg.path(cfg.structure)
    if not structure.is_file():
        what = "not a file" if structure.exists() else "no such file"
        raise UserError(f"structure: {what} {structure} (relative to the config's folder); give a structure YAML")
    task = load_structure(structure)
    parts = []
    for key, spec in (("part_a", task.part_a), ("part_b", task.part_b)):
        try:
            parts.append(build_part(spec))
        except UserError as exc:
            raise UserError(f"{structure.name}: {key} ({spec.name}): {exc}") from None
    part_a, part_b = parts
    _check_contact(task, part_a, part_b, structure)
    for key, part in (("part_a", part_a), ("part_b", part_b)):
        _check_markers_on_surface(key, part, structure)

    camera_file = cfg.path(cfg.camera) if cfg.camera else None
    if camera_file is not None and not camera_file.is_file():
        what = "not a file" if camera_file.exists() else "no such file"
        raise UserError(f"camera: {what} {camera_file} (relative to the config's folder); give a camera YAML")
    demo = _check_teacher(cfg, task, camera_file)

    center, size = _hand_table_to_robot(cfg)
    if center is not None and size is not None:
        _check_start_region(execution, (part_a, part_b), center, size)
    return RunSetup(
        cfg=cfg,
        task=task,
        part_a=part_a,
        part_b=part_b,
        execution=execution,
        demo=demo,
        camera_file=camera_file,
        table=TablePlane(height=cfg.table.height),
        table_center=center,
        table_size=size,
    )


def _check_teacher(cfg: RunConfig, task: AssemblyTask, camera_file: Path | None) -> BaseModel | None:
    """The teacher's own check of what its demonstration needs (``demo`` section, camera, markers).

    A teacher plugin offers it as a class method ``check_demonstration(task, demo, camera_file)`` returning
    its model of the ``demo`` section. A teacher without one (or that renders no demonstration: the run
    then fails at ``teach`` with the reason in its report) is not checked here.
    """
    cls = registry.get_class("teachers", cfg.teacher.plugin)
    check = getattr(cls, "check_demonstration", None)
    if check is None or getattr(cls, "demonstrate", Teacher.demonstrate) is Teacher.demonstrate:
        return None
    return check(task, cfg.demo, camera_file)


CONTACT_GAP_M = 0.01
"""Largest gap (metres) between A's and B's bounding boxes when assembled: an assembled B touches A."""


def _check_contact(task: AssemblyTask, a: PartModel, b: PartModel, structure: Path) -> None:
    """``T_A_B`` must put B against A (their boxes within :data:`CONTACT_GAP_M`); far apart is a unit slip
    (millimetres written as metres) or a wrong frame, and the demonstration would not show both parts."""
    va = np.asarray(a.mesh.vertices, float)
    T = np.asarray(task.T_A_B, float)
    vb = np.asarray(b.mesh.vertices, float) @ T[:3, :3].T + T[:3, 3]
    gap = np.maximum(0.0, np.maximum(va.min(axis=0) - vb.max(axis=0), vb.min(axis=0) - va.max(axis=0)))
    dist = float(np.linalg.norm(gap))
    if dist > CONTACT_GAP_M:
        raise UserError(
            f"{structure.name}: T_A_B puts {b.name} {1000 * dist:.0f} mm away from {a.name}; assembled, "
            "B touches A (T_A_B is B's pose in A's frame in metres: millimetres written as metres?)"
        )


MARKER_OFF_SURFACE_M = 0.002
"""Largest distance (metres) of a marker's centre from its part's surface: a marker is printed on a face."""


def _check_markers_on_surface(key: str, part: PartModel, structure: Path) -> None:
    """Each marker's centre must lie on the part's surface (within :data:`MARKER_OFF_SURFACE_M`)."""
    if not part.spec.markers:
        return
    centres = np.array([np.asarray(m.T_part_marker, float)[:3, 3] for m in part.spec.markers])
    _, dist, _ = part.mesh.nearest.on_surface(centres)
    for i, d in enumerate(np.asarray(dist, float)):
        if d > MARKER_OFF_SURFACE_M:
            raise UserError(
                f"{structure.name}: {key}.markers[{i}] (id {part.spec.markers[i].id}): its centre is "
                f"{1000 * d:.0f} mm off {part.name}'s surface; a marker is printed on a face "
                "(T_part_marker is in the part frame, metres)"
            )


def _check_scene(ex: ExecutionSettings) -> None:
    """The start region's ranges: low <= high, finite, |y| ranges not negative (metres)."""
    for name in ("x_range", "y_range"):
        lo, hi = getattr(ex.scene, name)
        if not (math.isfinite(lo) and math.isfinite(hi)):
            raise UserError(f"execution.scene.{name}: not a finite number (NaN or infinity); write numbers")
        if lo > hi:
            raise UserError(f"execution.scene.{name}: [{lo:g}, {hi:g}] runs backwards; write [low, high] in metres")
    if ex.scene.y_range[0] < 0:
        raise UserError(
            "execution.scene.y_range: it is a range of |y| (the parts start on both sides); write it with values >= 0"
        )


def table_of_robot(cfg: RunConfig) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """The robot plugin's table centre and size (metres) after its settings are validated; None if it has none."""
    cls = registry.get_class("robots", cfg.robot.plugin)
    st = validate_settings(cls, cfg.robot.settings, where="robot.settings")
    center, size = getattr(st, "table_center", None), getattr(st, "table_size", None)
    return (
        None if center is None else (float(center[0]), float(center[1])),
        None if size is None else (float(size[0]), float(size[1])),
    )


def _hand_table_to_robot(cfg: RunConfig) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """Put ``table.center/size/height`` into ``cfg.robot.settings`` (in place); return the robot's table.

    A robot plugin without such settings cannot honour a given centre or
    size: that is an error, not a silent default. The same value given in
    both places is fine; two different values are refused.
    """
    cls = registry.get_class("robots", cfg.robot.plugin)
    fields = cls.Settings.model_fields
    settings = copy.deepcopy(cfg.robot.settings)
    given = {"table_center": cfg.table.center, "table_size": cfg.table.size}
    for key, value in given.items():
        if value is None:  # left to the robot: it keeps its own table
            continue
        short = key.removeprefix("table_")
        if key not in fields:
            raise UserError(
                f"table.{short}: the robot plugin {cfg.robot.plugin!r} has no table of its own "
                f"({key} is not one of its settings); remove table.{short}"
            )
        if key in settings and not np.allclose(np.asarray(settings[key], float), np.asarray(value, float)):
            raise UserError(
                f"table.{short} {list(value)} and robot.settings.{key} {list(settings[key])} differ; "
                f"give the table once, under table.{short}"
            )
        settings[key] = [float(v) for v in value]
    if "table_height" in fields:
        if "table_height" in settings and not math.isclose(float(settings["table_height"]), cfg.table.height):
            raise UserError(
                f"table.height {cfg.table.height:g} and robot.settings.table_height "
                f"{settings['table_height']} differ; give the height once, under table.height"
            )
        if "table_height" in settings or cfg.table.height != 0.0:
            settings["table_height"] = float(cfg.table.height)
    cfg.robot.settings = settings
    return table_of_robot(cfg)


def _part_radius(part: PartModel) -> float:
    """Largest distance (metres) of the part's surface from its bounding-box centre: its footprint in any pose."""
    v = np.asarray(part.mesh.vertices, float)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return float(np.max(np.linalg.norm(v - centre, axis=1)))


def _check_start_region(
    ex: ExecutionSettings, parts: tuple[PartModel, PartModel], center: tuple[float, float], size: tuple[float, float]
) -> None:
    """The parts' start region, grown by the larger part's radius, must lie on the table (world x, y, metres)."""
    r = max(_part_radius(p) for p in parts)
    (x0, x1), (y0, y1) = ex.scene.x_range, ex.scene.y_range
    tx0, tx1 = center[0] - 0.5 * size[0], center[0] + 0.5 * size[0]
    ty0, ty1 = center[1] - 0.5 * size[1], center[1] + 0.5 * size[1]
    # Parts start at +-y (one on each side), so both signs of the |y| range must fit.
    if x0 - r < tx0 or x1 + r > tx1 or -y1 - r < ty0 or y1 + r > ty1:
        raise UserError(
            f"table: the parts start at x {x0:g}..{x1:g} m, |y| {y0:g}..{y1:g} m (execution.scene) and reach "
            f"{1000 * r:.0f} mm around that, off the table x {tx0:.3g}..{tx1:.3g} m, y {ty0:.3g}..{ty1:.3g} m "
            "(table.center, table.size); move or enlarge the table, or narrow execution.scene"
        )
