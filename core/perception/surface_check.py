"""What the camera should see of a posed model, against what it saw: rays from the eye to the model surface.

:func:`ray_depths` casts rays from the eye at the model's ray-casting scene (part frame, metres);
:func:`surface_check` is verification's model-to-scene test (is the surface the model shows the camera at a pose
where the camera saw one?), and :func:`ray_plane` maps rays to a plane one metre ahead so rays close in angle are
close points. Split out of :mod:`asmteach.core.perception.registration`, which uses them in ``verify``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry

import open3d as o3d  # isort: skip

if TYPE_CHECKING:
    from asmteach.core.perception.registration import ModelCloud

__all__ = ["SurfaceCheck", "ray_depths", "ray_plane", "surface_check"]


def ray_depths(model: ModelCloud, eye: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(t_hit, dist)`` along the rays from ``eye`` through ``points`` (both part frame, metres).

    ``t_hit`` is where each ray first meets the model (``inf`` where it misses),
    ``dist`` how far the point is from the eye: the depth the model predicts
    against the depth seen.
    """
    d = np.asarray(points, float) - eye
    dist = np.linalg.norm(d, axis=1)
    rays = np.hstack([np.broadcast_to(eye, d.shape), d / dist[:, None]]).astype(np.float32)
    return model.scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy(), dist


@dataclass
class SurfaceCheck:
    """What the camera saw along the rays to the model surface the pose says it should see.

    Counts of the model's surface samples visible from the camera at the pose
    (facing it, not hidden by the part itself, incidence below the grazing
    limit), by what the nearest observed ray (within ``ray_radius``) saw.
    """

    visible: int
    explained: int
    """the seen depth is within ``fit`` of the model's"""
    seen_through: int
    """the camera saw farther than the model's surface by more than ``off``: the model is not there"""
    in_front: int
    """something nearer than the model's surface by more than ``off`` hides it (no evidence either way)"""
    missing: int
    """no observed ray near it (a dropout; no evidence either way)"""

    @property
    def coverage(self) -> float:
        """Share of the model's visible surface with evidence that the seen depth explains (0 with no evidence)."""
        judged = self.visible - self.in_front - self.missing
        return self.explained / judged if judged > 0 else 0.0

    @property
    def contradicted(self) -> float:
        """Share of the model's visible surface with evidence where the camera saw through it."""
        judged = self.visible - self.in_front - self.missing
        return self.seen_through / judged if judged > 0 else 1.0


def ray_plane(direction: np.ndarray) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The unit ``axis`` along ``direction`` and the map of rays to a plane 1 m along it.

    ``plane(u)`` takes ``(n, 3)`` ray directions from the eye (any length, ahead of it) to ``(n, 2)``
    points where they cross the plane ``axis . x = 1`` (metres), so rays close in angle are close there.
    """
    axis = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    basis = np.column_stack([e1, np.cross(axis, e1)])

    def plane(u: np.ndarray) -> np.ndarray:
        return (u @ basis) / (u @ axis)[:, None]

    return axis, plane


def surface_check(
    T_part_world: np.ndarray,
    context: np.ndarray,
    viewpoint: np.ndarray,
    model: ModelCloud,
    *,
    fit: float,
    off: float,
    ray_radius: float,
    max_incidence_deg: float,
) -> SurfaceCheck:
    """Model-to-scene check: is the surface the model shows the camera at this pose where the camera saw one?"""
    from scipy.spatial import cKDTree

    eye = geometry.transform_points(T_part_world, np.asarray(viewpoint, float)[None])[0]
    pts, nrm = model.points, model.normals
    d = pts - eye
    dist = np.linalg.norm(d, axis=1)
    unit = d / dist[:, None]
    cos_inc = -np.einsum("ij,ij->i", unit, nrm)
    cand = cos_inc > np.cos(np.radians(max_incidence_deg))
    hit, _ = ray_depths(model, eye, pts[cand])
    vis = np.flatnonzero(cand)[hit > dist[cand] - 1e-3]
    if len(vis) == 0 or len(context) == 0:
        return SurfaceCheck(len(vis), 0, 0, 0, len(vis))
    # Rays as points of a plane one metre in front of the eye, facing the part: nearest ray = nearest pixel.
    axis, plane = ray_plane(model.center - eye)
    obs = geometry.transform_points(T_part_world, context) - eye
    asked = plane(unit[vis])
    # Only a seen ray within ray_radius of some model ray can answer: keep those inside the model rays'
    # bounding box grown by ray_radius (a superset of every answer, so each nearest ray within the bound is
    # the same). The tree then holds the few hundred rays around the part, not the ~12 000 seen points of
    # the context (table mostly): building it was half of verify's time.
    lo, hi = asked.min(axis=0) - 1.01 * ray_radius, asked.max(axis=0) + 1.01 * ray_radius
    # The box lies within the cone tan^2(angle to the axis) <= 2 b^2 (b its largest |coordinate|): the seen
    # rays outside it (most of the context) are dropped before their projection; the slack only keeps more.
    along, sq = obs @ axis, np.einsum("ij,ij->i", obs, obs)
    b2 = 2.0 * float(np.max(np.maximum(np.abs(lo), np.abs(hi)))) ** 2 * (1.0 + 1e-6) + 1e-12
    obs = obs[(along > 0) & (sq - along * along <= b2 * along * along)]
    obs_dist = np.linalg.norm(obs, axis=1)
    seen = plane(obs / obs_dist[:, None])
    keep = np.flatnonzero(np.all((seen >= lo) & (seen <= hi), axis=1))
    if len(keep) == 0:
        return SurfaceCheck(len(vis), 0, 0, 0, len(vis))
    obs_dist = obs_dist[keep]
    gap, j = cKDTree(seen[keep]).query(asked, distance_upper_bound=ray_radius)
    found = np.isfinite(gap)
    delta = np.full(len(vis), np.nan)
    delta[found] = obs_dist[j[found]] - dist[vis][found]
    explained = int(np.sum(found & (np.abs(delta) <= fit)))
    through = int(np.sum(found & (delta > off)))
    front = int(np.sum(found & (delta < -off)))
    return SurfaceCheck(len(vis), explained, through, front, int(np.sum(~found)))
