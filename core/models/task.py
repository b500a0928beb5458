"""The assembly task a teacher learns (T_A_B, v_a), the camera it watched with and what it saw."""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from asmteach.core.models.base import Mat3, Mat4, StrictModel, Vec3, finite_array
from asmteach.core.models.parts import PartSpec

__all__ = ["AssemblyTask", "CameraIntrinsics", "TeachingEvidence"]


class CameraIntrinsics(StrictModel):
    """Pinhole camera with OpenCV distortion ``(k1, k2, p1, p2[, k3, ...])``."""

    K: Mat3 = Field(description="3x3 camera matrix, pixels")
    dist: list[float] = Field(default_factory=lambda: [0.0] * 5, description="OpenCV distortion coefficients")
    width: int = Field(gt=0, description="image width, pixels")
    height: int = Field(gt=0, description="image height, pixels")

    @field_validator("K")
    @classmethod
    def _focal(cls, K: np.ndarray) -> np.ndarray:
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise ValueError(f"the focal lengths fx, fy must be > 0 pixels (got {K[0, 0]:g}, {K[1, 1]:g})")
        return K

    @field_validator("dist")
    @classmethod
    def _finite_dist(cls, d: list[float]) -> list[float]:
        finite_array(d, "distortion coefficients")
        return d

    @property
    def dist_array(self) -> np.ndarray:
        """Distortion coefficients as a float array (OpenCV's layout)."""
        return np.asarray(self.dist, dtype=float)


class TeachingEvidence(StrictModel):
    """What the teacher saw: frames used and how consistent they were."""

    frames_total: int = 0
    frames_used: list[int] = Field(default_factory=list)
    residuals_px: list[float] = Field(default_factory=list, description="per used frame, RMS reprojection error")
    spread_mm: float | None = Field(None, description="spread (robust std) of the fused translation")
    spread_deg: float | None = Field(None, description="spread of the fused rotation")
    insertion_source: Literal["demonstration", "geometric", "given"] = "given"
    notes: list[str] = Field(default_factory=list)


class AssemblyTask(StrictModel):
    """Two parts and how B sits in A: ``T_A_B`` and the insertion direction ``v_a``.

    ``v_a`` is a unit vector in A's frame along which B moves *into* its
    assembled pose; the pre-assembly pose of B is ``T_A_B`` translated by
    ``-retract * v_a``.
    """

    name: str
    part_a: PartSpec
    part_b: PartSpec
    T_A_B: Mat4
    v_a: Vec3
    evidence: TeachingEvidence | None = None

    @field_validator("v_a")
    @classmethod
    def _unit(cls, v: np.ndarray) -> np.ndarray:
        n = float(np.linalg.norm(v))
        if n < 1e-9:
            raise ValueError("v_a must be a non-zero direction")
        return v / n

    @model_validator(mode="after")
    def _unique_markers(self) -> AssemblyTask:
        a = {m.id for m in self.part_a.markers}
        b = {m.id for m in self.part_b.markers}
        both = sorted(a & b)
        if both:
            raise ValueError(
                f"marker ids {both} are used on both {self.part_a.name!r} and {self.part_b.name!r}; "
                "give each marker of a structure its own id"
            )
        return self
