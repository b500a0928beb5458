"""``fpfh_ransac``: the baseline depth detector (Open3D FPFH + RANSAC + ICP).

Same scene preparation, ICP and verification as ``cvfh_icp`` (so the two
compare on the matching step alone): the cluster's FPFH features are matched
to the model's (a dense surface sample of the mesh) and Open3D's feature
RANSAC, seeded from the plugin seed, proposes the pose; ICP refines it and
the verification accepts or rejects it. A rejected pose triggers another
RANSAC round (``attempts``).

A part given as a scan (``PartModel.points``: a PCD/PLY cloud, no mesh) is
matched the same way from its own points, their normals pointing at the
scanner (``PartModel.scan_viewpoint``; outward from the centroid when
unknown). Its verification has no surface to cast rays at or to rest on the
table: it checks both directions on points instead (:func:`verify_scan`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.models import Detection, StrictModel, TablePlane, Vec3
from asmteach.core.perception.open3d_tools import one_thread, to_o3d
from asmteach.core.perception.registration import (
    ModelCloud,
    RefineSettings,
    Verdict,
    icp_refine,
    model_cloud,
    verify,
)
from asmteach.core.perception.segmentation import (
    SegmentSettings,
    check_cloud,
    cluster_objects,
    merge_nearby,
    remove_table,
)
from asmteach.core.perception.surface_check import ray_plane
from asmteach.core.perception.viewpoint import StageClock, resolve_viewpoint

import open3d as o3d  # isort: skip

__all__ = ["FpfhRansacDetector", "scan_model", "verify_scan"]

reg = o3d.pipelines.registration


class FpfhSettings(StrictModel):
    """Settings of the ``fpfh_ransac`` detector (metres)."""

    viewpoint: Vec3 | None = Field(
        None,
        description="camera centre in the world frame, metres, when detect() is not given one (orients the "
        "cluster's normals, casts the verification's rays); no default",
    )
    segment: SegmentSettings = Field(
        default_factory=SegmentSettings, description="table removal and clustering of the cloud"
    )
    refine: RefineSettings = Field(default_factory=RefineSettings, description="ICP refinement and verification")
    voxel: float = Field(0.004, gt=0.0, description="voxel size of the clouds FPFH is computed on")
    normal_radius: float = Field(0.012, gt=0.0, description="normal estimation radius of the cluster")
    feature_radius: float = Field(0.025, gt=0.0, description="FPFH radius")
    ransac_iterations: int = Field(50000, ge=100, description="RANSAC iterations per attempt")
    ransac_confidence: float = Field(0.999, gt=0.0, lt=1.0, description="RANSAC stops once this sure (0..1)")
    mutual_filter: bool = Field(True, description="keep only mutually nearest feature matches")
    attempts: int = Field(3, ge=1, description="RANSAC rounds until a pose verifies")
    max_clusters: int = Field(3, ge=1, description="largest plausible clusters tried, biggest first")
    size_slack: float = Field(1.25, ge=1.0, description="a cluster wider than this times the part's is skipped")
    scan_spacing: float = Field(0.002, gt=0.0, description="voxel size a part given as a scan is thinned to, metres")
    scan_min_coverage: float = Field(
        0.7,
        ge=0.0,
        le=1.0,
        description="part given as a scan: least share of its points facing the camera that lie on seen points",
    )


@dataclass
class _Prepared:
    model: ModelCloud
    down: o3d.geometry.PointCloud
    features: reg.Feature
    diameter: float


class FpfhRansacDetector(Detector):
    """Open3D FPFH features, feature-matching RANSAC (seeded), point-to-plane ICP, verification."""

    Settings = FpfhSettings
    settings: FpfhSettings
    takes_cloud_models = True

    def __init__(self, settings=None, *, seed: int = 0) -> None:  # type: ignore[no-untyped-def]
        super().__init__(settings, seed=seed)
        self._prepared: dict[str, _Prepared] = {}

    def prepare(self, part: PartModel) -> None:
        """Sample the part's surface and compute its FPFH features."""
        self._prep(part)

    def _prep(self, part: PartModel) -> _Prepared:
        key = part.source_hash or part.name
        if key not in self._prepared:
            s = self.settings
            if part.points is not None:
                model = scan_model(part, s.scan_spacing, s.normal_radius)
            else:
                model = model_cloud(part.mesh, s.refine.model_points, seed=self.seed)
            down = model.pcd.voxel_down_sample(s.voxel)
            feats = reg.compute_fpfh_feature(down, o3d.geometry.KDTreeSearchParamHybrid(s.feature_radius, 100))
            diameter = float(np.linalg.norm(np.ptp(np.asarray(part.mesh.vertices), axis=0)))
            self._prepared[key] = _Prepared(model, down, feats, diameter)
        return self._prepared[key]

    def detect(
        self,
        cloud: np.ndarray,
        part: PartModel,
        table: TablePlane | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Detection:
        """Find ``part`` in ``cloud`` ((n, 3) world frame, metres).

        ``viewpoint`` is the camera centre ((3,), world frame, metres) that
        orients the cluster's normals and casts the free-space check's rays;
        ``None`` uses the ``viewpoint`` setting, and :class:`UserError` without either.
        """
        eye = resolve_viewpoint(viewpoint, self.settings.viewpoint)
        prep = self._prep(part)
        s = self.settings
        clock = StageClock()

        def fail(reason: str) -> Detection:
            return Detection(part=part.name, found=False, reason=reason, timing_ms=clock.done())

        pts, reason = check_cloud(cloud)
        if pts is None:
            return fail(reason or "invalid cloud")
        table, above, reason = remove_table(pts, s.segment, table=table, seed=self.seed)
        clock.lap("segment")
        if above is None or table is None:
            return fail(reason or "no table")
        clusters = merge_nearby(
            cluster_objects(above, s.segment), s.segment.merge_gap, s.size_slack * prep.diameter + 0.01
        )
        clock.lap("cluster")
        if not clusters:
            return fail("nothing stands on the table: the points above it form no cluster")
        plausible = [c for c in clusters if _width(c) <= s.size_slack * prep.diameter + 0.01]
        if not plausible:
            return fail(f"no cluster fits {part.name!r}: every cluster is wider than the part")
        best: Verdict | None = None
        closest: Verdict | None = None
        for ci, cluster in enumerate(plausible[: s.max_clusters]):
            src = to_o3d(cluster).voxel_down_sample(s.voxel)
            src.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(s.normal_radius, 30))
            src.orient_normals_towards_camera_location(eye)
            feats = reg.compute_fpfh_feature(src, o3d.geometry.KDTreeSearchParamHybrid(s.feature_radius, 100))
            clock.lap("descriptors")
            context = pts[np.linalg.norm(pts - cluster.mean(axis=0), axis=1) < prep.diameter + 0.02]
            for attempt in range(s.attempts):
                o3d.utility.random.seed(int(self.seed * 7919 + ci * 101 + attempt))
                dist = 1.5 * s.voxel
                # On one thread: on parallel threads which hypothesis won depended on the scheduler (the
                # milk scan, one seed, three processes at once: 0.13 or 0.92 mm off).
                with one_thread():
                    res = reg.registration_ransac_based_on_feature_matching(
                        src,
                        prep.down,
                        feats,
                        prep.features,
                        s.mutual_filter,
                        dist,
                        reg.TransformationEstimationPointToPoint(False),
                        3,
                        [
                            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
                            reg.CorrespondenceCheckerBasedOnDistance(dist),
                        ],
                        reg.RANSACConvergenceCriteria(s.ransac_iterations, s.ransac_confidence),
                    )
                clock.lap("matching")
                T0 = geometry.invert(np.asarray(res.transformation))
                T = icp_refine(np.asarray(src.points), prep.model, T0, s.refine)
                clock.lap("icp")
                if part.points is not None:
                    v = verify_scan(T, cluster, context, eye, prep.model, s.refine, s.scan_min_coverage)
                else:
                    v = verify(T, cluster, context, eye, prep.model, s.refine, table)
                clock.lap("verify")
                if closest is None or v.score > closest.score:
                    closest = v
                if v.accepted:
                    best = v
                    break
            if best is not None:
                break
        timing = clock.done()
        if best is None:
            why = closest.why if closest is not None else "no hypothesis"
            return Detection(
                part=part.name,
                found=False,
                reason=f"{part.name!r} not found: best hypothesis rejected ({why})",
                timing_ms=timing,
            )
        return Detection(
            part=part.name,
            found=True,
            rough=best.T_world_part,
            fitness=best.fitness,
            inlier_rmse=best.inlier_rmse,
            timing_ms=timing,
            details={
                "violation": best.violation,
                "clusters": len(clusters),
                "table": table.model_dump(mode="json"),
                "viewpoint": eye.tolist(),
                **(
                    {"model": "scan", "coverage": best.coverage, "contradicted": best.contradicted}
                    if part.points is not None
                    else {}
                ),
            },
        )


