"""ICP refinement and hypothesis verification, shared by the depth detectors (``cvfh_icp``, ``fpfh_ransac``).

A hypothesis is a ``T_world_part`` (4x4, metres). Refinement runs Open3D's
point-to-plane ICP from the observed cluster (world frame) to a dense sample
of the part's surface (part frame, with normals), coarse then fine.
Verification asks of a refined pose, in both directions (scene to model, as
the fitness, and model to scene, as PCL's global hypothesis verification does
with its model outliers):

* fitness: which share of the observed cluster lies on the model surface;
* inlier RMSE: how far those points are from it;
* free-space violations: which share of the observed points near the part
  (table included) the model would hide, i.e. the model surface would lie
  in front of what the camera saw. A wrong pose, or a bigger part than the
  one on the table, puts model surface where the camera saw through;
* surface check (model to scene, :func:`surface_check`): of the model surface
  the camera should see at this pose (facing it, not self-hidden, not
  grazing), the share the seen depth along its ray explains (``coverage``)
  and the share the camera saw through (``contradicted``). Its denominator
  is the model's own visible surface, so a small part is judged on its size;
* support (the paper's geometric constraint): a part lying on the table
  touches it, so the model's lowest point must be at the table height, neither
  below (inside the table) nor above (floating). This rejects the poses that
  explain the visible surface equally well but hide a different shape below
  it, e.g. an L-block turned over with its upright hidden under the foot.

The distance tests (fitness, RMSE, the free-space margin) were measured on scenes seen from 0.8-0.9 m; a
point farther away gets them grown by its depth noise (:func:`noise_scale`), since at the pipeline's 1.0 m the
same 4 mm rejects right poses. The score keeps the fixed inlier distance.

Why the poses 17-20 mm / 66-105 deg off of issue 22 passed: every check was
one-directional or diluted. Fitness counts cluster points within 4 mm of the
model *anywhere*, so a small part turned about its axis keeps fitness ~0.99;
the free-space share is taken over every seen point within the part's
diameter + 2 cm, mostly table, so a part of 200 points can put a third of its
surface over seen table and stay under 1.5 %. Measured on 641 refined
hypotheses of 49 corpus parts: right poses have coverage >= 0.76 and
contradicted <= 0.13, hence the thresholds 0.70 and 0.20. Those two reject
most wrong poses, but not the ones a *near twin* of the part explains as well
as the right one (a D-peg or keyed peg turned about its axis with the flat or
key out of sight, a 52 x 53 mm block turned by 90 deg): their scores fall
within 0.01 of the right pose's, inside the spread of right poses. No fixed
threshold separates those; the ``cvfh_icp`` detector compares the pose with its
near twins instead (its ``resting.near_twins``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.models import StrictModel, TablePlane
from asmteach.core.perception.open3d_tools import one_thread, to_o3d
from asmteach.core.perception.surface_check import SurfaceCheck, ray_depths, surface_check

import open3d as o3d  # isort: skip

__all__ = [
    "ModelCloud",
    "RefineSettings",
    "Verdict",
    "check_surface",
    "icp_refine",
    "model_cloud",
    "noise_scale",
    "verify",
    "visible_samples",
]

reg = o3d.pipelines.registration


class RefineSettings(StrictModel):
    """ICP and verification thresholds (metres)."""

    model_points: int = Field(4000, ge=100, description="surface samples of the part model used by ICP")
    icp_coarse_distance: float = Field(0.012, gt=0.0, description="correspondence distance of the first ICP pass")
    icp_fine_distance: float = Field(0.004, gt=0.0, description="correspondence distance of the last ICP pass")
    icp_iterations: int = Field(30, ge=1, description="iterations per ICP pass")
    visible_icp: bool = Field(
        True,
        description="the fine ICP pass registers onto the model surface the camera sees at its start (icp_refine's "
        "viewpoint; the detector passes its camera centre), not the whole model: a seen wall pairs with none "
        "behind it (a cup turned over); corpus, session 17: found 169 -> 171 of 245 with one view, 200 -> 203 "
        "with two, 0 wrong. The coarse pass keeps the whole model: from a start tens of degrees off, the surface "
        "seen at the start is not the one seen at the truth (session 18: a keyed peg tilted 55 deg)",
    )
    inlier_distance: float = Field(
        0.004,
        gt=0.0,
        description="a cluster point within this of the model is an inlier (at noise_range; farther points get it "
        "grown with the Kinect's depth noise)",
    )
    noise_range: float = Field(
        0.85,
        gt=0.0,
        description="camera range (metres) inlier_distance, max_rmse and occlusion_margin were measured at (the "
        "corpus scenes: 0.8-0.9 m); for a point farther away the fitness test counts it an inlier within "
        "inlier_distance times the ratio of the depth noise at its range to the noise at this one, and max_rmse "
        "and its occlusion_margin grow alike (never shrink for nearer points); the score keeps inlier_distance",
    )
    min_fitness: float = Field(
        0.95, ge=0.0, le=1.0, description="least inlier share of the cluster (right poses measured: >= 0.98)"
    )
    max_rmse: float = Field(0.0025, gt=0.0, description="largest inlier RMSE, metres")
    occlusion_margin: float = Field(0.006, gt=0.0, description="model this far in front of a seen point violates")
    max_violation: float = Field(
        0.015, ge=0.0, le=1.0, description="largest share of nearby seen points hidden (right poses: <= 0.005)"
    )
    support_tolerance: float = Field(
        0.004, gt=0.0, description="largest gap or penetration between the model's lowest point and the table"
    )
    surface_fit: float = Field(
        0.004, gt=0.0, description="model surface explained: the depth seen along its ray is within this, metres"
    )
    surface_off: float = Field(
        0.006, gt=0.0, description="model surface seen through: the camera saw farther than it by more than this"
    )
    ray_radius: float = Field(
        0.0029, gt=0.0, description="nearest observed ray searched within this angle, radians (1.5 Kinect pixels)"
    )
    max_incidence_deg: float = Field(
        70.0, gt=0.0, le=90.0, description="model surface more oblique to its ray gives no return (Kinect grazing)"
    )
    min_coverage: float = Field(
        0.70,
        ge=0.0,
        le=1.0,
        description="least share of the model's visible surface the seen depth explains (right poses on 49 corpus "
        "parts: >= 0.76)",
    )
    max_contradicted: float = Field(
        0.20,
        ge=0.0,
        le=1.0,
        description="largest share of the model's visible surface the camera saw through (right poses: <= 0.13)",
    )


@dataclass
class ModelCloud:
    """Dense surface sample of a part (part frame) with outward normals, and its mesh."""

    points: np.ndarray
    normals: np.ndarray
    mesh: trimesh.Trimesh
    pcd: o3d.geometry.PointCloud
    radius: float
    """Largest distance of a surface point from the bounding-box centre, metres."""
    center: np.ndarray
    hull_vertices: np.ndarray
    """(k, 3) convex-hull vertices, part frame (the lowest point of any pose is among them)."""
    scene: o3d.t.geometry.RaycastingScene
    """Ray-casting scene of the mesh in the part frame (distances, visibility)."""


@dataclass
class Verdict:
    """A refined hypothesis and its verification scores."""

    T_world_part: np.ndarray
    fitness: float
    inlier_rmse: float
    violation: float
    support_gap: float
    """Height (metres) of the model's lowest point above the table; NaN without a table."""
    accepted: bool
    why: str | None = None
    coverage: float = float("nan")
    """Share of the model's visible surface the seen depth explains (:class:`SurfaceCheck`)."""
    contradicted: float = float("nan")
    """Share of the model's visible surface the camera saw through."""

    @property
    def score(self) -> float:
        """Ranking key: inlier share, less the share of free space the model would fill."""
        return self.fitness - 2.0 * self.violation


