"""What the execution phase sees: the table plane, detections, corrections and the parts' resting placements."""

from __future__ import annotations

from typing import Any

import numpy as np
from pydantic import Field

from asmteach.core.models.base import FloatArray, Mat4, StrictModel, Vec3

__all__ = ["Correction", "Detection", "Placement", "TablePlane"]


class TablePlane(StrictModel):
    """The supporting plane: points ``p`` with ``normal . p = height`` (world frame)."""

    height: float = Field(0.0, description="metres along the normal")
    normal: Vec3 = Field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))


class Detection(StrictModel):
    """Result of detecting one part in a depth cloud (world frame, metres)."""

    part: str
    found: bool
    reason: str | None = Field(None, description="why nothing was found; None when found")
    rough: Mat4 | None = Field(None, description="T_world_part from the detector")
    corrected: Mat4 | None = Field(None, description="T_world_part after the corrector")
    fitness: float | None = Field(None, description="ICP inlier fraction; higher is better")
    inlier_rmse: float | None = Field(None, description="metres; lower is better")
    timing_ms: dict[str, float] = Field(default_factory=dict)
    details: dict[str, Any] = Field(default_factory=dict)

    @property
    def best(self) -> np.ndarray | None:
        """The corrected pose when there is one, else the rough one."""
        return self.corrected if self.corrected is not None else self.rough


class Correction(StrictModel):
    """A corrector's output: the corrected pose and the placement it snapped to."""

    T_world_part: Mat4
    placement_id: int | None = None
    details: dict[str, Any] = Field(default_factory=dict)


class Placement(StrictModel):
    """A stable resting pose of a part on a horizontal table at z = 0.

    ``T_table_part`` puts the part on the table (lowest point at z = 0) with
    the placement's canonical yaw; any yaw about the table normal and any
    x, y translation of it are the same placement.
    """

    id: int
    T_table_part: Mat4
    probability: float = Field(ge=0.0, le=1.0)
    margin: float = Field(description="stability margin d / h (dimensionless)")
    support_polygon: FloatArray = Field(description="(n, 2) support polygon in the table frame, metres")
    symmetry_yaws: list[float] = Field(default_factory=lambda: [0.0], description="radians; equivalent yaws")
