"""The detection stage of the ``part_corpus`` experiment, and the scenes ``benchmarks/detection_corpus.py`` runs.

Each scene puts the part's true mesh in one of its stable rests (trimesh's,
drawn by probability) at a seeded yaw and position on the table, renders it
with the scene Kinect (noise on; ``execution.depth_frames`` frames stacked, as a run senses) and runs
the detector on the part as it was loaded (a user's CAD STL, repaired), the camera centre as the viewpoint.
Errors are symmetry-aware (:func:`asmteach.core.symmetry.equivalent_transforms`,
turns about an axis of revolution included): position of the part origin in
mm, geodesic rotation in degrees, of the rough pose. A scene succeeds when
the pose is found within 5 mm / 5 deg; a pose found farther off is *wrong*,
unless it puts the part's surface where the truth puts it within 0.5 mm
everywhere after a shift of at most 5 mm (:class:`asmteach.core.symmetry.near.NearSymmetry`,
the detector's ``same_surface`` rule: a symmetry of a tessellated torus or ball the listed ones miss);
such a scene counts as a success with ``same_surface`` set and its error against the truth as measured.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from asmteach.core import registry
from asmteach.core.config import ExecutionSettings, TableSettings
from asmteach.core.detect_correct import resolve_by_views
from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.models import Detection
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.perception.second_view import DepthView
from asmteach.core.perception.view_choice import ViewChoiceSettings
from asmteach.core.pose_error import pose_error
from asmteach.core.rests.drops import drop_rests, likely_rests
from asmteach.core.symmetry import equivalent_transforms
from asmteach.core.symmetry.near import NearSymmetry
from asmteach.plugins.detectors.cvfh.close_look import REACH_REGION, CloseLooks, free_looks
from asmteach.plugins.detectors.cvfh.scenes import default_camera_pose, place_on_table, render_table_scene

__all__ = ["AREA", "asmteach_measure_part", "rest_poses", "run_part", "scene_pose"]

DEPTH_FRAMES = int(ExecutionSettings.model_fields["depth_frames"].default)
"""Kinect frames stacked per fixed view, as a run senses by default (``execution.depth_frames``)."""

LOOKS = int(ExecutionSettings.model_fields["look_closer"].default)
"""Wrist-camera looks at an ambiguous detection, as a run takes them by default (``execution.look_closer``)."""

AREA = (0.24, 0.34)
"""Work-area extent (x, y, metres) the part's centre is drawn from, around the work centre (0.45, 0)."""


