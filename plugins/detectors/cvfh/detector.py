"""``cvfh_icp``: CVFH + CRH view matching, ICP and hypothesis verification.

Pipeline (paper, "Rough detection using point cloud"), all in the world frame
(metres, z up) unless said otherwise:

1. check the cloud, fit and remove the table plane (Open3D RANSAC), cluster
   what stands on it (DBSCAN; pieces a self-occlusion split apart are merged
   while the union fits the part); clusters too big for the part are skipped;
2. describe each cluster in a virtual camera frame at the viewpoint (the
   ``viewpoint`` argument of :meth:`detect`, else the setting; there is no
   default camera, :class:`UserError` without one) looking
   at the cluster (CVFH regions + CRH), match its regions against the 42-view
   database (k nearest views), and turn every (view, CRH roll peak) pair into
   a pose hypothesis;
3. pre-score hypotheses by the share of cluster points near the model and
   whether they rest on the table, refine the best with point-to-plane ICP
   (coarse on a subsample for ten, fine for the best four), and verify them
   (fitness, inlier RMSE, free-space violations, the model surface the
   camera should see, support on the table: :func:`~asmteach.core.perception.registration.verify`; a
   rejected pose within ``rest_snap_deg`` of a stable rest is verified again snapped onto it:
   :func:`~asmteach.plugins.detectors.cvfh.pose_search.verify_at_rest`); the best verified one is the
   rough pose. When none verifies, the next ten hypotheses get their turn (``max_rounds``);
4. when no CVFH hypothesis verifies, the part's stable rests on the table at
   evenly spaced yaws become the hypotheses and go through step 3
   (:mod:`~asmteach.plugins.detectors.cvfh.resting`; ``details["source"]``
   says which source the pose came from);
5. the verified pose is tried again turned by each *hull twin* (a rotation
   keeping the convex hull, not the part); the pose the observed points
   favour wins. When the view cannot tell a twin from it, the detection is
   ``found: false`` ("ambiguous: ..."), the poses listed in
   ``details["ambiguous"]`` (best-scoring first) with
   ``details["ambiguous_kind"] = "hull_twin"``: the part can be picked by its
   outside and looked at again once moved
   (:func:`asmteach.core.detect_correct.detect_and_correct`'s ``provisional``);
6. the pose is tried again turned by each *near twin* (a turn that keeps the
   part's surface within ``near_twin_tol``, e.g. a keyed peg about its axis)
   and by small nudges (``nudge_deg``) - a short coarse ICP first, the full one
   only when it does not fall back onto a pose already tried
   (``near_screen_iterations``); the best-scoring verified pose wins,
   and when a distinct one (beyond the part's symmetries, ``distinct_mm`` /
   ``distinct_deg``) scores within ``ambiguity_margin`` and the ray evidence
   does not rule it out, the view cannot tell them apart: ``found: false``
   with the reason ("ambiguous: ...") and the poses in ``details["ambiguous"]``
   (``details["ambiguous_kind"] = "near_twin"``);
7. the winner's rotation uncertainty is estimated from the seen points (linearised point-to-plane
   registration with the Kinect's noise, turns about an axis of revolution left out:
   :func:`~asmteach.plugins.detectors.cvfh.pinning.rotation_sigma_deg`); when ``pin_sigmas`` times it
   exceeds ``distinct_deg``, the view does not pin the pose down to the tolerance and it is not reported
   (``details["rotation_sigma_deg"]``).

Thin parts (thinner than ``thin_height``) also keep their points below the table-removal height where their
patch stands clearly above the table (:mod:`~asmteach.plugins.detectors.cvfh.thin`).

Nothing verified means ``found: false`` with the reason of the closest miss;
a wrong pose is never reported as found.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from asmteach.core import geometry
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.models import Detection, TablePlane
from asmteach.core.perception.depth_camera import look_at
from asmteach.core.perception.open3d_tools import one_thread, to_o3d
from asmteach.core.perception.registration import Verdict, model_cloud
from asmteach.core.perception.segmentation import check_cloud, cluster_objects, merge_nearby, remove_table
from asmteach.core.perception.viewpoint import StageClock, resolve_viewpoint
from asmteach.core.symmetry import part_symmetries, principal_frame
from asmteach.core.symmetry.near import NearSymmetry
from asmteach.plugins.detectors.cvfh.pinning import free_axes, pin_rivals
from asmteach.plugins.detectors.cvfh.pose_search import (
    ClusterJob,
    Prepared,
    hull_twin_pass,
    near_twin_pass,
    poses_apart,
    rest_pass,
    settle,
    verify_rounds,
    view_hypotheses,
)
from asmteach.plugins.detectors.cvfh.prescore import SampleIndex, near_shares, support_gap
from asmteach.plugins.detectors.cvfh.resting import (
    every_rest,
    hull_twins,
    near_twins,
    resting_hypotheses,
    stable_rests,
)
from asmteach.plugins.detectors.cvfh.settings import CvfhSettings
from asmteach.plugins.detectors.cvfh.thin import raised_mask
from asmteach.plugins.detectors.cvfh.views import describe_cloud, load_or_build

__all__ = ["CvfhIcpDetector"]


@dataclass
class _Outcome:
    best: Verdict | None = None
    closest: Verdict | None = None
    details: dict = field(default_factory=dict)
    icp_passes: int = 0


class CvfhIcpDetector(Detector):
    """CVFH + CRH matching against 42 rendered views, point-to-plane ICP, verification."""

    Settings = CvfhSettings
    settings: CvfhSettings

    def __init__(self, settings=None, *, seed: int = 0) -> None:  # type: ignore[no-untyped-def]
        super().__init__(settings, seed=seed)
        self._prepared: dict[str, Prepared] = {}

    # ------------------------------------------------------------ preparation
    def prepare(self, part: PartModel) -> None:
        """Load (or build and cache) the part's view database and model cloud."""
        self._prep(part)

    def _prep(self, part: PartModel) -> Prepared:
        key = part.source_hash or part.name
        if key in self._prepared:
            return self._prepared[key]
        t0 = time.perf_counter()
        s = self.settings
        db, built = load_or_build(part.mesh, key, s.views, s.descriptors, s.camera)
        model = model_cloud(part.mesh, s.refine.model_points, seed=self.seed)
        diameter = float(np.linalg.norm(np.ptp(np.asarray(part.mesh.vertices), axis=0)))
        com = np.asarray(part.center_of_mass, float)
        rests = stable_rests(part.mesh, com, s.resting_poses) if s.resting_poses else np.zeros((0, 4, 4))
        own = part_symmetries(part.mesh, com)
        twins = hull_twins(part.mesh, com, own)
        near = near_twins(part.mesh, com, s.near_twin_tol, own=own) if s.near_twin_tol > 0 else []
        if s.nudge_deg > 0:
            # Small turns about the principal axes: a pose ICP left a few degrees off (a smooth free-form part)
            # is pulled to the right one, or shows the view does not pin it down.
            for axis in principal_frame(part.mesh).T:
                for a in (-s.nudge_deg, s.nudge_deg):
                    R = geometry.from_rotvec(np.radians(a) * axis)[:3, :3]
                    near.append(geometry.from_rotation(R, com - R @ com))
        samples = SampleIndex.of(model, self.seed)
        thin = float(part.mesh.bounding_box_oriented.primitive.extents.min()) < s.thin_height
        free = free_axes(part.mesh, com, s.pin_same) if s.pin_sigmas > 0 else np.zeros((0, 3))
        same = NearSymmetry(part.mesh, s.same_surface, seed=self.seed) if s.same_surface > 0 else None
        prep = Prepared(
            model,
            db,
            diameter,
            built,
            1000.0 * (time.perf_counter() - t0),
            rests,
            twins,
            near,
            own,
            samples,
            thin,
            free,
            same,
            every_rest(part.mesh, com) if s.rest_rivals_deg > 0 else np.zeros((0, 4, 4)),
        )
        self._prepared[key] = prep
        return prep

    # ------------------------------------------------------------ detection
    def detect(
        self,
        cloud: np.ndarray,
        part: PartModel,
        table: TablePlane | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Detection:
        """Find ``part`` in ``cloud`` ((n, 3) world frame, metres); see the module docstring.

        ``viewpoint`` is the camera centre ((3,), world frame, metres); ``None``
        uses the ``viewpoint`` setting, and :class:`UserError` without either. It orients the virtual camera the
        descriptors are computed in (CVFH's viewpoint component, CRH's roll)
        and casts the rays of the free-space check; ``details["viewpoint"]``
        reports the one used, ``details["icp_passes"]`` the Open3D ICP runs it took.
        """
        eye = resolve_viewpoint(viewpoint, self.settings.viewpoint)
        prep = self._prep(part)
        s = self.settings
        clock = StageClock()

        def fail(reason: str, **details: object) -> Detection:
            return Detection(part=part.name, found=False, reason=reason, timing_ms=clock.done(), details=details)

        pts, reason = check_cloud(cloud)
        if pts is None:
            return fail(reason or "invalid cloud")
        table, above, reason = remove_table(pts, s.segment, table=table, seed=self.seed)
        if table is not None and prep.thin:
            # Most of a thin part is below min_height: its low points are kept where their patch is raised.
            raised, _ = raised_mask(pts, table, s.segment.min_height, s.segment.max_height, s.thin_cell, s.thin_sigmas)
            above = pts[raised] if raised.sum() >= s.segment.min_cluster_points else above
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
            return fail(
                f"no cluster fits {part.name!r}: the smallest is {_width(clusters[-1]) * 1000:.0f} mm wide, "
                f"the part at most {prep.diameter * 1000:.0f} mm"
            )
        outcome = _Outcome()
        tried = icp_passes = 0
        for cluster in plausible[: s.max_clusters]:
            tried += 1
            with one_thread():  # one limit for the cluster's ~50 ICP calls, not a TBB re-sync around each
                got = self._detect_cluster(cluster, pts, prep, clock, table, eye)
            icp_passes += got.icp_passes
            if got.best is not None and (outcome.best is None or got.best.score > outcome.best.score):
                outcome.best, outcome.details = got.best, got.details
            if got.closest is not None and (outcome.closest is None or got.closest.score > outcome.closest.score):
                outcome.closest = got.closest
                if got.best is None:  # the closest rejected pose's evidence goes with it (an ambiguity)
                    outcome.details = got.details
            if outcome.best is not None:
                break  # the largest plausible cluster that verifies is the part
        timing = clock.done()
        if outcome.best is None:
            why = outcome.closest.why if outcome.closest is not None else "no cluster could be described"
            return Detection(
                part=part.name,
                found=False,
                reason=f"{part.name!r} not found: best hypothesis rejected ({why})",
                timing_ms=timing,
                details={
                    **{k: outcome.details[k] for k in ("ambiguous", "ambiguous_kind") if k in outcome.details},
                    "clusters": len(clusters),
                    "clusters_tried": tried,
                    "icp_passes": icp_passes,
                    "table": table.model_dump(mode="json"),
                    "viewpoint": eye.tolist(),
                },
            )
        v = outcome.best
        return Detection(
            part=part.name,
            found=True,
            rough=v.T_world_part,
            fitness=v.fitness,
            inlier_rmse=v.inlier_rmse,
            timing_ms=timing,
            details={
                **outcome.details,
                "violation": v.violation,
                "support_gap_mm": round(v.support_gap * 1000.0, 3),
                "clusters": len(clusters),
                "clusters_tried": tried,
                "icp_passes": icp_passes,
                "table": table.model_dump(mode="json"),
                "viewpoint": eye.tolist(),
                "view_db_built_ms": round(prep.build_ms, 1) if prep.built_now else 0.0,
            },
        )

    def _detect_cluster(
        self,
        cluster: np.ndarray,
        pts: np.ndarray,
        prep: Prepared,
        clock: StageClock,
        table: TablePlane,
        eye: np.ndarray,
    ) -> _Outcome:
        s = self.settings
        centroid = cluster.mean(axis=0)
        T_world_vcam = look_at(eye, centroid, _up_for(centroid - eye))
        local = geometry.transform_points(geometry.invert(T_world_vcam), cluster)
        desc = describe_cloud(local, s.descriptors, lap=clock.lap)
        clock.lap("descriptors")
        if desc is None:
            return _Outcome()
        hyps = view_hypotheses(desc, prep.db, T_world_vcam, s)
        # Cheap pre-score: share of cluster points near the model surface, less a penalty for not resting
        # on the table (a hypothesis 20 deg off still nearly touches it; a wrong one floats or sinks).
        sub = cluster[:: max(1, len(cluster) // 300)]

        def prescored(hs: list[tuple[int, np.ndarray, float]]) -> list[tuple[int, np.ndarray, float]]:
            """``hs`` best pre-score first (a stable sort: ties keep their order)."""
            # One distance query for every hypothesis: the per-call overhead was most of the matching step.
            shares = near_shares([h[1] for h in hs], sub, prep.model, s.refine.icp_coarse_distance, prep.samples)
            score = [
                float(sh) - min(1.0, abs(support_gap(h[1], prep.model, table)) / 0.03)
                for h, sh in zip(hs, shares, strict=True)
            ]
            return [hs[i] for i in sorted(range(len(hs)), key=lambda i: -score[i])]

        scored = prescored(hyps)
        clock.lap("matching")
        # Squared distances, one coordinate at a time: on a Kinect frame's 300 000 points np.linalg.norm of the
        # difference array took longer than describing the cluster.
        q = [pts[:, k] - centroid[k] for k in range(3)]
        context = pts[q[0] * q[0] + q[1] * q[1] + q[2] * q[2] < (prep.diameter + 0.02) ** 2]
        icp_in = _down(cluster, s.descriptors.voxel)
        job = ClusterJob(cluster, context, icp_in, icp_in[:: max(1, len(icp_in) // s.coarse_points)], table, eye)
        best, closest, info = verify_rounds(scored, job, prep, clock, s)
        info["source"] = "cvfh"
        if best is None and len(prep.rests):
            rest = [
                (-1, T, yaw)
                for T, yaw in resting_hypotheses(cluster, prep.model, prep.rests, table, eye, s.resting_yaws)
            ]
            scored = prescored(rest)
            clock.lap("matching")
            best, closest2, info2 = verify_rounds(scored, job, prep, clock, s, s.resting_rounds)
            if closest2 is not None and (closest is None or closest2.score > closest.score):
                closest = closest2
            if best is not None:
                info = {**info2, "source": "resting", "rounds": info["rounds"] + info2["rounds"]}
        if best is not None and prep.twins:
            best, info["twins"], ambiguous = hull_twin_pass(best, job, prep, clock, s)
            if ambiguous:
                # A twin of the convex hull explains every point seen as well: the view cannot say which side
                # is which, and reporting either would be a guess. The poses go in details["ambiguous"] (the
                # best-scoring first), so a caller that can look again once the part is moved may go on with one
                # (detect_and_correct's ``provisional``).
                why = (
                    f"ambiguous: the part turned by a twin of its convex hull explains the view as well "
                    f"({len(ambiguous)} such pose(s)); the faces that tell them apart are out of sight"
                )
                first = {
                    "T_world_part": best.T_world_part.tolist(),
                    "fitness": round(best.fitness, 4),
                    "violation": round(best.violation, 4),
                }
                info["ambiguous"] = [first, *ambiguous]
                info["ambiguous_kind"] = "hull_twin"
                return _Outcome(None, replace(best, accepted=False, why=why), info, job.icp_passes)
        at_rest = False
        if best is not None and prep.near:
            best, rivals = near_twin_pass(best, job, prep, clock, s)
            poses = [best.T_world_part, *(v.T_world_part for v in rivals)]
            settled = rest_pass(poses, job, prep, clock, s) if rivals else None
            if settled is not None:
                # The view cannot tell them apart, but the table can: one of them rests on it.
                info["at_rest"] = {"rivals": "near_twin", "poses": 1 + len(rivals)}
                best, at_rest = settled, True
            elif rivals:
                # The view cannot tell two distinct poses apart: reporting either would be a guess.
                rival = rivals[0]
                mm, deg = poses_apart(best.T_world_part, rival.T_world_part, prep.own)
                why = (
                    f"ambiguous: a pose {mm:.0f} mm and {deg:.0f} deg away explains the view as well (score "
                    f"{rival.score:.3f} vs {best.score:.3f}); the part is nearly symmetric and this view misses "
                    f"the difference"
                )
                info["ambiguous"] = [  # the poses the view cannot tell apart, so that callers need not read `why`
                    {"T_world_part": v.T_world_part.tolist(), "score": round(v.score, 4)} for v in (best, rival)
                ]
                info["ambiguous_kind"] = "near_twin"
                return _Outcome(None, replace(best, accepted=False, why=why), info, job.icp_passes)
        if best is not None and s.pin_sigmas > 0:
            sigma, rivals = pin_rivals(best.T_world_part, job, prep, s, at_rest=at_rest)
            settled = None if at_rest or not rivals else rest_pass([best.T_world_part, *rivals], job, prep, clock, s)
            if settled is not None:
                # The view leaves a tilt free, and the table pins it: the pose turned both ways rests as one.
                info["at_rest"] = {"rivals": "unpinned", "poses": 1 + len(rivals)}
                best = settled
                sigma, rivals = pin_rivals(best.T_world_part, job, prep, s, at_rest=True)
            info["rotation_sigma_deg"] = round(sigma, 3)
            if rivals:
                # The seen points leave the pose free to turn by the tolerance: reporting it would be a guess.
                # The pose turned both ways by pin_sigmas sigma goes with it, so another view can judge them.
                why = (
                    f"the view does not pin the pose down: its rotation is uncertain by {sigma:.1f} deg (one "
                    f"sigma), {s.pin_sigmas:.0f} sigma > {s.distinct_deg:.0f} deg"
                )
                info["ambiguous"] = [{"T_world_part": T.tolist()} for T in (best.T_world_part, *rivals)]
                info["ambiguous_kind"] = "unpinned"
                return _Outcome(None, replace(best, accepted=False, why=why), info, job.icp_passes)
        if best is not None and not at_rest:
            rested = settle(best, job, prep, clock, s)
            if rested is not None:
                # ICP tilts a part the view pins otherwise (a filleted block 2.9 deg, the duck 3.1 deg, with four
                # stacked frames: over the 5 deg line at times); at its rest the table gives its tilt
                turn = np.degrees(geometry.rotation_distance(best.T_world_part, rested.T_world_part))
                info["at_rest"] = {"rivals": "none", "turn_deg": round(float(turn), 2)}
                best = rested
        info = {**info, "hypotheses": len(hyps), "cluster_points": len(cluster)}
        return _Outcome(best, closest, info, job.icp_passes)


def _width(points: np.ndarray) -> float:
    """Diagonal of a cluster's tightest box standing on the table (metres): the minimum-area rectangle of its
    footprint (x, y) and its height (z).

    A world-axis-aligned box would grow by up to sqrt(2) for a part turned 45 deg about the table normal; so
    would a box on the footprint's principal axes for a near-square footprint, whose axes are undefined (a
    54 x 52 mm block measured 75 x 77 mm, wider than the size check allows, and was never tried). The tightest
    rectangle has a side along an edge of the footprint's convex hull (rotating calipers).
    """
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    height = float(np.ptp(points[:, 2]))
    if len(xy) < 3:
        return float(np.linalg.norm([*np.ptp(xy, axis=0), height])) if len(xy) else 0.0
    from scipy.spatial import ConvexHull, QhullError

    try:
        hull = xy[ConvexHull(xy).vertices]
    except QhullError:  # collinear footprint: its box is the segment itself
        hull = xy
    edges = np.roll(hull, -1, axis=0) - hull
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    c, s = np.cos(angles), np.sin(angles)
    # each hull vertex in the frame of each edge: (edges, vertices)
    u = c[:, None] * hull[None, :, 0] + s[:, None] * hull[None, :, 1]
    v = -s[:, None] * hull[None, :, 0] + c[:, None] * hull[None, :, 1]
    du, dv = np.ptp(u, axis=1), np.ptp(v, axis=1)
    i = int(np.argmin(du * dv))
    return float(np.linalg.norm([du[i], dv[i], height]))


def _up_for(direction: np.ndarray) -> np.ndarray:
    d = direction / np.linalg.norm(direction)
    return np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.95 else np.array([1.0, 0.0, 0.0])


def _down(points: np.ndarray, voxel: float) -> np.ndarray:
    return np.asarray(to_o3d(points).voxel_down_sample(voxel).points)