def model_cloud(mesh: trimesh.Trimesh, n: int, seed: int = 0) -> ModelCloud:
    """Evenly spread surface samples of ``mesh`` with face normals (seeded)."""
    pts, faces = trimesh.sample.sample_surface_even(mesh, n, seed=seed)
    if len(pts) < n // 2:  # even sampling can reject many; top up uniformly
        more, more_faces = trimesh.sample.sample_surface(mesh, n - len(pts), seed=seed + 1)
        pts, faces = np.vstack([pts, more]), np.concatenate([faces, more_faces])
    normals = np.asarray(mesh.face_normals)[faces]
    center = np.asarray(mesh.bounds).mean(axis=0)
    radius = float(np.max(np.linalg.norm(np.asarray(mesh.vertices) - center, axis=1)))
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    hull = np.asarray(mesh.convex_hull.vertices, dtype=float)
    return ModelCloud(pts, normals, mesh, to_o3d(pts, normals), radius, center, hull, scene)


def icp_refine(
    cluster: np.ndarray,
    model: ModelCloud,
    T_world_part: np.ndarray,
    s: RefineSettings,
    *,
    coarse: bool = True,
    fine: bool = True,
    viewpoint: np.ndarray | None = None,
) -> np.ndarray:
    """Point-to-plane ICP of the observed ``cluster`` (world) onto the model; returns ``T_world_part``.

    The coarse pass (wide correspondence distance) pulls a hypothesis in; the
    fine pass (narrow) ignores what is not the part's surface. With ``viewpoint`` (the camera centre,
    world, metres) the fine pass registers onto the model surface the camera can see at its starting
    pose only (:func:`visible_samples`): a seen point near a wall the camera cannot see (the inside of a
    cup turned over, 2-3 mm behind its outside) otherwise pairs with it and pulls the pose off.

    The coarse pass registers onto the whole model, viewpoint or not: it starts from a hypothesis that
    may be tens of degrees off, where the surface the camera would see is not the one it saw (a keyed peg
    tilted 55 deg onto an edge shows its head's underside and hides the top the camera saw), and the
    seen points, left without their faces, pulled the pose into a wrong minimum (19 mm / 88 deg off, half
    a centimetre into the table) that the whole model's coarse pass leaves for the truth.
    """
    src = to_o3d(cluster)
    T = geometry.invert(T_world_part)  # ICP moves the cluster into the part frame
    passes = [
        (d, seen) for d, on, seen in ((s.icp_coarse_distance, coarse, False), (s.icp_fine_distance, fine, True)) if on
    ]
    with one_thread():
        for dist, seen in passes:
            target = model.pcd
            if seen and viewpoint is not None:
                keep = visible_samples(model, geometry.transform_points(T, np.asarray(viewpoint, float)[None])[0])
                if keep.sum() >= 10:
                    target = model.pcd.select_by_index(np.flatnonzero(keep).tolist())
            res = reg.registration_icp(
                src,
                target,
                dist,
                T,
                reg.TransformationEstimationPointToPlane(),
                reg.ICPConvergenceCriteria(relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=s.icp_iterations),
            )
            T = np.asarray(res.transformation)
    return geometry.invert(T)