def _width(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0)))


def scan_model(part: PartModel, spacing: float, normal_radius: float) -> ModelCloud:
    """The model cloud of a part given as a scan: its points thinned to ``spacing`` (metres), with normals.

    Normals point at the scanner (``part.scan_viewpoint``, part frame) as the scene's point at the camera,
    so FPFH sees the same signs on both; outward from the centroid when the scanner is unknown (a merged
    all-round scan). The mesh fields hold the points' convex hull, used for size only.
    """
    pcd = to_o3d(np.asarray(part.points, dtype=float)).voxel_down_sample(spacing)
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(normal_radius, 30))
    pts = np.asarray(pcd.points)
    nrm = np.asarray(pcd.normals)
    if part.scan_viewpoint is not None:
        pcd.orient_normals_towards_camera_location(np.asarray(part.scan_viewpoint, dtype=float))
    else:
        flip = np.einsum("ij,ij->i", nrm, pts - pts.mean(axis=0)) < 0
        nrm[flip] *= -1.0
        pcd.normals = o3d.utility.Vector3dVector(nrm)
    nrm = np.asarray(pcd.normals)
    hull = part.mesh
    center = np.asarray(hull.bounds).mean(axis=0)
    scene = o3d.t.geometry.RaycastingScene()  # empty: a scan has no surface to cast rays at
    return ModelCloud(
        pts,
        nrm,
        hull,
        pcd,
        float(np.max(np.linalg.norm(pts - center, axis=1))),
        center,
        np.asarray(hull.vertices, dtype=float),
        scene,
    )


