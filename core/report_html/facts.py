"""What the report page and the console summary both show: values as text, poses in mm and deg, errors of a
detection against the true pose, and the robot's clock."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from typing import Any

import numpy as np

from asmteach.core import geometry
from asmteach.core.models import Detection, RunReport
from asmteach.core.pose_error import pose_error

TRUE_POSE_KEYS: tuple[str, ...] = ("T_world_part_true", "T_world_true", "T_true")
"""Keys of ``Detection.details`` read as the true ``T_world_part`` (4x4, metres), first found wins."""


def format_value(value: Any, width: int = 160) -> str:
    """Compact text of a report value (floats to 4 significant digits)."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple | dict):
        text = json.dumps(value, default=str, separators=(", ", ": "))
        if isinstance(value, list | tuple) and all(isinstance(v, int | float) for v in value):
            text = "[" + ", ".join(format_value(v) for v in value) + "]"
    else:
        text = str(value)
    return text if len(text) <= width else text[: width - 1] + "…"


def vector_text(values: Iterable[float], digits: int = 2) -> str:
    return ", ".join(f"{v:+.{digits}f}" for v in values)


def pose_text(T: np.ndarray) -> tuple[str, str]:
    """``("x, y, z" in mm, "roll, pitch, yaw" in deg)`` of a 4x4 transform."""
    p = geometry.to_xyz_mm_rpy_deg(T)
    return vector_text(p["xyz_mm"]), vector_text(p["rpy_deg"])


def true_pose(det: Detection) -> np.ndarray | None:
    """The true ``T_world_part`` stored in ``det.details``, or None (also when malformed)."""
    for key in TRUE_POSE_KEYS:
        if key in det.details:
            try:
                T = np.asarray(det.details[key], dtype=float).reshape(4, 4)
            except (TypeError, ValueError):
                return None
            return T if np.all(np.isfinite(T)) else None
    return None


def recorded_errors(det: Any, label: str, T: np.ndarray, T_true: np.ndarray) -> dict[str, Any]:
    """:func:`~asmteach.core.pose_error.pose_error` of ``T`` against ``T_true`` as a dict, with distance and
    angle as the run recorded them (modulo the part's symmetries)."""
    err = pose_error(T, T_true).as_dict()
    rec = det.details.get(f"{label}_error") or {}
    err["position_mm"] = rec.get("position_mm", err["position_mm"])
    err["angle_deg"] = rec.get("angle_deg", err["angle_deg"])
    return err


ROBOT_KINDS = ("transit", "approach", "insertion", "regrasp")


def robot_clock(report: RunReport) -> dict[str, float]:
    """The robot seconds to show: those executed, else the plan's (seconds of simulated motion)."""
    if report.robot_seconds:
        return dict(report.robot_seconds)
    planned = report.plan_stats.get("robot_seconds")
    return dict(planned) if isinstance(planned, dict) else {}