def visible_samples(model: ModelCloud, eye: np.ndarray, slack: float = 0.001) -> np.ndarray:
    """``(n,) bool``: the model's surface samples the camera at ``eye`` (part frame, metres) sees: facing it and
    the first surface along their ray (within ``slack`` metres)."""
    facing = np.einsum("ij,ij->i", model.normals, eye - model.points) > 0.0
    out = np.zeros(len(model.points), dtype=bool)
    if facing.any():
        hit, dist = ray_depths(model, eye, model.points[facing])
        out[np.flatnonzero(facing)] = hit >= dist - slack
    return out


def verify(
    T_world_part: np.ndarray,
    cluster: np.ndarray,
    context: np.ndarray,
    viewpoint: np.ndarray,
    model: ModelCloud,
    s: RefineSettings,
    table: TablePlane | None = None,
) -> Verdict:
    """Score a refined pose against the observed ``cluster`` and the seen points ``context`` near it.

    ``context`` is every observed point (table included, world frame) within
    reach of the part; ``viewpoint`` is the camera centre (world, metres);
    ``table`` the supporting plane (no support check without it).
    """
    T_part_world = geometry.invert(T_world_part)
    local = geometry.transform_points(T_part_world, cluster)
    d = _distances_to_model(local, model)
    inl = d < s.inlier_distance
    fitness = float(inl.mean()) if len(d) else 0.0
    rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("inf")
    # The tests allow for the depth noise at the cluster's range; the score (fitness above) does not: a looser
    # inlier distance brings a wrong near twin's score closer to the right one's (a 90 deg turned slot block).
    scale = noise_scale(cluster, viewpoint, s.noise_range)
    noisy_fitness = float(np.mean(d < s.inlier_distance * scale)) if len(d) else 0.0
    max_rmse = s.max_rmse * (float(np.sqrt(np.mean(scale[inl] ** 2))) if inl.any() else 1.0)

    violation = _free_space_violation(T_part_world, context, viewpoint, model, s.occlusion_margin, s.noise_range)
    gap = float("nan")
    if table is not None:
        n = np.asarray(table.normal, dtype=float)
        gap = float(np.min(geometry.transform_points(T_world_part, model.hull_vertices) @ n) - table.height)
    why = None
    if np.isfinite(gap) and abs(gap) > s.support_tolerance:
        where = "inside the table" if gap < 0 else "above the table (floating)"
        why = f"the part would rest {abs(gap) * 1000:.1f} mm {where}"
    elif noisy_fitness < s.min_fitness:
        why = f"fitness {noisy_fitness:.2f} < {s.min_fitness:.2f} (inliers within the depth noise at their range)"
    elif rmse > max_rmse:
        why = f"inlier RMSE {rmse * 1000:.2f} mm > {max_rmse * 1000:.2f} mm"
    elif violation > s.max_violation:
        why = f"the model would hide {100 * violation:.1f}% of the points seen around it"
    if why is not None:
        # Rejected already: the surface check (the costliest, ~60 % of a verification) would change neither
        # the verdict, nor its score, nor the reason; its shares stay NaN.
        return Verdict(T_world_part, fitness, rmse, violation, gap, False, why)
    surf = check_surface(T_part_world, context, viewpoint, model, s)
    if surf.contradicted > s.max_contradicted:
        why = f"the camera saw through {100 * surf.contradicted:.0f}% of the model surface it should see"
    elif surf.coverage < s.min_coverage:
        why = f"the seen depth explains {100 * surf.coverage:.0f}% of the model surface it should see"
    return Verdict(T_world_part, fitness, rmse, violation, gap, why is None, why, surf.coverage, surf.contradicted)


