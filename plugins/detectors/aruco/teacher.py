"""The ``aruco`` teacher: ``T_A_B`` and ``v_a`` from RGB frames of a human demonstration.

Per frame: detect markers (OpenCV ``ArucoDetector``, edge-fitted sub-pixel
corners), one multi-marker PnP per part (:mod:`.pnp`). Over frames: the
assembled frames are the largest cluster of consistent relative poses
``T_A_B = T_cam_A^-1 T_cam_B``; planar flips left ambiguous in a frame are
resolved by agreement with that cluster; outliers are rejected by
reprojection error and by robust fusion (:mod:`.fusion`); a joint
Levenberg-Marquardt adjustment over all kept frames (unknowns: ``T_A_B`` and
each frame's ``T_cam_A``) polishes the fused pose and drops frames that do not
fit one rigid ``T_A_B``. Frames before the assembled ones where B moves toward
A, each refitted with B's rotation in A held at the taught one
(:mod:`.approach`), give ``v_a`` (:mod:`.insertion`); a learned ``v_a`` that
fails the python-fcl retreat check moves to the centre of the free retreat
directions near it.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Teacher
from asmteach.core.models import AssemblyTask, CameraIntrinsics, TeachingEvidence
from asmteach.core.parts import build_part
from asmteach.plugins.detectors.aruco.approach import refit_with_rotation
from asmteach.plugins.detectors.aruco.branches import follow_branch
from asmteach.plugins.detectors.aruco.detect import MarkerDetector
from asmteach.plugins.detectors.aruco.fusion import fuse_poses
from asmteach.plugins.detectors.aruco.insertion import (
    check_retreat,
    direction_from_approach,
    free_cone_centre,
    separation_direction,
)
from asmteach.plugins.detectors.aruco.joint import CornerSet, adjust, frame_rms
from asmteach.plugins.detectors.aruco.markers import MarkerRef, marker_table
from asmteach.plugins.detectors.aruco.pnp import MarkerObservation, PartPose, solve_part_pose
from asmteach.plugins.detectors.aruco.scene import DemoSettings
from asmteach.plugins.detectors.aruco.teacher_settings import ArucoTeacherSettings

__all__ = ["ArucoTeacher", "FrameResult"]


@dataclass
class FrameResult:
    """What the teacher made of one frame."""

    index: int
    pose_a: PartPose | None
    pose_b: PartPose | None
    obs_a: list[MarkerObservation]
    obs_b: list[MarkerObservation]
    T_A_B: np.ndarray | None = None

    @property
    def rms_px(self) -> float:
        """RMS reprojection error over both parts' corners, pixels."""
        num = den = 0.0
        for p in (self.pose_a, self.pose_b):
            if p is not None:
                n = 4 * len(p.marker_ids)
                num += n * p.rms_px**2
                den += n
        return float(np.sqrt(num / den)) if den else float("inf")