def verify_scan(
    T_world_part: np.ndarray,
    cluster: np.ndarray,
    context: np.ndarray,
    viewpoint: np.ndarray,
    model: ModelCloud,
    s: RefineSettings,
    min_coverage: float,
) -> Verdict:
    """Score a pose of a part given as a scan, on points both ways (world frame, metres).

    * fitness: the share of the observed ``cluster`` within ``s.inlier_distance`` of a model point (and
      the RMSE of those), as :func:`verify` does against a mesh;
    * along the camera's rays (``viewpoint``), for the model's points facing the camera: ``coverage``, the
      share whose seen depth (nearest observed ray of ``context`` within ``s.ray_radius``) is within
      ``s.surface_fit`` of theirs, must reach ``min_coverage``; ``contradicted``, the share where the camera
      saw farther than the model by more than ``s.surface_off`` (the model is not there), must stay under
      ``s.max_contradicted``. A scan too big for the object, or put where nothing was seen, fails these.

    No support test: it needs the part's underside, which a scan does not show. Points facing the camera
    stand in for the visible ones (a scan has no surface to cast rays at for self-occlusion; a point hidden
    by the part itself sees a nearer depth, which counts as no evidence, not as a contradiction).
    """
    from scipy.spatial import cKDTree

    local = geometry.transform_points(geometry.invert(T_world_part), cluster)
    d, _ = cKDTree(model.points).query(local, k=1)
    inl = d < s.inlier_distance
    fitness = float(inl.mean()) if len(d) else 0.0
    rmse = float(np.sqrt(np.mean(d[inl] ** 2))) if inl.any() else float("inf")
    eye = np.asarray(viewpoint, dtype=float)
    world = geometry.transform_points(T_world_part, model.points)
    normals = model.normals @ np.asarray(T_world_part)[:3, :3].T
    facing = np.einsum("ij,ij->i", normals, eye - world) > 0
    coverage, contradicted = _along_rays(world[facing], context, eye, s)
    why = None
    if fitness < s.min_fitness:
        why = f"fitness {fitness:.2f} < {s.min_fitness:.2f}"
    elif rmse > s.max_rmse:
        why = f"inlier RMSE {rmse * 1000:.2f} mm > {s.max_rmse * 1000:.2f} mm"
    elif contradicted > s.max_contradicted:
        why = f"the camera saw through {100 * contradicted:.0f}% of the scan's side facing it"
    elif coverage < min_coverage:
        why = f"the seen depth explains {100 * coverage:.0f}% of the scan's side facing the camera"
    return Verdict(T_world_part, fitness, rmse, 0.0, float("nan"), why is None, why, coverage, contradicted)


def _along_rays(points: np.ndarray, context: np.ndarray, eye: np.ndarray, s: RefineSettings) -> tuple[float, float]:
    """(coverage, contradicted) of model ``points`` (world) against the seen ``context`` along rays from ``eye``.

    Each point's nearest observed ray within ``s.ray_radius`` (rays as points of a plane 1 m in front of
    the eye, as :func:`~asmteach.core.perception.surface_check.surface_check` does); points without one,
    or hidden by something nearer, give no evidence. ``(0, 1)`` when nothing can be judged.
    """
    from scipy.spatial import cKDTree

    if len(points) == 0 or len(context) == 0:
        return 0.0, 1.0
    axis, plane = ray_plane(points.mean(axis=0) - eye)
    obs = context - eye
    obs = obs[obs @ axis > 0]
    if len(obs) == 0:
        return 0.0, 1.0
    obs_dist = np.linalg.norm(obs, axis=1)
    rel = points - eye
    dist = np.linalg.norm(rel, axis=1)
    gap, j = cKDTree(plane(obs)).query(plane(rel), distance_upper_bound=s.ray_radius)
    found = np.isfinite(gap)
    delta = obs_dist[j[found]] - dist[found]
    judged = int(np.sum(delta >= -s.surface_off))  # a nearer surface hides the point: no evidence
    if judged == 0:
        return 0.0, 1.0
    return float(np.sum(np.abs(delta) <= s.surface_fit)) / judged, float(np.sum(delta > s.surface_off)) / judged
