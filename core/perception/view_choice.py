"""Where a close camera should look from to tell a detection's rival poses apart.

A one-view detection may list rival poses it cannot tell apart (a D peg turned about its axis with the flat out of
sight). A camera on the robot's wrist can look again from close by; this module predicts, before any motion, how
strongly each candidate viewpoint would tell the rivals apart. Candidates sit on a grid around the rivals' centre
(distances, elevations above the table, azimuths), each looking at the centre. For each, rays over the rivals'
bounding sphere are cast against the part at every compared pose, the table plane and any known occluder
(Open3D ray casting, as :mod:`~asmteach.core.perception.second_view` does). A pair of poses differs on a ray by
``min(((r_i - r_j) / sigma(r_i))^2, clip^2)`` (sigma: the sensor's noise at that range,
:func:`~asmteach.core.perception.second_view.range_sigma`), summed over the rays, each weighted by the pixels it
stands for and the frames stacked: the same units as :func:`~asmteach.core.perception.second_view.judge_rivals`'s
cost gaps (squared sigmas). The weakest pair decides a viewpoint's ``separation``: for each rival taken as the
truth, the cheapest other compared pose distinct from it (beyond ``distinct_mm`` / ``distinct_deg`` up to the
part's symmetries).

Frames: world, z up, metres; cameras are ``T_world_cam`` in OpenCV's camera frame (z forward, y down).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import trimesh
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import StrictModel, TablePlane
from asmteach.core.perception.depth_camera import KinectSettings, look_at
from asmteach.core.perception.registration import model_cloud
from asmteach.core.perception.second_view import SecondViewSettings, axis_turns, range_sigma, screw_turns
from asmteach.core.pose_error import pose_error

import open3d as o3d  # isort: skip  (after asmteach.core)

__all__ = ["ViewChoiceSettings", "Viewpoint", "candidate_cameras", "rank_viewpoints"]


class ViewChoiceSettings(StrictModel):
    """The candidate viewpoints of a close look and how finely their power is predicted (metres, degrees)."""

    distances: list[float] = Field(
        default_factory=lambda: [0.2, 0.275, 0.35], description="camera centre to the rivals' centre, metres"
    )
    elevations_deg: list[float] = Field(
        default_factory=lambda: [35.0, 55.0, 75.0], description="view axis above the table plane, degrees"
    )
    azimuth_step_deg: float = Field(30.0, gt=0.0, le=180.0, description="azimuths about the table normal, degrees")
    rays: int = Field(16, ge=2, le=128, description="rays across the rivals' bounding sphere, per side")
    step_deg: float = Field(30.0, gt=0.0, le=90.0, description="turns of the first rival compared, degrees")
    max_rivals: int = Field(6, ge=2, description="the first this many listed rivals are taken as the truth")


@dataclass(frozen=True)
class Viewpoint:
    """A candidate camera ``T_world_cam`` (4, 4) and its predicted ``separation`` of the rivals (squared sigmas)."""

    T_world_cam: np.ndarray
    separation: float
    distance: float
    elevation_deg: float
    azimuth_deg: float

    def as_details(self) -> dict:
        """JSON-ready summary: camera centre in mm, the grid coordinates and the separation."""
        return {
            "camera_xyz_mm": [round(1000.0 * float(v), 1) for v in self.T_world_cam[:3, 3]],
            "distance_m": round(self.distance, 3),
            "elevation_deg": round(self.elevation_deg, 1),
            "azimuth_deg": round(self.azimuth_deg, 1),
            "predicted_separation": round(self.separation, 1),
        }


def candidate_cameras(
    center: np.ndarray,
    surface: np.ndarray,
    sensor: KinectSettings,
    table: TablePlane,
    settings: ViewChoiceSettings | None = None,
) -> list[tuple[np.ndarray, float, float, float]]:
    """``(T_world_cam, distance, elevation_deg, azimuth_deg)`` of every grid viewpoint looking at ``center`` (3,)
    whose camera is within the sensor's range of every point of ``surface`` (n, 3) (the part's surface at every
    rival pose): nearer than ``min_range`` the sensor sees nothing, and beyond ``max_range`` neither."""
    s = settings or ViewChoiceSettings()
    n = np.asarray(table.normal, float)
    # a horizontal frame on the table: azimuth 0 along the world x axis projected onto the table
    ex = np.array([1.0, 0.0, 0.0]) - n[0] * n
    if np.linalg.norm(ex) < 1e-6:
        ex = np.array([0.0, 1.0, 0.0]) - n[1] * n
    ex /= np.linalg.norm(ex)
    ey = np.cross(n, ex)
    out = []
    for dist in s.distances:
        for el in s.elevations_deg:
            for az in np.arange(0.0, 360.0 - 1e-9, s.azimuth_step_deg):
                e, a = np.radians(el), np.radians(az)
                eye = center + dist * (np.cos(e) * (np.cos(a) * ex + np.sin(a) * ey) + np.sin(e) * n)
                rng = np.linalg.norm(surface - eye, axis=1)
                if rng.min() < sensor.min_range or rng.max() > sensor.max_range:
                    continue
                out.append((look_at(eye, center, up=n), float(dist), float(el), float(az)))
    return out


def _rays(T_cams: np.ndarray, center: np.ndarray, radius: float, sensor: KinectSettings, n: int) -> tuple:
    """``(eyes (c, 3), unit directions (c, n*n, 3), pixels per ray (c,))``: an ``n`` x ``n`` grid of rays over the
    image square that holds the sphere (``center``, ``radius``), cut to the image."""
    eyes = T_cams[:, :3, 3]
    dist = np.linalg.norm(center - eyes, axis=1)
    half = np.tan(np.arcsin(np.clip(radius / dist, 0.0, 0.999)))
    fov_x, fov_y = sensor.cx / sensor.fx, sensor.cy / sensor.fy
    hx, hy = np.minimum(half, fov_x), np.minimum(half, fov_y)
    g = np.linspace(-1.0, 1.0, n) * (n - 1) / n  # cell centres
    gx, gy = np.meshgrid(g, g, indexing="xy")
    xs = gx.reshape(1, -1) * hx[:, None]
    ys = gy.reshape(1, -1) * hy[:, None]
    d_cam = np.stack([xs, ys, np.ones_like(xs)], axis=-1)
    d_cam /= np.linalg.norm(d_cam, axis=-1, keepdims=True)
    dirs = np.einsum("cij,ckj->cki", T_cams[:, :3, :3], d_cam)
    pixels = (2.0 * hx * sensor.fx / n) * (2.0 * hy * sensor.fy / n)
    return eyes, dirs, pixels


def _cast(scene: o3d.t.geometry.RaycastingScene, eyes: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Ranges ``(c, m)`` to the first hit of ``scene`` (inf on a miss) from ``eyes`` (c, 3) along ``dirs`` (c, m, 3)."""
    rays = np.concatenate([np.broadcast_to(eyes[:, None, :], dirs.shape), dirs], axis=-1).reshape(-1, 6)
    t = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy().astype(float)
    return t.reshape(dirs.shape[:2])


