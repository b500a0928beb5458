"""Close looks of a free wrist camera at a corpus scene's ambiguous detection: what the robot's looks could give.

The pipeline's look (:func:`asmteach.core.pipeline.active_look.look_closer`) ranks viewpoints by how well they
would tell a detection's rivals apart (:func:`~asmteach.core.perception.view_choice.rank_viewpoints`: the rivals
as listed, the part's symmetries, the fixed views' height map above the table as occluder), moves a wrist camera
(``KinectSettings.wrist_stereo()``, one frame) to the best one the arm reaches, and judges the rivals on every
view so far (:func:`~asmteach.core.detect_correct.resolve_by_views`); the first look that settles it ends the
search, else the viewpoints are ranked again for the two poses the views now leave (the best and its closest
rival) and the best of those is looked from. Here the same is done with no robot: the camera goes to the
ranked viewpoints themselves (no IK, no collision, no path), so the figures are an upper bound of what the arm's
looks give. :data:`REACH_REGION` restricts the candidates to a cone from above that a Nextage wrist reaches.

Frames: world, z up, metres; cameras ``T_world_cam`` in OpenCV's frame.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import trimesh

from asmteach.core.config import TableSettings
from asmteach.core.detect_correct import resolve_by_views
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Detection, TablePlane
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.perception.second_view import DepthView
from asmteach.core.perception.view_choice import ViewChoiceSettings, Viewpoint, rank_viewpoints
from asmteach.core.pipeline.active_look import seen_heightmap
from asmteach.plugins.detectors.cvfh.scenes import render_table_scene

__all__ = ["REACH_REGION", "CloseLooks", "free_looks"]

REACH_REGION = ViewChoiceSettings(distances=[0.16, 0.2, 0.275, 0.35], elevations_deg=[55.0, 75.0, 90.0])
"""Viewpoints a Nextage wrist camera reaches over the work area: 0.16-0.35 m from the rivals' centre, 55 deg above
the table or steeper (structures_corpus.md, session 16: the 0.12 m and the 35 deg views the ranking preferred were
mostly out of reach, 29 of 45 tries)."""


@dataclass
class CloseLooks:
    """The detection after the looks, each look's record (JSON-ready) and the wrist views taken (world frame)."""

    detection: Detection
    looks: list[dict[str, Any]] = field(default_factory=list)
    views: list[DepthView] = field(default_factory=list)


def free_looks(
    det: Detection,
    part: PartModel,
    truth: tuple[trimesh.Trimesh, np.ndarray],
    views: Sequence[DepthView],
    table: TablePlane,
    *,
    looks: int,
    seed: int,
    symmetries: Sequence[np.ndarray] | None = None,
    settings: ViewChoiceSettings | None = None,
    table_settings: TableSettings | None = None,
) -> CloseLooks:
    """``det`` judged again with up to ``looks`` wrist frames taken from its best-ranked viewpoints.

    ``truth`` is the scene's part (the true mesh, ``T_world_part``) the wrist camera renders with the table, one
    frame per look, noise seeded by ``seed`` and the look's number; ``views`` the fixed views (``det``'s first).
    The rivals are ranked as the pipeline ranks them (``symmetries``: the part's, part frame; ``settings``: the
    candidate viewpoints, default the pipeline's grid). A detection that is found or lists fewer than two rivals
    comes back unchanged with no look.
    """
    rivals = det.details.get("ambiguous") or []
    if det.found or len(rivals) < 2 or looks <= 0:
        return CloseLooks(det)
    t0 = time.perf_counter()
    sensor = KinectSettings.wrist_stereo()
    poses = [np.asarray(r["T_world_part"], float) for r in rivals]
    centre = part.mesh.bounds.mean(axis=0)
    radius = float(np.max(np.linalg.norm(part.mesh.vertices - centre, axis=1)))
    skip = [(T[:3, :3] @ centre + T[:3, 3], radius + 0.01) for T in poses]
    seen = seen_heightmap(views, table, skip)
    occluders = [] if seen is None else [(seen, np.eye(4))]

    def rank(rivals: list[np.ndarray]) -> list[Viewpoint]:
        return rank_viewpoints(
            part.mesh, rivals, sensor, table, symmetries=symmetries, occluders=occluders, frames=1, settings=settings
        )

    ranked, rank_i = rank(poses), 0
    out = CloseLooks(det, [{"ranked_viewpoints": len(ranked), "rank_seconds": round(time.perf_counter() - t0, 3)}])
    mesh, T_true = truth
    looked: list[np.ndarray] = []  # camera centres looked from
    while len(out.views) < looks and rank_i < len(ranked):
        vp, rank_i = ranked[rank_i], rank_i + 1
        eye = vp.T_world_cam[:3, 3]
        if any(np.linalg.norm(eye - c) < 0.01 for c in looked):
            continue
        t1 = time.perf_counter()
        camera = DepthCamera(sensor, seed=seed + 7919 * (len(out.views) + 1))
        shot = render_table_scene(camera, mesh, T_true, table=table_settings, T_world_cam=vp.T_world_cam)
        view = DepthView(shot.cloud, eye.copy(), sensor)
        out.views.append(view)
        looked.append(eye.copy())
        judged = resolve_by_views(det, part, [*views, *out.views], table, symmetries)
        verdict = judged.details.get("resolved_by_view") or judged.details.get("second_view") or {}
        rec = {
            **vp.as_details(),
            "points": len(view.cloud),
            "winner": verdict.get("winner"),
            "closest_rival_gain": verdict.get("closest_rival_gain"),
            "closest_rival_z": verdict.get("closest_rival_z"),
        }
        out.looks.append(rec)
        out.detection = judged
        if judged.found:
            judged.details["resolved_by_look"] = rec
            rec["compute_seconds"] = round(time.perf_counter() - t1, 3)
            break
        pair = [verdict.get(k) for k in ("best_T_world_part", "closest_rival_T_world_part")]
        if len(out.views) < looks and all(T is not None for T in pair):
            # ranked again for the two poses the views now leave, as the pipeline's look_closer does: the first
            # ranking was for the fixed views' rivals, and a look that rules those out leaves others
            ranked, rank_i = rank([np.asarray(T, float) for T in pair]), 0
        rec["compute_seconds"] = round(time.perf_counter() - t1, 3)
    return out