def rest_poses(mesh: trimesh.Trimesh, com: np.ndarray, min_share: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """``(T_table_part (k, 4, 4), probability (k,))`` of trimesh's stable rests, those below ``min_share`` of the
    likeliest dropped (a tube's side is 64 facets of 1.5 % each: the threshold is relative)."""
    return likely_rests(*drop_rests(mesh, com), min_share=min_share)


def scene_pose(
    mesh: trimesh.Trimesh, rests: np.ndarray, probs: np.ndarray, rng: np.random.Generator, table: TableSettings
) -> tuple[int, float, np.ndarray]:
    """``(rest index, yaw rad, T_world_part)`` of one scene: a rest drawn by probability, yaw and xy uniform."""
    k = int(rng.choice(len(rests), p=probs))
    yaw = float(rng.uniform(-np.pi, np.pi))
    xy = np.array([0.45, 0.0]) + rng.uniform(-0.5 * np.asarray(AREA), 0.5 * np.asarray(AREA))
    return k, yaw, place_on_table(mesh, rests[k], yaw, xy, table.height)


def _outcome(
    det: Detection,
    T_true: np.ndarray,
    syms: list[np.ndarray],
    tol_mm: float,
    tol_deg: float,
    same: NearSymmetry | None = None,
) -> dict:
    """found / pos_mm / rot_deg / success / wrong_found / same_surface / reason of one detection against the truth.

    ``same``: a pose beyond ``tol_mm`` / ``tol_deg`` of every listed symmetric equivalent is still right when it
    puts the surface where the truth does (:meth:`NearSymmetry.same`, shift at most ``tol_mm``).
    """
    out = {
        "found": det.found,
        "pos_mm": None,
        "rot_deg": None,
        "success": False,
        "wrong_found": False,
        "same_surface": False,
        "reason": det.reason or "",
    }
    if det.found and det.rough is not None:
        err = pose_error(det.rough, T_true, right=syms)
        ok = err.within(tol_mm, tol_deg)
        by_surface = not ok and same is not None and same.same(det.rough, T_true, tol_mm)
        ok = ok or by_surface
        out.update(
            pos_mm=round(err.position_mm, 2),
            rot_deg=round(err.angle_deg, 2),
            success=ok,
            wrong_found=not ok,
            same_surface=by_surface,
        )
    return out


def run_part(
    name: str,
    mesh: trimesh.Trimesh,
    part: PartModel,
    detector: Detector,
    scenes: int,
    seed: int,
    tol_mm: float = 5.0,
    tol_deg: float = 5.0,
    T_cam2: np.ndarray | None = None,
    close_looks: int = 0,
    look_settings: ViewChoiceSettings | None = None,
    frames: int = DEPTH_FRAMES,
) -> list[dict]:
    """Render ``scenes`` scenes of ``mesh`` (the truth) and detect ``part`` (as loaded) in each.

    ``T_cam2`` (``T_world_cam``): a second Kinect renders each scene too (its own noise seed; the first
    view's frame is the same as without it), and the ambiguous detections are judged against its view
    (:func:`asmteach.core.detect_correct.resolve_by_views`): the row's ``two_*`` keys hold that outcome.
    ``close_looks``: a detection the first view leaves ambiguous gets up to that many wrist-camera looks from its
    best-ranked viewpoints (:func:`~asmteach.plugins.detectors.cvfh.close_look.free_looks`, ``look_settings``
    the candidates): ``look_*`` keys after one Kinect and the looks, ``two_look_*`` after both Kinects and the
    looks (looked at only when both Kinects leave it ambiguous; else the two-view outcome).
    ``frames``: Kinect frames stacked into each fixed view's cloud, new noise in each (a run's
    ``execution.depth_frames``; the first frame is the one a single-frame scene has); a wrist look takes one.
    """
    table = TableSettings()
    com = np.asarray(mesh.center_mass, float)
    rests, probs = rest_poses(mesh, com)
    syms = equivalent_transforms(mesh, com)
    same = NearSymmetry(mesh, seed=seed)  # the truth's own surface, the detector's same_surface tolerance
    T_cam = default_camera_pose(table)
    t0 = time.perf_counter()
    detector.prepare(part)
    prep_s = time.perf_counter() - t0
    rows = []
    for i in range(scenes):
        rng = np.random.default_rng([seed, i, 22])
        k, yaw, T_true = scene_pose(mesh, rests, probs, rng, table)
        scene, cloud = _stacked(DepthCamera(KinectSettings(), seed=1000 * seed + i), mesh, T_true, table, T_cam, frames)
        det = detector.detect(cloud, part, viewpoint=T_cam[:3, 3])
        row = {
            "part": name,
            "scene": i,
            "rest": k,
            "yaw_deg": round(math.degrees(yaw), 1),
            "part_points": int((scene.frame.labels == 1).sum()),
            **_outcome(det, T_true, syms, tol_mm, tol_deg, same),
            "source": det.details.get("source", ""),
            "detect_ms": det.timing_ms.get("total"),
            "prepare_s": round(prep_s, 1) if i == 0 else 0.0,
            "symmetries": len(syms),
        }
        alts = [np.asarray(a["T_world_part"]) for a in det.details.get("ambiguous", [])]
        row["alternatives"] = len(alts)  # hull twins the view cannot tell apart, listed with the found pose
        row["truth_in_alternatives"] = any(
            pose_error(T, T_true, right=syms).within(tol_mm, tol_deg) or same.same(T, T_true, tol_mm) for T in alts
        )
        views = [DepthView(cloud, T_cam[:3, 3])]
        # the free wrist camera's looks, the same for what one Kinect and what both leave ambiguous
        look = {
            "looks": close_looks,
            "seed": 1000 * seed + i,
            "symmetries": syms,
            "settings": look_settings,
            "table_settings": table,
        }
        if close_looks:
            got = free_looks(det, part, (mesh, T_true), views, scene.table, **look)
            row.update(_look_row("look_", got, T_true, syms, tol_mm, tol_deg, same))
        if T_cam2 is not None:
            camera2 = DepthCamera(KinectSettings(), seed=1000 * seed + i + 500)
            _, other = _stacked(camera2, mesh, T_true, table, T_cam2, frames)
            two_views = [*views, DepthView(other, T_cam2[:3, 3])]
            two = resolve_by_views(det, part, two_views, scene.table, syms)
            row.update({f"two_{k}": v for k, v in _outcome(two, T_true, syms, tol_mm, tol_deg, same).items()})
            judged = two.details.get("resolved_by_view") or two.details.get("second_view") or {}
            best = judged.pop("best_T_world_part", None)
            row["two_judgement"] = judged
            # how far the views' cheapest pose is from the truth, refused or not: what the margin guards
            err = None if best is None else pose_error(np.asarray(best), T_true, right=syms)
            row["two_best_pos_mm"] = None if err is None else round(err.position_mm, 2)
            row["two_best_rot_deg"] = None if err is None else round(err.angle_deg, 2)
            row["two_ms"] = two.timing_ms.get("second_view")
            if close_looks:
                # only what both Kinects leave ambiguous is looked at (free_looks returns a found one as it is)
                got = free_looks(two, part, (mesh, T_true), two_views, scene.table, **look)
                row.update(_look_row("two_look_", got, T_true, syms, tol_mm, tol_deg, same))
        rows.append(row)
    return rows


def _stacked(
    camera: DepthCamera, mesh: trimesh.Trimesh, T_true: np.ndarray, table: TableSettings, T_cam: np.ndarray, frames: int
) -> tuple[Any, np.ndarray]:
    """``(the first frame's scene, the cloud of ``frames`` frames stacked)``: one camera, new noise in each frame,
    as a run senses (:func:`asmteach.core.pipeline.detect.sense_views`); world frame, metres."""
    shots = [render_table_scene(camera, mesh, T_true, table=table, T_world_cam=T_cam) for _ in range(frames)]
    return shots[0], np.concatenate([shot.cloud for shot in shots])


def _look_row(
    prefix: str,
    got: CloseLooks,
    T_true: np.ndarray,
    syms: list[np.ndarray],
    tol_mm: float,
    tol_deg: float,
    same: NearSymmetry,
) -> dict:
    """The outcome after close looks under ``prefix``: as :func:`_outcome`, the looks made, their viewpoints
    (distance m / elevation / azimuth deg) and the seconds spent ranking and judging."""
    made = got.looks[1:]
    where = "; ".join(f"{lk['distance_m']}/{lk['elevation_deg']:.0f}/{lk['azimuth_deg']:.0f}" for lk in made)
    seconds = (got.looks[0]["rank_seconds"] + sum(lk["compute_seconds"] for lk in made)) if got.looks else 0.0
    return {
        **{prefix + k: v for k, v in _outcome(got.detection, T_true, syms, tol_mm, tol_deg, same).items()},
        prefix + "n": len(made),
        prefix + "where": where,
        prefix + "s": round(seconds, 2),
    }


@hookimpl
def asmteach_measure_part(
    part: PartModel, stage: str, seed: int, workdir: Path, options: dict[str, Any]
) -> dict[str, Any] | None:
    """Detection on ``options["scenes"]`` seeded scenes of ``part``; ``None`` for other stages.

    As a run detects: one Kinect (``frames`` stacked frames, default ``execution.depth_frames``) and up to
    ``close_looks`` looks of a wrist camera in the reach region when it leaves the pose ambiguous (default 2, as
    ``execution.look_closer``; a free camera, :func:`~asmteach.plugins.detectors.cvfh.close_look.free_looks`).
    ``found`` / ``success`` / ``wrong_found`` are after the looks, ``view_*`` the Kinect's view alone.
    """
    if stage != "detection":
        return None
    detector = registry.create("detectors", str(options.get("detector", "cvfh_icp")), {}, seed=seed)
    looks = int(options.get("close_looks", LOOKS))
    frames = int(options.get("frames", DEPTH_FRAMES))
    rows = run_part(
        part.name,
        part.mesh,
        part,
        detector,
        int(options.get("scenes", 5)),
        seed,
        close_looks=looks,
        look_settings=REACH_REGION,
        frames=frames,
    )
    p = "look_" if looks else ""
    return {
        "scenes": len(rows),
        "frames": frames,
        "close_looks": looks,
        "found": sum(r[f"{p}found"] for r in rows),
        "success": sum(r[f"{p}success"] for r in rows),
        "wrong_found": sum(r[f"{p}wrong_found"] for r in rows),
        "view_found": sum(r["found"] for r in rows),
        "view_success": sum(r["success"] for r in rows),
        "view_wrong_found": sum(r["wrong_found"] for r in rows),
        "looks_taken": sum(int(r.get("look_n") or 0) for r in rows),
        "max_pos_mm_found": max((r[f"{p}pos_mm"] for r in rows if r[f"{p}found"]), default=0.0),
        "max_rot_deg_found": max((r[f"{p}rot_deg"] for r in rows if r[f"{p}found"]), default=0.0),
        "reasons": "; ".join(sorted({r[f"{p}reason"][:80] for r in rows if not r[f"{p}found"]})),
    }
