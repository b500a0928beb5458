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
   camera should see, support on the table: :func:`~asmteach.core.perception.registration.verify`); the
   best verified one is the rough pose. When none verifies, the next ten
   hypotheses get their turn (``max_rounds``);
4. when no CVFH hypothesis verifies, the part's stable rests on the table at
   evenly spaced yaws become the hypotheses and go through step 3
   (:mod:`~asmteach.plugins.detectors.cvfh.resting`; ``details["source"]``
   says which source the pose came from);
5. the verified pose is tried again turned by each *hull twin* (a rotation
   keeping the convex hull, not the part); the pose the observed points
   favour wins, and twins the view cannot tell apart are listed in
   ``details["ambiguous"]``;
6. the pose is tried again turned by each *near twin* (a turn that keeps the
   part's surface within ``near_twin_tol``, e.g. a keyed peg about its axis)
   and by small nudges (``nudge_deg``) - a short coarse ICP first, the full one
   only when it does not fall back onto a pose already tried
   (``near_screen_iterations``); the best-scoring verified pose wins,
   and when a distinct one (beyond the part's symmetries, ``distinct_mm`` /
   ``distinct_deg``) scores within ``ambiguity_margin`` and the ray evidence
   does not rule it out, the view cannot tell them apart: ``found: false``
   with the reason ("ambiguous: ...").

Nothing verified means ``found: false`` with the reason of the closest miss;
a wrong pose is never reported as found.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from pydantic import Field

from asmteach.core import geometry
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.models import Detection, StrictModel, TablePlane, Vec3
from asmteach.core.perception.depth_camera import KinectSettings, look_at
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
from asmteach.core.perception.viewpoint import StageClock, resolve_viewpoint
from asmteach.core.symmetry import part_symmetries
from asmteach.plugins.detectors.cvfh.prescore import SampleIndex, near_shares, support_gap
from asmteach.plugins.detectors.cvfh.resting import (
    disagreement,
    hull_twins,
    near_twins,
    resting_hypotheses,
    stable_rests,
)
from asmteach.plugins.detectors.cvfh.views import (
    CloudDescription,
    DescriptorSettings,
    ViewDatabase,
    ViewSettings,
    describe_cloud,
    load_or_build,
)

__all__ = ["CvfhIcpDetector"]

class CvfhSettings(StrictModel):
    """Settings of the ``cvfh_icp`` detector."""

    viewpoint: Vec3 | None = Field(
        None,
        description="camera centre in the world frame, metres, when detect() is not given one (the CVFH "
        "viewpoint component and the verification's rays need it); no default: a wrong camera rejects every pose",
    )
    segment: SegmentSettings = Field(default_factory=SegmentSettings)
    descriptors: DescriptorSettings = Field(default_factory=DescriptorSettings)
    views: ViewSettings = Field(default_factory=ViewSettings)
    camera: KinectSettings = Field(default_factory=KinectSettings, description="the camera that renders the views")
    refine: RefineSettings = Field(default_factory=RefineSettings)
    nn_views: int = Field(10, ge=1, le=42, description="nearest views (by CVFH distance) turned into hypotheses")
    max_rolls: int = Field(3, ge=1, le=8, description="CRH correlation peaks tried per view (plus their half turns)")
    blind_rolls: int = Field(12, ge=1, description="rolls tried, evenly spaced, when a CRH is undefined")
    icp_candidates: int = Field(10, ge=1, description="hypotheses given a coarse ICP after pre-scoring")
    coarse_points: int = Field(250, ge=20, description="cluster points used by the coarse ICP")
    verify_candidates: int = Field(
        4, ge=1, description="best coarse results given a fine ICP and verification (until two are accepted)"
    )
    max_rounds: int = Field(3, ge=1, description="rounds of icp_candidates hypotheses tried until one verifies")
    max_clusters: int = Field(3, ge=1, description="largest plausible clusters tried, biggest first")
    resting_poses: int = Field(
        8, ge=0, description="most likely stable rests tried when no CVFH hypothesis verifies (0: never)"
    )
    resting_yaws: int = Field(24, ge=1, description="yaws per stable rest, evenly spaced")
    resting_rounds: int = Field(
        8, ge=1,
        description="rounds of icp_candidates resting hypotheses tried until one verifies: they are many (rests x "
        "yaws) and a part seen end-on ranks the right yaw low, since every yaw explains the face it shows",
    )
    twin_fit: float = Field(0.004, gt=0.0, description="a pose explains a point within this along its ray, metres")
    twin_off: float = Field(0.010, gt=0.0, description="a pose clearly fails a point beyond this along its ray")
    twin_min_points: int = Field(10, ge=1, description="points of evidence needed to tell hull twins apart")
    twin_ratio: float = Field(
        4.0, ge=1.0, description="the evidence against the loser must exceed that against the winner this many times"
    )
    size_slack: float = Field(1.25, ge=1.0, description="a cluster wider than this times the part's is skipped")
    near_twin_tol: float = Field(
        0.002, ge=0.0,
        description="a turn keeping the part's surface within this mean distance (metres) of itself is a near twin "
        "whose pose must score clearly worse than the found one (0: no near-twin check)",
    )
    ambiguity_margin: float = Field(
        0.02, ge=0.0,
        description="a distinct verified pose scoring within this of the best makes the view ambiguous: found "
        "false (measured on 49 corpus parts: wrong near-twin poses score within 0.007 of the right one, views that "
        "tell them apart put the right one ahead by >= 0.026)",
    )
    nudge_deg: float = Field(
        10.0, ge=0.0, description="the found pose is also tried turned by this about each principal axis (0: not)"
    )
    near_screen_iterations: int = Field(
        10,
        ge=0,
        description="near twins and nudges: a short coarse ICP (this many iterations, on the coarse subsample) "
        "first; a turned pose it brings within half of distinct_mm / distinct_deg of a pose already tried gets no "
        "full ICP (0: every turned pose gets the full ICP)",
    )
    near_fit: float = Field(0.003, gt=0.0, description="near twins: a pose explains a point within this along its ray")
    near_off: float = Field(0.006, gt=0.0, description="near twins: a pose clearly fails a point beyond this")
    distinct_mm: float = Field(5.0, gt=0.0, description="poses farther apart than this (mm) are distinct")
    distinct_deg: float = Field(5.0, gt=0.0, description="poses turned further apart than this (deg) are distinct")


@dataclass
class _Prepared:
    model: ModelCloud
    db: ViewDatabase
    diameter: float
    built_now: bool
    build_ms: float
    rests: np.ndarray
    """(k, 4, 4) stable rests on z = 0 (see :func:`stable_rests`)."""
    twins: list[np.ndarray]
    """Part-frame rotations keeping the convex hull but not the part (see :func:`hull_twins`)."""
    near: list[np.ndarray]
    """Part-frame rotations keeping the part nearly (see :func:`near_twins`)."""
    own: list[np.ndarray]
    """The part's own symmetries (poses that differ by one are the same pose)."""
    samples: SampleIndex
    """The model's surface samples indexed for the pre-score's distance tests."""


@dataclass
class _Cluster:
    """One observed cluster and what its hypotheses are checked against (world frame, metres)."""

    cluster: np.ndarray
    context: np.ndarray
    icp_in: np.ndarray
    icp_sub: np.ndarray
    table: TablePlane
    eye: np.ndarray
    judged: list[np.ndarray] = field(default_factory=list)
    """Poses the hull-twin pass verified and judged by the ray evidence (the near-twin pass leaves them alone)."""
    icp_passes: int = 0
    """Open3D ICP runs so far (a coarse + fine refinement is two): the detection's main cost."""

    def icp(
        self, points: np.ndarray, model: ModelCloud, T_world_part: np.ndarray, s: RefineSettings, **passes: bool
    ) -> np.ndarray:
        """:func:`icp_refine` of ``points`` (world, metres), counted in :attr:`icp_passes`."""
        self.icp_passes += passes.get("coarse", True) + passes.get("fine", True)
        return icp_refine(points, model, T_world_part, s, **passes)


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
        self._prepared: dict[str, _Prepared] = {}

    # ------------------------------------------------------------ preparation
    def prepare(self, part: PartModel) -> None:
        """Load (or build and cache) the part's view database and model cloud."""
        self._prep(part)

    def _prep(self, part: PartModel) -> _Prepared:
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
            F = np.array(part.mesh.principal_inertia_vectors, dtype=float)
            for axis in F:
                for a in (-s.nudge_deg, s.nudge_deg):
                    R = geometry.from_rotvec(np.radians(a) * axis / np.linalg.norm(axis))[:3, :3]
                    near.append(geometry.from_rotation(R, com - R @ com))
        samples = SampleIndex.of(model, self.seed)
        prep = _Prepared(
            model, db, diameter, built, 1000.0 * (time.perf_counter() - t0), rests, twins, near, own, samples
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
        prep: _Prepared,
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
        hyps = self._hypotheses(desc, prep.db, T_world_vcam)
        # Cheap pre-score: share of cluster points near the model surface, less a penalty for not resting
        # on the table (a hypothesis 20 deg off still nearly touches it; a wrong one floats or sinks).
        sub = cluster[:: max(1, len(cluster) // 300)]

        def prescored(hs: list[tuple[int, np.ndarray, float]]) -> list[tuple[int, np.ndarray, float]]:
            """``hs`` best pre-score first (a stable sort: ties keep their order)."""
            # One distance query for every hypothesis: the per-call overhead was most of the matching step.
            shares = near_shares([h[1] for h in hs], sub, prep.model, s.refine.icp_coarse_distance, prep.samples)
            score = [float(sh) - min(1.0, abs(support_gap(h[1], prep.model, table)) / 0.03)
                     for h, sh in zip(hs, shares, strict=True)]
            return [hs[i] for i in sorted(range(len(hs)), key=lambda i: -score[i])]

        scored = prescored(hyps)
        clock.lap("matching")
        # Squared distances, one coordinate at a time: on a Kinect frame's 300 000 points np.linalg.norm of the
        # difference array took longer than describing the cluster.
        q = [pts[:, k] - centroid[k] for k in range(3)]
        context = pts[q[0] * q[0] + q[1] * q[1] + q[2] * q[2] < (prep.diameter + 0.02) ** 2]
        icp_in = _down(cluster, s.descriptors.voxel)
        job = _Cluster(cluster, context, icp_in, icp_in[:: max(1, len(icp_in) // s.coarse_points)], table, eye)
        best, closest, info = self._rounds(scored, job, prep, clock)
        info["source"] = "cvfh"
        if best is None and len(prep.rests):
            rest = [(-1, T, yaw) for T, yaw in resting_hypotheses(
                cluster, prep.model, prep.rests, table, eye, s.resting_yaws)]
            scored = prescored(rest)
            clock.lap("matching")
            best, closest2, info2 = self._rounds(scored, job, prep, clock, s.resting_rounds)
            if closest2 is not None and (closest is None or closest2.score > closest.score):
                closest = closest2
            if best is not None:
                info = {**info2, "source": "resting", "rounds": info["rounds"] + info2["rounds"]}
        if best is not None and prep.twins:
            best, info["twins"], ambiguous = self._twins(best, job, prep, clock)
            if ambiguous:
                info["ambiguous"] = ambiguous
        if best is not None and prep.near:
            best, rival = self._near_twins(best, job, prep, clock)
            if rival is not None:
                # The view cannot tell two distinct poses apart: reporting either would be a guess.
                mm, deg = self._apart(best.T_world_part, rival.T_world_part, prep.own)
                why = (f"ambiguous: a pose {mm:.0f} mm and {deg:.0f} deg away explains the view as well (score "
                       f"{rival.score:.3f} vs {best.score:.3f}); the part is nearly symmetric and this view misses "
                       f"the difference")
                return _Outcome(None, replace(best, accepted=False, why=why), info, job.icp_passes)
        info = {**info, "hypotheses": len(hyps), "cluster_points": len(cluster)}
        return _Outcome(best, closest, info, job.icp_passes)

    def _rounds(
        self, scored: list[tuple[int, np.ndarray, float]], job: _Cluster, prep: _Prepared, clock: StageClock,
        max_rounds: int | None = None,
    ) -> tuple[Verdict | None, Verdict | None, dict]:
        """Refine and verify pre-scored hypotheses in rounds until one verifies: ``(best, closest miss, info)``.

        At most ``max_rounds`` rounds (default: the ``max_rounds`` setting).
        """
        s = self.settings
        max_rounds = s.max_rounds if max_rounds is None else max_rounds
        best: Verdict | None = None
        closest: Verdict | None = None
        info: dict = {}
        rounds = 0
        # Rounds of icp_candidates hypotheses, best pre-scored first; later rounds only when nothing verified.
        for first in range(0, min(len(scored), max_rounds * s.icp_candidates), s.icp_candidates):
            rounds += 1
            # Coarse ICP on a subsample for every candidate, fine ICP and verification for the best few.
            batch = scored[first : first + s.icp_candidates]
            Ts = [job.icp(job.icp_sub, prep.model, T0, s.refine, fine=False) for _, T0, _ in batch]
            coarse = []
            shares = near_shares(Ts, job.icp_sub, prep.model, s.refine.inlier_distance, prep.samples)
            for (view, _, roll), T, share in zip(batch, Ts, shares, strict=True):
                score = float(share)
                if abs(support_gap(T, prep.model, job.table)) > 2.0 * s.refine.support_tolerance:
                    score -= 1.0  # resting inside the table or floating: last in line
                coarse.append((score, view, T, roll))
            coarse.sort(key=lambda c: -c[0])
            clock.lap("icp")
            accepted = 0
            for _, view, T1, roll in coarse[: s.verify_candidates]:
                if accepted >= 2:
                    break  # two verified poses are enough to pick the better of a near-symmetric pair
                T = job.icp(job.icp_in, prep.model, T1, s.refine, coarse=False)
                clock.lap("icp")
                v = verify(T, job.cluster, job.context, job.eye, prep.model, s.refine, job.table)
                clock.lap("verify")
                accepted += v.accepted
                if v.accepted and (best is None or v.score > best.score):
                    best = v
                    info = {"view": int(view), "roll_deg": round(float(np.degrees(roll)), 2)}
                if closest is None or v.score > closest.score:
                    closest = v
            if best is not None:
                break
        info["rounds"] = rounds
        return best, closest, info

    def _twins(
        self, best: Verdict, job: _Cluster, prep: _Prepared, clock: StageClock
    ) -> tuple[Verdict, int, list[dict]]:
        """Try ``best`` turned by each hull twin; keep the pose the disagreement evidence favours.

        Returns the chosen verdict, the number of twins that verified, and the
        twins the view cannot tell from it (pose, scores, evidence), for the report.
        """
        s = self.settings
        verified, undecided = 0, []
        for S in prep.twins:
            T = job.icp(job.icp_in, prep.model, best.T_world_part @ S, s.refine, coarse=False)
            v = verify(T, job.cluster, job.context, job.eye, prep.model, s.refine, job.table)
            clock.lap("verify")
            if not v.accepted:
                continue
            verified += 1
            job.judged += [T, best.T_world_part]
            ev = disagreement(best.T_world_part, T, job.cluster, job.eye, prep.model, s.twin_fit, s.twin_off)
            verdict = ev.verdict(s.twin_min_points, s.twin_ratio)
            if verdict == "b" or (verdict == "ambiguous" and v.score > best.score):
                best, v = v, best
            if verdict == "ambiguous":
                undecided.append(v)
        # the evidence is stated against the final choice
        ambiguous = []
        for v in undecided:
            ev = disagreement(best.T_world_part, v.T_world_part, job.cluster, job.eye, prep.model, s.twin_fit,
                              s.twin_off)
            ambiguous.append({"T_world_part": v.T_world_part.tolist(), "fitness": round(v.fitness, 4),
                              "violation": round(v.violation, 4), "points_against": [ev.against_a, ev.against_b]})
        clock.lap("verify")
        return best, verified, ambiguous

    def _near_twins(
        self, best: Verdict, job: _Cluster, prep: _Prepared, clock: StageClock
    ) -> tuple[Verdict, Verdict | None]:
        """Try ``best`` turned by each near twin: ``(the best-scoring verified pose, a distinct rival or None)``.

        A rival is a verified pose, distinct from the winner (beyond the part's
        own symmetries), scoring within ``ambiguity_margin`` of it, that the
        disagreement evidence (``near_fit``, ``near_off``) does not rule out.
        """
        s = self.settings
        found = [best]
        # Hull twins the hull pass verified were judged there (found with details["ambiguous"] when the view
        # cannot tell); the ones it could not verify (its ICP is fine-only) get a full ICP here.
        judged = list(job.judged)
        screen = s.refine.model_copy(update={"icp_iterations": s.near_screen_iterations})
        screen = screen if s.near_screen_iterations > 0 else None
        for S in prep.near:
            T0 = best.T_world_part @ S
            tried = [v.T_world_part for v in found] + judged
            # 3 in 4 turned poses fall back onto a pose already tried (the found one): a full ICP from them costs
            # 4-6x a short coarse one, which already brings them within a few mm / deg of it.
            if screen is not None and not self._distinct(
                job.icp(job.icp_sub, prep.model, T0, screen, fine=False), tried, prep.own, 0.5
            ):
                clock.lap("icp")
                continue
            T = job.icp(job.icp_in, prep.model, T0, s.refine)
            clock.lap("icp")
            if not self._distinct(T, tried, prep.own):
                continue  # ICP pulled it back onto a pose already tried
            v = verify(T, job.cluster, job.context, job.eye, prep.model, s.refine, job.table)
            clock.lap("verify")
            if v.accepted:
                found.append(v)
        found.sort(key=lambda v: -v.score)
        winner = found[0]
        for v in found[1:]:
            if winner.score - v.score > s.ambiguity_margin or not self._distinct(
                v.T_world_part, [winner.T_world_part], prep.own
            ):
                continue
            ev = disagreement(winner.T_world_part, v.T_world_part, job.cluster, job.eye, prep.model, s.near_fit,
                              s.near_off)
            if ev.verdict(s.twin_min_points, s.twin_ratio) != "a":
                return winner, v
        return winner, None

    def _apart(self, A: np.ndarray, B: np.ndarray, own: list[np.ndarray]) -> tuple[float, float]:
        """``(mm, deg)`` between two poses, the nearest of ``B``'s symmetric equivalents ``B @ S``."""
        BS = np.einsum("ij,sjk->sik", B, np.asarray(own).reshape(-1, 4, 4))
        mm = 1000.0 * np.linalg.norm(BS[:, :3, 3] - A[:3, 3], axis=1)
        cos = (np.einsum("ij,sij->s", A[:3, :3], BS[:, :3, :3]) - 1.0) / 2.0
        deg = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
        i = int(np.argmin(mm + deg))
        return float(mm[i]), float(deg[i])

    def _distinct(self, T: np.ndarray, others: list[np.ndarray], own: list[np.ndarray], scale: float = 1.0) -> bool:
        """Whether ``T`` is farther than ``scale * distinct_mm`` or turned more than ``scale * distinct_deg`` from
        every other."""
        s = self.settings
        for O in others:
            mm, deg = self._apart(T, O, own)
            if mm <= scale * s.distinct_mm and deg <= scale * s.distinct_deg:
                return False
        return True

    def _hypotheses(
        self, desc: CloudDescription, db: ViewDatabase, T_world_vcam: np.ndarray
    ) -> list[tuple[int, np.ndarray, float]]:
        """``(view, T_world_part, roll)`` from the nearest views and their CRH roll peaks."""
        from asmteach.plugins.detectors.cvfh.descriptors import crh_roll_candidates

        s = self.settings
        # L1 distance between every cluster region and every view region; a view scores its best pair.
        d = np.abs(desc.hists[:, None, :] - db.hists[None, :, :]).sum(axis=2).min(axis=0)
        view_best = np.full(len(db.T_acam_part), np.inf)
        np.minimum.at(view_best, db.region_view, d)
        order = [int(i) for i in np.argsort(view_best) if np.isfinite(view_best[i])][: s.nn_views]
        out: list[tuple[int, np.ndarray, float]] = []
        for i in order:
            if desc.crh is None or not np.any(db.crh[i]):
                # A face seen head-on has no roll histogram: try rolls all round instead.
                rolls = list(np.linspace(-np.pi, np.pi, s.blind_rolls, endpoint=False))
            else:
                # The roll that turns the view into the cluster (view a -> cluster b).
                rolls = crh_roll_candidates(db.crh[i], desc.crh, max_peaks=s.max_rolls)
            for roll in rolls:
                # Cluster ~ Rz(roll) view, both centroids on +z: rotate about the view centroid, then move it.
                # (Rz written out: scipy's Rotation per roll was 4 % of detect.)
                c, s_ = np.cos(roll), np.sin(roll)
                T_align = np.eye(4)
                T_align[:3, :3] = [[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]
                T_align[:3, 3] = desc.centroid - T_align[:3, :3] @ db.centroids[i]
                out.append((i, T_world_vcam @ T_align @ db.T_acam_part[i], float(roll)))
        return out


def _width(points: np.ndarray) -> float:
    """Diagonal of a cluster's bounding box aligned with its principal axes in the table plane, metres.

    A world-axis-aligned box would grow by up to sqrt(2) for a part turned 45 deg
    about the table normal and reject it as too wide.
    """
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    if len(xy) >= 3:
        _, vecs = np.linalg.eigh(xy.T @ xy)
        xy = xy @ vecs
    return float(np.linalg.norm([*np.ptp(xy, axis=0), np.ptp(points[:, 2])]))


def _up_for(direction: np.ndarray) -> np.ndarray:
    d = direction / np.linalg.norm(direction)
    return np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.95 else np.array([1.0, 0.0, 0.0])


def _down(points: np.ndarray, voxel: float) -> np.ndarray:
    return np.asarray(to_o3d(points).voxel_down_sample(voxel).points)