def rank_viewpoints(
    mesh: trimesh.Trimesh,
    poses: Sequence[np.ndarray],
    sensor: KinectSettings,
    table: TablePlane,
    *,
    symmetries: Sequence[np.ndarray] | None = None,
    occluders: Sequence[tuple[trimesh.Trimesh, np.ndarray]] = (),
    frames: int = 1,
    settings: ViewChoiceSettings | None = None,
    judge: SecondViewSettings | None = None,
) -> list[Viewpoint]:
    """The grid viewpoints (:func:`candidate_cameras`) ranked by their predicted separation of ``poses``, best first.

    ``poses`` (``T_world_part``) are the rivals of an ambiguous detection, best first; the poses compared are they
    and the first one turned about the screw axis to each other one and about its principal axes (every
    ``step_deg``), as :func:`~asmteach.core.perception.second_view.judge_rivals` compares turns too.
    ``symmetries`` (part frame) are the part's, so that a pose one of them maps onto a rival is no rival (none
    when ``None``). ``occluders`` (mesh, ``T_world``) hide what lies behind them (the other part). ``frames``
    stacked depth frames multiply every ray's weight. ``judge`` gives the clip, the pose allowance and what
    counts as distinct.
    """
    s = settings or ViewChoiceSettings()
    j = judge or SecondViewSettings()
    rivals = [np.asarray(T, float) for T in poses[: s.max_rivals]]
    if len(rivals) < 2:
        return []
    compared = list(rivals)
    for T in rivals[1:]:
        compared += screw_turns(rivals[0], T, s.step_deg)
    compared += axis_turns(mesh, rivals[0], s.step_deg)
    syms = np.eye(4)[None] if symmetries is None else np.asarray(symmetries, float).reshape(-1, 4, 4)
    distinct = np.array(
        [[not pose_error(Tk, Ti, right=syms).within(j.distinct_mm, j.distinct_deg) for Tk in compared] for Ti in rivals]
    )
    model = model_cloud(mesh, 2000)
    centers = np.array([geometry.transform_points(T, model.center[None])[0] for T in compared])
    center = centers.mean(axis=0)
    radius = model.radius + float(np.max(np.linalg.norm(centers - center, axis=1)))
    surface = np.vstack([geometry.transform_points(T, model.points) for T in rivals])
    cams = candidate_cameras(center, surface, sensor, table, s)
    if not cams:
        return []
    T_cams = np.array([c[0] for c in cams])
    eyes, dirs, pixels = _rays(T_cams, center, radius, sensor, s.rays)
    # what every pose shares: the table plane and the occluders
    n = np.asarray(table.normal, float)
    denom = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t_table = (table.height - eyes @ n)[:, None] / denom
    fixed = np.where((denom < -1e-9) & (t_table > 0), t_table, np.inf)
    if occluders:
        occ = o3d.t.geometry.RaycastingScene()
        for m, T in occluders:
            moved = np.asarray(m.vertices, float) @ np.asarray(T, float)[:3, :3].T + np.asarray(T, float)[:3, 3]
            occ.add_triangles(
                o3d.core.Tensor(moved.astype(np.float32)), o3d.core.Tensor(np.asarray(m.faces, np.uint32))
            )
        fixed = np.minimum(fixed, _cast(occ, eyes, dirs))
    ranges = np.empty((len(compared), *fixed.shape))
    for k, T in enumerate(compared):
        T_pw = geometry.invert(T)
        eyes_p = eyes @ T_pw[:3, :3].T + T_pw[:3, 3]
        dirs_p = dirs @ T_pw[:3, :3].T
        ranges[k] = np.minimum(_cast(model.scene, eyes_p, dirs_p), fixed)
    # a return only within the sensor's range; elsewhere no pose is seen
    seen = (ranges >= sensor.min_range) & (ranges <= sensor.max_range)
    clip2 = j.clip_sigmas**2
    weakest = np.full(len(cams), np.inf)
    for i in range(len(rivals)):
        others = np.flatnonzero(distinct[i])
        if not len(others):
            continue
        r_i, seen_i = ranges[i], seen[i]
        sigma = range_sigma(np.where(seen_i, r_i, 1.0), sensor, j.pose_sigma)
        with np.errstate(invalid="ignore"):
            z = (r_i[None] - ranges[others]) / sigma[None]
        cost = np.where(seen_i[None] & seen[others], np.minimum(z * z, clip2), 0.0)
        # a return under one pose and none under the other tells them apart as surely as a clipped residual
        cost = np.where(seen_i[None] != seen[others], clip2, cost)
        total = cost.sum(axis=2) * pixels[None] * frames
        weakest = np.minimum(weakest, total.min(axis=0))
    weakest = np.where(np.isfinite(weakest), weakest, 0.0)
    order = np.argsort(-weakest, kind="stable")
    return [Viewpoint(cams[c][0], float(weakest[c]), *cams[c][1:]) for c in order]