def check_surface(
    T_part_world: np.ndarray, context: np.ndarray, viewpoint: np.ndarray, model: ModelCloud, s: RefineSettings
) -> SurfaceCheck:
    """:func:`surface_check` of the model at ``T_part_world`` (the world-to-part transform) against the seen
    ``context`` (world) from ``viewpoint``, with the thresholds of ``s``."""
    return surface_check(
        T_part_world,
        context,
        viewpoint,
        model,
        fit=s.surface_fit,
        off=s.surface_off,
        ray_radius=s.ray_radius,
        max_incidence_deg=s.max_incidence_deg,
    )


def noise_scale(points: np.ndarray, viewpoint: np.ndarray, reference_range: float) -> np.ndarray:
    """``(n,)`` factor >= 1 by which the Kinect's depth noise at each point's range from ``viewpoint`` (world,
    metres) exceeds the noise at ``reference_range`` (metres): :func:`asmteach.core.clouds.depth_sigma`.

    Thresholds on point-to-model distances measured at one range reject right poses farther away: at 1.0 m
    (the pipeline's camera) the noise is 1.25 times that at 0.85 m (the corpus scenes), and 4 mm, 2.7 sigma
    there, is 2.1 sigma here: a keyed peg at its true pose had 5.2 % of its points beyond it (fitness 0.948).
    """
    return _range_scale(
        np.linalg.norm(np.asarray(points, float) - np.asarray(viewpoint, float), axis=1), reference_range
    )


def _range_scale(ranges: np.ndarray, reference_range: float) -> np.ndarray:
    from asmteach.core.clouds import depth_sigma

    return np.maximum(1.0, depth_sigma(ranges) / depth_sigma(np.asarray(reference_range)))


def _distances_to_model(local: np.ndarray, model: ModelCloud) -> np.ndarray:
    """Unsigned distances (metres) of part-frame points to the mesh surface."""
    res = model.scene.compute_distance(o3d.core.Tensor(local.astype(np.float32)))
    return res.numpy().astype(float)


def _free_space_violation(
    T_part_world: np.ndarray,
    context: np.ndarray,
    viewpoint: np.ndarray,
    model: ModelCloud,
    margin: float,
    noise_range: float | None = None,
) -> float:
    """Share of the seen points near the part that the model, at this pose, would hide from the camera."""
    local = geometry.transform_points(T_part_world, context)
    near = np.linalg.norm(local - model.center, axis=1) < 1.5 * model.radius + 0.01
    if not near.any():
        return 0.0
    eye = geometry.transform_points(T_part_world, viewpoint[None])[0]
    # Only rays through the model's bounding sphere, beyond its near side, can meet the model in front of their
    # point (slack for float32 ray casting): the others (two in three, mostly table beside the part) get none.
    pts, c, r = local[near], model.center - eye, model.radius * (1.0 + 1e-6) + 1e-6
    d, reach = pts - eye, float(np.linalg.norm(c))
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    maybe = (reach * reach - ((d @ c) / dist) ** 2 < r * r) & (dist - margin > reach - r - 1e-5)
    hit, cast = ray_depths(model, eye, pts[maybe]) if maybe.any() else (np.zeros(0), np.zeros(0))
    if noise_range is not None and len(cast):
        margin = margin * _range_scale(cast, noise_range)  # the depth noise at each point's range, as for inliers
    return float(np.sum(hit < cast - margin) / len(pts))
