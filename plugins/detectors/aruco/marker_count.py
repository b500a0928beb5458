"""Teaching precision per number of markers per part (issue 23): generated structures, markers kept, the bound.

A trial of the ``teaching_precision`` experiment may name a generated
structure (``generated: "family:index"``, :mod:`asmteach.core.structure_corpus`,
generator seed 0) and keep at most ``markers_per_part`` markers on each part.
The kept markers start with the A and B pair that faces most alike (a camera
sees both), then follow the structure's order.

The bound: corners are detected with some noise ``sigma`` (pixels, each image
axis; measured per trial as the RMS of detected minus true corners over the
frames the teacher used). The least-squares ``T_A_B`` of those corners, with
every frame's ``T_cam_A`` free as the teacher has it, then scatters with the
covariance ``sigma^2 (J^T J)^-1`` (Cramer-Rao for Gaussian corner noise; ``J``
the joint adjustment's Jacobian at the true poses, :mod:`.joint`). ``bound_mm``
and ``bound_deg`` are the RMS translation (of B's origin in A) and rotation
error it predicts: no unbiased estimator from those corners does better on
average.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.io import write_text
from asmteach.core.models import AssemblyTask, CameraIntrinsics
from asmteach.core.parts import load_structure
from asmteach.core.structure_corpus import STRUCTURE_FAMILIES, generate_structure, write_structure
from asmteach.core.sweep import to_csv
from asmteach.plugins.detectors.aruco.joint import CornerSet, jacobian
from asmteach.plugins.detectors.aruco.pnp import project
from asmteach.plugins.detectors.aruco.scene import DemoFrame
from asmteach.plugins.detectors.aruco.teacher import FrameResult

__all__ = ["generated_task", "keep_markers", "precision_bound", "write_marker_count_report"]


def generated_task(spec: str, folder: Path) -> AssemblyTask:
    """The structure ``"family:index"`` of the corpus (generator seed 0), written into ``folder`` (STL files the
    task's parts name, keep it while they are used) and loaded as a user's files would be."""
    family, _, index = spec.partition(":")
    if family not in STRUCTURE_FAMILIES or not index.isdigit():
        raise UserError(f"generated: {spec!r} must be 'family:index' with a family of {', '.join(STRUCTURE_FAMILIES)}")
    gs = generate_structure(family, 0, int(index))
    return load_structure(write_structure(gs, Path(folder) / gs.name))


def keep_markers(task: AssemblyTask, k: int) -> AssemblyTask:
    """``task`` with at most ``k`` markers per part: the A-B pair facing most alike first, then in order."""
    a, b = task.part_a.markers, task.part_b.markers
    na = np.array([m.T_part_marker[:3, 2] for m in a])
    nb = np.array([(task.T_A_B @ m.T_part_marker)[:3, 2] for m in b])
    i, j = np.unravel_index(int(np.argmax(na @ nb.T)), (len(a), len(b)))
    keep_a = [a[int(i)], *[m for n, m in enumerate(a) if n != i][: k - 1]]
    keep_b = [b[int(j)], *[m for n, m in enumerate(b) if n != j][: k - 1]]
    part_a = task.part_a.model_copy(update={"markers": keep_a})
    part_b = task.part_b.model_copy(update={"markers": keep_b})
    return task.model_copy(update={"part_a": part_a, "part_b": part_b})


def precision_bound(
    results: list[FrameResult], truth: list[DemoFrame], used: list[int], T_A_B: np.ndarray, camera: CameraIntrinsics
) -> dict[str, float]:
    """Measured corner noise and the RMS error bound of ``T_A_B`` over the frames ``used`` (see module doc).

    Returns ``corner_sigma_px`` (per axis), ``bound_mm``, ``bound_deg`` and
    ``seen_a``, ``seen_b``: the median number of each part's markers used per
    frame (markers a view does not show, or that were rejected, do not count).
    """
    K, dist = camera.K, camera.dist_array
    data, poses, resid = [], [], []
    seen: dict[str, list[int]] = {"A": [], "B": []}
    for idx in used:
        r, fr = results[idx], truth[idx]
        parts = []
        for role, obs, pose, T in (("A", r.obs_a, r.pose_a, fr.T_cam_A), ("B", r.obs_b, r.pose_b, fr.T_cam_B)):
            kept = [o for o in obs if pose is not None and o.marker_id in pose.marker_ids]
            seen[role].append(len(kept))
            obj = np.concatenate([o.object_points for o in kept])
            img = np.concatenate([o.corners_px for o in kept])
            resid.append(img - project(T, obj, K, dist))
            parts += [obj, img]
        data.append(tuple(parts))
        poses.append(fr.T_cam_A)
    sigma = float(np.sqrt(np.mean(np.concatenate(resid) ** 2)))
    J = jacobian(CornerSet.build(data), T_A_B, poses, K, dist)
    cov = np.linalg.inv(J.T @ J)[:6, :6] * sigma**2
    return {
        "corner_sigma_px": sigma,
        "bound_mm": float(np.sqrt(np.trace(cov[3:, 3:]))) * 1000.0,
        "bound_deg": float(np.degrees(np.sqrt(np.trace(cov[:3, :3])))),
        "seen_a": int(np.median(seen["A"])),
        "seen_b": int(np.median(seen["B"])),
    }


def _group(trials: list[dict[str, Any]], by: str, count: Any) -> list[dict[str, Any]]:
    """One record per count: median and worst taught error, median bound, corner noise and error / bound."""
    recs = []
    for c in sorted({count(m) for m in trials}):
        ms = [m for m in trials if count(m) == c]

        def med(k: str, ms: list[dict[str, Any]] = ms) -> float:
            return float(np.median([m[k] for m in ms]))

        recs.append(
            {
                "grouped_by": by,
                "markers_per_part": c,
                "trials": len(ms),
                "dt_median_mm": med("dt_mm"),
                "dt_max_mm": float(max(m["dt_mm"] for m in ms)),
                "drot_median_deg": med("drot_deg"),
                "drot_max_deg": float(max(m["drot_deg"] for m in ms)),
                "bound_median_mm": med("bound_mm"),
                "bound_median_deg": med("bound_deg"),
                "corner_sigma_median_px": med("corner_sigma_px"),
                "dt_over_bound_median": float(np.median([m["dt_mm"] / m["bound_mm"] for m in ms])),
                "drot_over_bound_median": float(np.median([m["drot_deg"] / m["bound_deg"] for m in ms])),
            }
        )
    return recs


def write_marker_count_report(rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
    """``teaching_markers.{md,csv}``: per markers-per-part count, the median taught error and bound.

    Two groupings, each by the weaker part (it limits ``T_A_B``): ``kept``,
    the fewer of the two parts' markers (``markers_per_part`` of the trial,
    fewer where a part has fewer), every trial counted; and ``seen``, the
    fewer of the two parts' markers seen per frame (``seen_a``, ``seen_b``: a
    marker the view does not show does not count), where a trial whose markers
    left the frames as another's did (a marker kept but never in view, so it
    taught exactly the same) is counted once.
    """
    ok = [r for r in rows if r.get("ok")]
    failed = len(rows) - len(ok)
    kept = [r["metrics"] for r in ok]
    distinct: dict[tuple[str, int, int, int, float], dict[str, Any]] = {}
    for r in ok:
        m = r["metrics"]
        distinct.setdefault((m["structure"], int(r.get("seed", 0)), m["seen_a"], m["seen_b"], round(m["dt_mm"], 9)), m)
    recs = _group(kept, "kept", lambda m: min(m["markers_a"], m["markers_b"]))
    recs += _group(list(distinct.values()), "seen", lambda m: min(m["seen_a"], m["seen_b"]))
    cols = list(recs[0]) if recs else []
    md = "# Teaching error per markers per part (the fewer of A's and B's: kept on the parts, seen per frame)\n\n"
    md += "| " + " | ".join(cols) + " |\n|" + "---|" * len(cols) + "\n"
    md += "".join(
        "| " + " | ".join(f"{r[c]:.3g}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |\n" for r in recs
    )
    md += (
        "\n| structure | seed | markers kept A+B | seen A+B | dt mm | drot deg | bound mm | bound deg | "
        "corner sigma px |\n|---|---|---|---|---|---|---|---|---|\n"
    )
    for (name, seed, sa, sb, _), m in sorted(distinct.items()):
        md += (
            f"| {name} | {seed} | {m['markers_a']}+{m['markers_b']} | {sa}+{sb} | {m['dt_mm']:.3f} | "
            f"{m['drot_deg']:.3f} | {m['bound_mm']:.3f} | {m['bound_deg']:.3f} | {m['corner_sigma_px']:.3f} |\n"
        )
    md += f"\n{len(kept)} trials ({len(distinct)} distinct), {failed} failed.\n"
    return [write_text(out_dir / "teaching_markers.md", md), write_text(out_dir / "teaching_markers.csv", to_csv(recs))]
