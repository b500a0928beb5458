"""Detect a part in a cloud, then correct the rough pose: the one path every caller takes.

The pipeline (first look and looking again at the goal), ``asmteach detect`` and
the detection experiments all run :func:`detect_and_correct`, so a pose is
corrected the same way wherever it is reported. Frames: the cloud, the table and
every pose are in the world frame, metres.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Corrector, Detector, PartModel
from asmteach.core.models import Correction, Detection, TablePlane
from asmteach.core.perception.second_view import DepthView, SecondViewSettings, judge_rivals
from asmteach.core.pose_error import pose_error
from asmteach.core.symmetry import part_symmetries

__all__ = ["SEGMENT_RADIUS", "detect_and_correct", "part_segment", "provisional_detection", "resolve_by_views"]

SEGMENT_RADIUS = 0.01
"""Metres: cloud points this close to the part's surface at the rough pose are its observed segment."""


def part_segment(
    cloud: np.ndarray, part: PartModel, T_world_part: np.ndarray, radius: float = SEGMENT_RADIUS
) -> np.ndarray:
    """Cloud points ``(n, 3)`` within ``radius`` metres of the part's surface at ``T_world_part``.

    The surface samples are seeded: unseeded, the segment (so the corrected pose and
    the whole plan after it) changed from run to run.
    """
    pts = np.asarray(cloud, dtype=float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    surface = geometry.transform_points(T_world_part, np.asarray(part.mesh.sample(3000, return_index=False, seed=0)))
    d, _ = cKDTree(surface).query(pts, distance_upper_bound=radius)
    return pts[np.isfinite(d)]


def provisional_detection(det: Detection) -> Detection:
    """``det`` taken as found at the first pose it lists when it is ambiguous between hull twins, else ``det``.

    The returned detection keeps the rivals in ``details["ambiguous"]`` (so the pipeline looks again),
    says ``details["provisional"] = True`` and keeps the detector's reason in
    ``details["provisional_reason"]``.
    """
    rivals = det.details.get("ambiguous") or []
    if det.found or det.details.get("ambiguous_kind") != "hull_twin" or not rivals:
        return det
    first = rivals[0]
    return det.model_copy(
        update={
            "found": True,
            "reason": None,
            "rough": np.asarray(first["T_world_part"], dtype=float),
            "fitness": first.get("fitness"),
            "details": {**det.details, "provisional": True, "provisional_reason": det.reason},
        }
    )


def resolve_by_views(
    det: Detection,
    part: PartModel,
    views: Sequence[DepthView],
    table: TablePlane | None = None,
    symmetries: Sequence[np.ndarray] | None = None,
    settings: SecondViewSettings | None = None,
) -> Detection:
    """``det`` settled by every depth view of the scene when it is ambiguous (rivals in ``details["ambiguous"]``).

    ``views`` are all the views, the one ``det`` was detected in first. The rivals and their turns are judged
    on every view (:func:`~asmteach.core.perception.second_view.judge_rivals`; ``symmetries`` are the part's,
    part frame, computed when ``None``): the pose they clearly prefer is reported found (``rough``), with
    ``details["resolved_by_view"]`` giving the costs, gaps and the winner; otherwise the detection stays not
    found, its reason starting "still ambiguous after N views" and the judgement in ``details["second_view"]``.
    Anything else (found, not ambiguous, a single view) is returned as it is.
    """
    rivals = det.details.get("ambiguous") or []
    if det.found or len(rivals) < 2 or len(views) < 2:
        return det
    t0 = time.perf_counter()
    poses = [np.asarray(r["T_world_part"], dtype=float) for r in rivals]
    verdict = judge_rivals(part.mesh, poses, list(views), table or _table_of(det), symmetries, settings=settings)
    ms = round(1000.0 * (time.perf_counter() - t0), 2)
    timing = {**det.timing_ms, "second_view": ms, "total": round(det.timing_ms.get("total", 0.0) + ms, 2)}
    summary = {**verdict.as_details(), "kind": det.details.get("ambiguous_kind"), "views": len(views)}
    if verdict.winner is None or verdict.pose is None:
        reason = f"still ambiguous after {len(views)} views: {verdict.why}; first view: {det.reason}"
        details = {**det.details, "second_view": summary}
        return det.model_copy(update={"reason": reason, "timing_ms": timing, "details": details})
    fitness = rivals[verdict.winner].get("fitness", det.fitness) if verdict.winner >= 0 else det.fitness
    return det.model_copy(
        update={
            "found": True,
            "reason": None,
            "rough": verdict.pose,
            "fitness": fitness,
            "timing_ms": timing,
            "details": {**det.details, "resolved_by_view": summary, "first_view_reason": det.reason},
        }
    )


SETTLED_MM = 5.0
"""A correction this far (mm) from a pose other views settled leaves the views' basin (second_view's distinct_mm)."""
SETTLED_DEG = 5.0
"""... or turned this far (degrees; second_view's distinct_deg)."""


def _keep_settled_basin(
    corrector: Corrector,
    corr: Correction,
    T_settled: np.ndarray,
    part: PartModel,
    table: TablePlane,
    symmetries: Sequence[np.ndarray] | None,
    details: dict,
) -> Correction:
    """``corr``, or the placement snap alone when ``corr`` left the pose other views settled.

    The corrector refines on the first view's segment, the very view that could not tell the rivals apart:
    its multi-start ICP may land on a rival the other views ruled out (hex_peg 0 seed 7: a wrist look settled
    the peg's turn within 0.6 deg of the truth, the planar ICP on the Kinect's segment turned it 26 deg). A
    correction beyond :data:`SETTLED_MM` / :data:`SETTLED_DEG` of ``T_settled`` (world, up to the part's
    ``symmetries``, part frame) is replaced by the snap onto the nearest placement without refinement (the
    corrector with no cloud); ``details["correction_overruled"]`` records the step it took.
    """
    syms = part_symmetries(part.mesh, np.asarray(part.center_of_mass, float)) if symmetries is None else symmetries
    moved = pose_error(corr.T_world_part, T_settled, (), syms)
    if moved.within(SETTLED_MM, SETTLED_DEG):
        return corr
    snap = corrector.correct(T_settled, part, table, None)
    details["correction_overruled"] = {
        "refined_vs_settled": moved.short(3),
        "snap_vs_settled": pose_error(snap.T_world_part, T_settled, (), syms).short(3),
    }
    return snap


def _table_of(det: Detection) -> TablePlane:
    """The table the detector found (or assumed), else the default one."""
    raw = det.details.get("table")
    return TablePlane.model_validate(raw) if raw else TablePlane()


def detect_and_correct(
    detector: Detector,
    corrector: Corrector | None,
    cloud: np.ndarray,
    part: PartModel,
    table: TablePlane | None = None,
    *,
    viewpoint: np.ndarray | None = None,
    provisional: bool = False,
    views: Sequence[DepthView] = (),
    symmetries: Sequence[np.ndarray] | None = None,
    closer: Callable[[Detection], Detection] | None = None,
) -> Detection:
    """Detect ``part`` in ``cloud`` ``(n, 3)``, then correct the rough pose when a corrector is given.

    ``provisional``: the caller looks at the part again once it has moved it (the pipeline's look-again
    step), so a detection the view left ambiguous between twins of the part's convex hull
    (``details["ambiguous_kind"] == "hull_twin"``: the same outside, so the same grasps) goes on with the
    first of the poses it lists (the best-scoring one) as found, marked ``details["provisional"] = True``
    and still listing them all in ``details["ambiguous"]``. The detector itself never reports such a
    guess as found (:func:`provisional_detection`).

    ``views``: other depth views of the same scene (other cameras, world frame). A detection the first
    view leaves ambiguous is judged against them first (:func:`resolve_by_views`); only what they leave
    ambiguous may go on provisionally. ``symmetries``: the part's (part frame; computed when needed and
    ``None``), so that a pose the views cannot tell from the winner by a symmetry is no rival.

    ``closer``: a last resort for a detection every view leaves ambiguous, before it may go on provisionally
    (the pipeline's look by a wrist camera, :func:`~asmteach.core.pipeline.active_look.look_closer`): it gets the
    ambiguous detection and returns it settled or as it was.

    ``viewpoint`` ((3,), world frame, metres) is the camera centre, or ``None`` for
    the detector's own setting; the corrector gets the viewpoint the detector used
    (``details["viewpoint"]``). ``table=None`` lets the detector find the table and
    the corrector use that one. A correction that fails with a :class:`UserError`
    leaves the rough pose and says why in ``details["correction_error"]``.

    Timings (ms): ``detect`` is the detector alone, ``correct`` the correction,
    ``total`` both, ``cpu_correct`` the correction's process time.
    """
    det = detector.detect(cloud, part, table, viewpoint=viewpoint)
    if views and not det.found:
        eye = det.details.get("viewpoint", viewpoint)
        first = DepthView(np.asarray(cloud, dtype=float), None if eye is None else np.asarray(eye, dtype=float))
        det = resolve_by_views(det, part, [first, *views], table, symmetries)
    if closer is not None and not det.found and det.details.get("ambiguous"):
        det = closer(det)
    if provisional and not det.found:
        det = provisional_detection(det)
    if not det.found or corrector is None or det.rough is None:
        return det
    t0, c0 = time.perf_counter(), time.process_time()
    used_table = table or _table_of(det)
    used_eye = det.details.get("viewpoint", viewpoint)
    det.timing_ms["detect"] = det.timing_ms.get("total", 0.0)
    try:
        corr = corrector.correct(
            det.rough,
            part,
            used_table,
            part_segment(cloud, part, det.rough),
            viewpoint=None if used_eye is None else np.asarray(used_eye, dtype=float),
        )
    except UserError as exc:
        det.details["correction_error"] = str(exc)
        det.timing_ms["correct"] = round(1000.0 * (time.perf_counter() - t0), 2)
        return det
    settled = det.details.get("resolved_by_view")
    if settled is not None:
        corr = _keep_settled_basin(corrector, corr, det.rough, part, used_table, symmetries, det.details)
    ms = 1000.0 * (time.perf_counter() - t0)
    det.corrected = corr.T_world_part
    det.timing_ms["correct"] = round(ms, 2)
    det.timing_ms["total"] = round(det.timing_ms["detect"] + ms, 2)
    det.timing_ms["cpu_correct"] = round(1000.0 * (time.process_time() - c0), 2)
    det.details["placement_id"] = corr.placement_id
    return det
