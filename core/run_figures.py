"""Figures of a run for the report: the sensed scene with detections, and the error summary.

matplotlib (Agg) only; every PNG is written atomically. Units on the axes:
millimetres for positions, degrees for angles.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from asmteach.core import geometry
from asmteach.core.interfaces import PartModel
from asmteach.core.io import atomic_path
from asmteach.core.models import Detection, RunReport

__all__ = ["detection_figure", "metrics_figure"]


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    _plt().close(fig)
    return path


def detection_figure(
    path: Path,
    depth: np.ndarray,
    cloud: np.ndarray,
    parts: Sequence[PartModel],
    detections: dict[str, Detection],
    truth: dict[str, np.ndarray],
) -> Path:
    """Left: the depth image. Right: the cloud seen from above with each part's model outline at its
    true pose (green), rough detection (orange) and corrected pose (red)."""
    plt = _plt()
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(12, 5))
    im = ax0.imshow(np.where(np.isfinite(depth), depth, np.nan), cmap="viridis")
    fig.colorbar(im, ax=ax0, fraction=0.035, label="depth (m)")
    ax0.set_title("simulated Kinect depth (NaN = no return)")
    ax0.axis("off")
    pts = cloud[np.all(np.isfinite(cloud), axis=1)]
    if len(pts):
        top = pts[:, 2] > np.percentile(pts[:, 2], 5) + 0.003
        ax1.scatter(1000 * pts[~top, 0], 1000 * pts[~top, 1], s=0.2, c="#dddddd", rasterized=True)
        ax1.scatter(1000 * pts[top, 0], 1000 * pts[top, 1], s=0.4, c="#7f7f7f", rasterized=True)
    styles = (("truth", "#2ca02c"), ("rough", "#ff7f0e"), ("corrected", "#d62728"))
    for part in parts:
        det = detections.get(part.name)
        poses = {"truth": truth.get(part.name)}
        if det is not None:
            poses.update(rough=det.rough, corrected=det.corrected)
        verts = np.asarray(part.mesh.vertices, float)
        for key, color in styles:
            T = poses.get(key)
            if T is None:
                continue
            v = geometry.transform_points(T, verts)[:, :2] * 1000.0
            from scipy.spatial import ConvexHull

            hull = ConvexHull(v)
            loop = np.vstack([v[hull.vertices], v[hull.vertices[:1]]])
            ax1.plot(loop[:, 0], loop[:, 1], color=color, lw=1.4, label=f"{key}" if part is parts[0] else None)
        if det is not None and det.best is not None:
            err = det.details.get("corrected_error") or det.details.get("rough_error") or {}
            c = det.best[:2, 3] * 1000.0
            ax1.annotate(
                f"{part.name}\n{err.get('position_mm', float('nan')):.2f} mm, "
                f"{err.get('angle_deg', float('nan')):.2f} deg",
                c,
                fontsize=8,
                ha="center",
                xytext=(0, 28),
                textcoords="offset points",
            )
    ax1.set_aspect("equal")
    ax1.set_xlabel("world x (mm)")
    ax1.set_ylabel("world y (mm)")
    ax1.legend(loc="lower right", fontsize=8)
    ax1.set_title("cloud from above; footprints of the part models")
    fig.tight_layout()
    return _save(fig, path)


def metrics_figure(path: Path, report: RunReport) -> Path:
    """Bar charts of the run's position (mm) and angle (deg) errors per stage."""
    plt = _plt()
    m = report.metrics
    pos = {k: v for k, v in m.items() if k.endswith("_mm")}
    ang = {k: v for k, v in m.items() if k.endswith("_deg")}
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for ax, data, unit in ((axes[0], pos, "mm"), (axes[1], ang, "deg")):
        names = list(data)
        ax.barh(range(len(names)), [data[k] for k in names], color="#4c72b0")
        ax.set_yticks(range(len(names)))
        ax.set_yticklabels([n.removesuffix(f"_{unit}").replace("_", " ") for n in names], fontsize=8)
        ax.set_xlabel(unit)
        for i, k in enumerate(names):
            ax.annotate(
                f"{data[k]:.3f}", (data[k], i), xytext=(3, 0), textcoords="offset points", va="center", fontsize=8
            )
    axes[0].set_title("position errors")
    axes[1].set_title("angle errors")
    fig.suptitle(
        f"{report.config.get('name', 'run')} (seed {report.seed}): "
        f"{'success' if report.success else 'failed at ' + str(report.failed_stage)}"
    )
    fig.tight_layout()
    return _save(fig, path)
