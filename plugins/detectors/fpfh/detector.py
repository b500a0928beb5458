"""``fpfh_ransac``: the baseline depth detector (Open3D FPFH + RANSAC + ICP).

Same scene preparation, ICP and verification as ``cvfh_icp`` (so the two
compare on the matching step alone): the cluster's FPFH features are matched
to the model's (a dense surface sample of the mesh) and Open3D's feature
RANSAC, seeded from the plugin seed, proposes the pose; ICP refines it and
the verification accepts or rejects it. A rejected pose triggers another
RANSAC round (``attempts``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.models import Detection, StrictModel, TablePlane, Vec3
from asmteach.plugins.detectors.cvfh.detector import StageClock, resolve_viewpoint
from asmteach.plugins.detectors.cvfh.refine import ModelCloud, RefineSettings, Verdict, icp_refine, model_cloud, verify
from asmteach.plugins.detectors.cvfh.segment import (
    SegmentSettings,
    check_cloud,
    cluster_objects,
    merge_nearby,
    remove_table,
    to_o3d,
)

import open3d as o3d  # isort: skip

__all__ = ["FpfhRansacDetector"]

reg = o3d.pipelines.registration


class FpfhSettings(StrictModel):
    """Settings of the ``fpfh_ransac`` detector (metres)."""

    viewpoint: Vec3 | None = Field(
        None,
        description="camera centre in the world frame, metres, when detect() is not given one (orients the "
        "cluster's normals, casts the verification's rays); no default",
    )
    segment: SegmentSettings = Field(default_factory=SegmentSettings)
    refine: RefineSettings = Field(default_factory=RefineSettings)
    voxel: float = Field(0.004, gt=0.0, description="voxel size of the clouds FPFH is computed on")
    normal_radius: float = Field(0.012, gt=0.0, description="normal estimation radius of the cluster")
    feature_radius: float = Field(0.025, gt=0.0, description="FPFH radius")
    ransac_iterations: int = Field(50000, ge=100, description="RANSAC iterations per attempt")
    ransac_confidence: float = Field(0.999, gt=0.0, lt=1.0)
    mutual_filter: bool = Field(True, description="keep only mutually nearest feature matches")
    attempts: int = Field(3, ge=1, description="RANSAC rounds until a pose verifies")
    max_clusters: int = Field(3, ge=1, description="largest plausible clusters tried, biggest first")
    size_slack: float = Field(1.25, ge=1.0, description="a cluster wider than this times the part's is skipped")


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
                res = reg.registration_ransac_based_on_feature_matching(
                    src,
                    prep.down,
                    feats,
                    prep.features,
                    s.mutual_filter,
                    dist,
                    reg.TransformationEstimationPointToPoint(False),
                    3,
                    [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(dist)],
                    reg.RANSACConvergenceCriteria(s.ransac_iterations, s.ransac_confidence),
                )
                clock.lap("matching")
                T0 = geometry.invert(np.asarray(res.transformation))
                T = icp_refine(np.asarray(src.points), prep.model, T0, s.refine)
                clock.lap("icp")
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
            },
        )


def _width(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.ptp(points, axis=0)))
