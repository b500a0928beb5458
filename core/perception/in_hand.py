"""Where a held part sits in the hand, as the depth cameras see it.

Before an insertion the robot stops at the pre-insertion pose; the cameras see the part it holds (the robot's
own points are filtered out of every cloud, as a cell's self-filter does). Starting from where the plan
believes the part is (its detection carried through the grasps), point-to-plane ICP of the seen points near
that belief onto the part's surface gives the pose the insertion is re-aimed for. Points nearer another part's
believed surface, or at the table, are not the held part's.

This is what a real cell can measure: no simulator truth is read. A measurement that is not sure (too few
points, a poor fit) returns ``None`` with the reason, and the planned line runs as it is.

Frames: every cloud and pose in the world frame, metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from pydantic import Field
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import StrictModel
from asmteach.core.perception.registration import RefineSettings, icp_refine, model_cloud

__all__ = ["HeldPose", "InHandSettings", "measure_held_pose"]


class InHandSettings(StrictModel):
    """How the held part is cut out of the clouds and registered (metres)."""

    crop: float = Field(0.015, gt=0.0, description="seen points this close to the believed surface are candidates")
    table_clearance: float = Field(0.004, ge=0.0, description="points this close above the table are the table's")
    min_points: int = Field(80, ge=10, description="fewer candidate points than this measure nothing")
    inlier: float = Field(0.003, gt=0.0, description="a point this close to the registered surface is an inlier")
    min_fitness: float = Field(0.85, ge=0.0, le=1.0, description="least inlier share of the candidates")
    max_rmse: float = Field(0.002, gt=0.0, description="largest inlier RMSE, metres")


@dataclass(frozen=True)
class HeldPose:
    """The measurement: ``T_world_part`` when sure, else ``None`` and ``why``."""

    T_world_part: np.ndarray | None
    points: int
    fitness: float
    rmse_mm: float
    why: str | None = None
    information: np.ndarray | None = None
    """``(6, 6)`` information of the registration about a small world-frame motion ``(rotation (rad), shift
    (m))`` about the world origin: a difference ``d`` from another pose is evidence of ``d' I d`` (chi-square,
    6 degrees of freedom at most; turns the view cannot see, e.g. about an axis of revolution, add nothing)."""

    def chi2(self, T_world_other: np.ndarray) -> float:
        """How strongly the measurement says the part is not at ``T_world_other``: ``d' I d`` of the small
        motion ``d`` from the measured pose to it (infinite when nothing was measured)."""
        if self.T_world_part is None or self.information is None:
            return float("inf")
        D = np.asarray(T_world_other, dtype=float) @ geometry.invert(self.T_world_part)
        d = np.concatenate([Rotation.from_matrix(D[:3, :3]).as_rotvec(), D[:3, 3]])
        return float(d @ self.information @ d)

    def short(self) -> dict[str, float | int | str | None]:
        """The figures a report shows."""
        return {
            "points": self.points,
            "fitness": round(self.fitness, 3),
            "rmse_mm": round(self.rmse_mm, 3),
            "why": self.why,
        }


def _surface(mesh: trimesh.Trimesh, T: np.ndarray, n: int = 3000) -> np.ndarray:
    return geometry.transform_points(T, np.asarray(mesh.sample(n, return_index=False, seed=0), dtype=float))


def measure_held_pose(
    clouds: Sequence[np.ndarray],
    mesh: trimesh.Trimesh,
    T_guess: np.ndarray,
    *,
    others: Sequence[tuple[trimesh.Trimesh, np.ndarray]] = (),
    table_height: float | None = None,
    settings: InHandSettings | None = None,
) -> HeldPose:
    """Measure the held part's ``T_world_part`` from ``clouds`` (each ``(n, 3)``, world frame), starting at the
    believed ``T_guess``; ``others`` are the other parts' meshes at their believed poses, ``table_height`` the
    table's plane (metres, world z)."""
    s = settings or InHandSettings()
    pts = np.concatenate([np.asarray(c, dtype=float).reshape(-1, 3) for c in clouds] or [np.empty((0, 3))])
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if table_height is not None:
        pts = pts[pts[:, 2] > table_height + s.table_clearance]
    d_self, _ = cKDTree(_surface(mesh, T_guess)).query(pts, distance_upper_bound=s.crop)
    near = np.isfinite(d_self)
    pts, d_self = pts[near], d_self[near]
    for other, T_other in others:
        d_other, _ = cKDTree(_surface(other, T_other)).query(pts)
        keep = d_other > d_self
        pts, d_self = pts[keep], d_self[keep]
    if len(pts) < s.min_points:
        return HeldPose(
            None, len(pts), 0.0, float("nan"), f"{len(pts)} points seen of the held part (< {s.min_points})"
        )
    model = model_cloud(mesh, 4000)
    refine = RefineSettings(icp_coarse_distance=s.crop, icp_fine_distance=s.inlier)
    T = icp_refine(pts, model, T_guess, refine)
    local = geometry.transform_points(geometry.invert(T), pts)
    d, nearest = cKDTree(model.points).query(local)
    inl = d <= s.inlier
    fitness = float(inl.mean())
    rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("inf")
    if fitness < s.min_fitness or rmse > s.max_rmse:
        why = f"the fit is poor: {100 * fitness:.0f}% of {len(pts)} points on the surface, RMSE {1000 * rmse:.2f} mm"
        return HeldPose(None, len(pts), fitness, 1000.0 * rmse, why)
    info = _information(pts[inl], model.normals[nearest[inl]], T, rmse)
    return HeldPose(T, len(pts), fitness, 1000.0 * rmse, information=info)


def _information(pts: np.ndarray, normals: np.ndarray, T: np.ndarray, sigma: float, voxel: float = 0.003) -> np.ndarray:
    """Point-to-plane information ``J' J / sigma^2`` of the inliers ``pts`` (world) at ``T``, with the part-frame
    ``normals`` of the model samples nearest them, one point per ``voxel`` (metres): neighbouring depth pixels
    share their error, so counting each would overstate it."""
    keys = np.floor(pts / voxel).astype(np.int64)
    _, first = np.unique(keys, axis=0, return_index=True)
    keep = np.sort(first)
    p = pts[keep]
    n = normals[keep] @ T[:3, :3].T
    J = np.hstack([np.cross(p, n), n])
    return J.T @ J / max(sigma, 1e-4) ** 2