class ArucoTeacher(Teacher):
    """Learns ``T_A_B`` and ``v_a`` from frames showing markers on both parts."""

    Settings = ArucoTeacherSettings
    settings: ArucoTeacherSettings
    DemoSettings = DemoSettings
    """The run config's ``demo`` section (the rendered demonstration), checked by the config loader."""

    def demonstrate(
        self, task: AssemblyTask, demo: dict, camera_file: Path | None = None, out_dir: Path | None = None
    ) -> tuple[list[np.ndarray], CameraIntrinsics]:
        """Rendered demonstration frames with exact ground truth; see :mod:`.demonstration`."""
        from asmteach.plugins.detectors.aruco.demonstration import demonstrate

        return demonstrate(task, demo, camera_file, out_dir, self.seed)

    @classmethod
    def check_demonstration(cls, task: AssemblyTask, demo: dict, camera_file: Path | None = None):
        """What :meth:`demonstrate` needs (demo section, camera, markers), checked without rendering."""
        from asmteach.plugins.detectors.aruco.commands import check_demonstration

        return check_demonstration(task, demo, camera_file)

    # ------------------------------------------------------------ per frame
    def observe(self, frames: Sequence[np.ndarray], camera: CameraIntrinsics, task: AssemblyTask) -> list[FrameResult]:
        """Detect markers and solve each part's pose in every frame."""
        table = marker_table(task.part_a, task.part_b)
        det = MarkerDetector(
            {k[0] for k in table},
            refine=self.settings.corner_refinement,
            edge_max_line_rms=self.settings.edge_max_line_rms,
            edge_min_inliers=self.settings.edge_min_inliers,
        )
        K, dist = camera.K, camera.dist_array
        results: list[FrameResult] = []
        prior: dict[str, np.ndarray | None] = {"A": None, "B": None}
        for i, img in enumerate(frames):
            h, w = img.shape[:2]
            if (w, h) != (camera.width, camera.height):
                raise UserError(
                    f"frame {i} is {w}x{h} pixels but the camera intrinsics are for {camera.width}x{camera.height}; "
                    "give the camera file of these frames (--camera)"
                )
        # Detection is independent per frame and OpenCV releases the GIL: use every core.
        with ThreadPoolExecutor(max_workers=max(1, min(self.settings.threads or os.cpu_count() or 1, 16))) as pool:
            detections = list(pool.map(det.detect, frames))
        for i, found in enumerate(detections):
            obs: dict[str, list[MarkerObservation]] = {"A": [], "B": []}
            for key, corners in found.items():
                ref: MarkerRef | None = table.get(key)
                if ref is None:
                    continue
                m = ref.spec
                obs[ref.role].append(MarkerObservation(m.id, m.size, m.T_part_marker, corners))
            poses = {}
            for role in ("A", "B"):
                priors = [prior[role]] if prior[role] is not None else None
                poses[role] = (
                    solve_part_pose(obs[role], K, dist, priors=priors, reject_px=self.settings.marker_reject_px)
                    if obs[role]
                    else None
                )
                if poses[role] is not None:
                    prior[role] = poses[role].T_cam_part
            results.append(FrameResult(i, poses["A"], poses["B"], obs["A"], obs["B"]))
        for role in ("A", "B"):
            follow_branch([r.pose_a if role == "A" else r.pose_b for r in results])
        for fr in results:
            if fr.pose_a is not None and fr.pose_b is not None:
                fr.T_A_B = geometry.invert(fr.pose_a.T_cam_part) @ fr.pose_b.T_cam_part
        return results

    # ------------------------------------------------------------ over frames
    def teach(self, frames: Sequence[np.ndarray], camera: CameraIntrinsics, task: AssemblyTask) -> AssemblyTask:
        """Estimate ``T_A_B``, ``v_a`` and the evidence (see the module docstring)."""
        return self.teach_observed(self.observe(frames, camera, task), camera, task)

    def teach_observed(self, results: list[FrameResult], camera: CameraIntrinsics, task: AssemblyTask) -> AssemblyTask:
        """:meth:`teach` from frames already observed (:meth:`observe`); flips it resolves are written back."""
        s = self.settings
        notes: list[str] = []
        for role, part in (("A", task.part_a), ("B", task.part_b)):
            if not any((r.obs_a if role == "A" else r.obs_b) for r in results):
                ids = [m.id for m in part.markers]
                raise UserError(
                    f"no marker of part {part.name!r} (ids {ids}, {part.markers[0].dictionary}) was seen in any of "
                    f"{len(results)} frame(s); check the dictionary, the ids and that the part faces the camera"
                )
        both = [r for r in results if r.T_A_B is not None and r.rms_px <= s.frame_reject_px]
        if len(both) < s.min_frames:
            raise UserError(
                f"both parts were seen with a consistent pose in only {len(both)} of {len(results)} frame(s); "
                f"at least {s.min_frames} are needed (show both parts' markers longer)"
            )
        cluster, flips = self._assembled_cluster(both)
        if flips:
            notes.append(f"{flips} frame(s) with an ambiguous planar flip resolved by agreement with other frames")
        if len(cluster) < s.min_frames:
            raise UserError(
                f"only {len(cluster)} frame(s) agree on the assembled pose; at least {s.min_frames} are needed "
                "(hold the assembled parts still in view longer)"
            )
        fused = fuse_poses(np.array([r.T_A_B for r in cluster]), k=s.fusion_k)
        used = [r for r, keep in zip(cluster, fused.inliers, strict=True) if keep]
        T_A_B = fused.T
        if s.joint_refine and len(used) >= 2:
            T_A_B, jnote, used = self._joint_refine(used, T_A_B, camera)
            notes.append(jnote)
        # Insertion direction from the approach (frames before the assembled ones), each frame refitted with
        # B's rotation in A held at the taught one (:mod:`.approach`).
        first_used = min(r.index for r in used)
        K, dist = camera.K, camera.dist_array
        approach = []
        for r in results:
            if r.pose_a is None or r.pose_b is None or r.index >= first_used:
                continue
            pt = refit_with_rotation(r.index, r.pose_a, r.obs_a, r.pose_b, r.obs_b, T_A_B[:3, :3], K, dist)
            if pt.rms_px <= s.frame_reject_px and np.linalg.norm(pt.position - T_A_B[:3, 3]) > s.assembled_radius:
                approach.append(pt)
        v_a: np.ndarray | None = None
        source = "geometric"
        if len(approach) >= s.min_approach_frames:
            pos = np.array([p.position for p in approach])
            travel = float(np.max(np.linalg.norm(pos - T_A_B[:3, 3], axis=1)))
            if travel >= s.min_approach_travel:
                v_a, lateral, n_kept = direction_from_approach(pos, T_A_B[:3, 3])
                source = "demonstration"
                notes.append(
                    f"v_a from {n_kept} of {len(approach)} approach frame(s) (B's rotation in A held at the taught "
                    f"one): travel {travel * 1000:.1f} mm, lateral rms {lateral * 1000:.2f} mm"
                )
            else:
                notes.append(f"approach travel {travel * 1000:.1f} mm is too short to learn v_a")
        else:
            notes.append(f"{len(approach)} approach frame(s) seen; at least {s.min_approach_frames} needed for v_a")
        meshes = None
        if s.check_insertion or v_a is None:
            meshes = (build_part(task.part_a).mesh, build_part(task.part_b).mesh)
        if v_a is not None and s.check_insertion and meshes is not None:
            chk = check_retreat(*meshes, T_A_B, v_a, retract=s.retract, tolerance=s.collision_tolerance)
            if chk.ok:
                notes.append(f"v_a checked: B retreated by {s.retract} m along -v_a stays free of A (python-fcl)")
            else:
                notes.append(
                    f"learned v_a {np.round(v_a, 3).tolist()} fails the retreat check (collision at "
                    f"{(chk.first_collision or s.retract) * 1000:.1f} mm)"
                )
                cone = free_cone_centre(
                    *meshes, T_A_B, v_a, cone_deg=s.snap_cone_deg, retract=s.retract, tolerance=s.collision_tolerance
                )
                if cone is not None:
                    moved = float(np.degrees(np.arccos(np.clip(np.dot(cone[0], v_a), -1.0, 1.0))))
                    v_a = cone[0]
                    notes.append(
                        f"v_a moved {moved:.2f} deg to the centre of the {cone[1]} free retreat direction(s) "
                        f"within {s.snap_cone_deg:g} deg of the demonstrated one (python-fcl)"
                    )
                else:
                    notes.append(f"no free retreat within {s.snap_cone_deg:g} deg; trying the geometric direction")
                    try:
                        v_a, travel = separation_direction(*meshes, T_A_B, tolerance=s.collision_tolerance)
                        source = "geometric"
                        notes.append(
                            f"v_a from geometry: least-travel free retreat ({travel * 1000:.0f} mm to clear A)"
                        )
                    except ValueError:
                        # The taught pose itself interpenetrates beyond the tolerance: keep what was demonstrated.
                        notes.append("no straight free retreat from the taught pose; keeping the demonstrated v_a")
        if v_a is None:
            assert meshes is not None
            try:
                v_a, travel = separation_direction(*meshes, T_A_B, tolerance=s.collision_tolerance)
            except ValueError as exc:
                before = [r for r in results if r.index < first_used]
                seen_a = sum(r.pose_a is not None for r in before)
                seen_b = sum(r.pose_b is not None for r in before)
                both = sum(r.pose_a is not None and r.pose_b is not None for r in before)
                raise UserError(
                    f"cannot find an insertion direction: {exc}; of the {len(before)} frame(s) before the assembled "
                    f"ones A's markers were seen in {seen_a}, B's in {seen_b}, both in {both} ({len(approach)} usable "
                    f"as approach, at least {s.min_approach_frames} needed): show both parts' markers while B "
                    "approaches A"
                ) from None
            notes.append(f"v_a from geometry: least-travel free retreat ({travel * 1000:.0f} mm to clear A)")
        rejected = sorted({i for r in results for p in (r.pose_a, r.pose_b) if p for i in p.rejected_ids})
        if rejected:
            notes.append(f"markers rejected by reprojection error in some frames: {rejected}")
        evidence = TeachingEvidence(
            frames_total=len(results),
            frames_used=[r.index for r in used],
            residuals_px=[round(r.rms_px, 4) for r in used],
            spread_mm=fused.spread_m * 1000.0,
            spread_deg=float(np.degrees(fused.spread_rad)),
            insertion_source=source,
            notes=notes,
        )
        return AssemblyTask(
            name=task.name, part_a=task.part_a, part_b=task.part_b, T_A_B=T_A_B, v_a=v_a, evidence=evidence
        )

    def _assembled_cluster(self, frames: list[FrameResult]) -> tuple[list[FrameResult], int]:
        """Frames in the densest cluster of relative poses, flips resolved; and how many flips were resolved."""
        s = self.settings
        Ts = np.array([r.T_A_B for r in frames])
        t = Ts[:, :3, 3]
        dt = np.linalg.norm(t[:, None] - t[None], axis=-1)
        R = Ts[:, :3, :3]
        cosang = np.clip((np.einsum("iab,jab->ij", R, R) - 1.0) / 2.0, -1.0, 1.0)
        close = (dt <= s.assembled_radius) & (np.degrees(np.arccos(cosang)) <= s.assembled_angle_deg)
        counts = close.sum(axis=1)
        # Densest frame; among ties the latest (the assembled pose ends a demonstration).
        centre = int(np.flatnonzero(counts == counts.max())[-1])
        ref = fuse_poses(Ts[close[centre]]).T
        flips = 0
        cluster = []
        for r in frames:
            options = [(r.pose_a.T_cam_part, r.pose_b.T_cam_part)]
            options += [(Ta, r.pose_b.T_cam_part) for Ta, _ in r.pose_a.alternatives]
            options += [(r.pose_a.T_cam_part, Tb) for Tb, _ in r.pose_b.alternatives]
            best, best_cost = None, np.inf
            for k, (Ta, Tb) in enumerate(options):
                T = geometry.invert(Ta) @ Tb
                cost = geometry.translation_distance(T, ref) / s.assembled_radius + geometry.rotation_distance(
                    T, ref
                ) / np.radians(s.assembled_angle_deg)
                if cost < best_cost:
                    best, best_cost = (k, T), cost
            assert best is not None
            k, T = best
            if geometry.translation_distance(T, ref) <= 2 * s.assembled_radius and geometry.rotation_distance(
                T, ref
            ) <= np.radians(2 * s.assembled_angle_deg):
                if k > 0:
                    flips += 1
                    Ta, Tb = options[k]
                    r.pose_a.T_cam_part, r.pose_b.T_cam_part = Ta, Tb
                r.T_A_B = T
                cluster.append(r)
        return cluster, flips

    def _joint_refine(
        self, frames: list[FrameResult], T_A_B: np.ndarray, camera: CameraIntrinsics
    ) -> tuple[np.ndarray, str, list[FrameResult]]:
        """Least-squares over all kept frames' corners: unknowns ``T_A_B`` and each ``T_cam_A`` (Huber loss,
        analytic Jacobian, all frames projected at once: :mod:`.joint`).

        Frames whose RMS after the adjustment stands out (above four times the
        median and ``joint_reject_px``) do not fit one rigid ``T_A_B`` with the
        others (a marker corner pulled by a shadow or a finger, a pose left on
        the wrong side of a flip): they are dropped and the adjustment is run
        again. Returns ``(T_A_B, note, frames kept)``.
        """
        K, dist = camera.K, camera.dist_array
        data = []
        for r in frames:
            obj_a = np.concatenate([o.object_points for o in r.obs_a if o.marker_id in r.pose_a.marker_ids])
            img_a = np.concatenate([o.corners_px for o in r.obs_a if o.marker_id in r.pose_a.marker_ids])
            obj_b = np.concatenate([o.object_points for o in r.obs_b if o.marker_id in r.pose_b.marker_ids])
            img_b = np.concatenate([o.corners_px for o in r.obs_b if o.marker_id in r.pose_b.marker_ids])
            data.append((obj_a, img_a, obj_b, img_b))
        corners = CornerSet.build(data)

        # Each frame's start: A's own pose or B's pose carried to A through the fused T_A_B (flip alternatives
        # included), whichever fits both parts' corners best. A single square marker's pose can be tilted by
        # degrees or flipped while the other part's is not; starting from it traps the joint problem.
        # All candidates of all frames are scored in one vectorised projection.
        cand: list[np.ndarray] = []
        owner: list[int] = []
        for i, r in enumerate(frames):
            Ts = [r.pose_a.T_cam_part] + [T for T, _ in r.pose_a.alternatives]
            Ts += [T @ geometry.invert(T_A_B) for T in [r.pose_b.T_cam_part] + [T for T, _ in r.pose_b.alternatives]]
            cand += Ts
            owner += [i] * len(Ts)
        owner_arr = np.array(owner)
        cost = frame_rms(corners.subset(owner), T_A_B, cand, K, dist)  # one pseudo-frame per candidate
        starts = []
        for i in range(len(frames)):
            mine = np.flatnonzero(owner_arr == i)
            starts.append(cand[int(mine[np.argmin(cost[mine])])])
        active = list(range(len(frames)))
        T0 = T_A_B
        T = T_A_B
        rms0 = _rms_all(frame_rms(corners, T0, starts, K, dist), corners)
        dropped: list[int] = []
        for _round in range(3):
            n = len(active)
            sub = corners.subset(active)
            T, poses, _nfev = adjust(sub, T, [starts[i] for i in active], K, dist, f_scale=0.5)
            for k, i in enumerate(active):
                starts[i] = poses[k]
            per_frame = frame_rms(sub, T, poses, K, dist)
            thr = max(4.0 * float(np.median(per_frame)), self.settings.joint_reject_px)
            bad = [i for i, e in zip(active, per_frame, strict=True) if e > thr]
            if not bad or n - len(bad) < max(2, self.settings.min_frames):
                break
            dropped += [frames[i].index for i in bad]
            active = [i for i in active if i not in bad]
        sub = corners.subset(active)
        rms1 = _rms_all(frame_rms(sub, T, [starts[i] for i in active], K, dist), sub)
        shift = geometry.translation_distance(T, T0) * 1000.0
        note = (
            f"joint adjustment over {len(active)} frame(s): RMS {rms0:.3f} -> {rms1:.3f} px, "
            f"moved T_A_B by {shift:.3f} mm"
        )
        if dropped:
            note += f"; frame(s) {sorted(dropped)} dropped (do not fit one rigid T_A_B)"
        return T, note, [frames[i] for i in active]


def _rms_all(per_frame: np.ndarray, cs: CornerSet) -> float:
    """RMS over all corners (pixels) from per-frame RMS values of ``cs``'s frames."""
    cnt = np.bincount(cs.frame, minlength=cs.n_frames)
    return float(np.sqrt(np.sum(per_frame**2 * cnt) / np.sum(cnt)))
