"""PNG pictures of grasps on a part (matplotlib 3D, Agg; no global pyplot state).

A grasp is drawn as a small gripper skeleton at its TCP pose: the jaw segment
between the two contacts, the two fingers back along -z, and the palm bar.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import trimesh
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_hex
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from asmteach.core.interfaces import Obstacle, PartModel
from asmteach.core.io import atomic_path
from asmteach.core.models import Grasp

__all__ = ["draw_scene", "render_grasps"]

Segment = tuple[np.ndarray, float, str]
"""``(T_frame_tcp (4, 4), jaw width (m), colour)`` of one grasp to draw."""


def _skeleton(T: np.ndarray, width: float, finger: float) -> np.ndarray:
    """Line segments ``(4, 2, 3)`` of a gripper sketch at ``T`` (frame of ``T``, metres)."""
    h = 0.5 * width
    local = np.array(
        [
            [[0, -h, 0], [0, h, 0]],  # jaw between the contacts
            [[0, -h, 0], [0, -h, -finger]],  # finger 0
            [[0, h, 0], [0, h, -finger]],  # finger 1
            [[0, -h, -finger], [0, h, -finger]],  # palm bar
        ],
        dtype=float,
    )
    return local @ T[:3, :3].T + T[:3, 3]


def _add_mesh(ax, mesh: trimesh.Trimesh, color: str, alpha: float) -> None:
    tris = np.asarray(mesh.triangles)
    shade = 0.55 + 0.45 * np.clip(np.asarray(mesh.face_normals) @ np.array([0.3, -0.4, 0.85]), 0.0, 1.0)
    rgb = np.array([int(color[i : i + 2], 16) / 255.0 for i in (1, 3, 5)])
    colors = np.clip(shade[:, None] * rgb[None, :], 0, 1)
    poly = Poly3DCollection(tris, facecolors=np.c_[colors, np.full(len(tris), alpha)], edgecolors="none")
    ax.add_collection3d(poly)


def draw_scene(
    mesh: trimesh.Trimesh | object,
    segments: Sequence[Segment],
    path: str | Path,
    *,
    obstacles: Sequence[Obstacle] = (),
    title: str = "",
    legend: dict[str, str] | None = None,
    finger: float = 0.03,
) -> Path:
    """Draw ``mesh`` (same frame as the segments), optional obstacles and grasp sketches; write a PNG atomically."""
    fig = Figure(figsize=(6.4, 5.6), dpi=110)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(111, projection="3d")
    _draw_into(ax, mesh, segments, obstacles, finger)
    if title:
        ax.set_title(title, fontsize=10)
    if legend:
        handles = [Line2D([0], [0], color=c, lw=2, label=name) for name, c in legend.items()]
        ax.legend(handles=handles, loc="upper left", fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return Path(path)


def _draw_into(ax, mesh, segments: Sequence[Segment], obstacles: Sequence[Obstacle], finger: float) -> None:
    pts = [np.asarray(mesh.vertices)]
    _add_mesh(ax, mesh, "#c89e66", 0.55)
    for ob in obstacles:
        m = ob.mesh.copy()
        m.apply_transform(ob.T_world)
        # Large obstacles (a table) are cut to the neighbourhood of the part so the view stays readable.
        lo, hi = pts[0].min(0) - 0.08, pts[0].max(0) + 0.08
        keep = np.all((m.triangles_center >= lo) & (m.triangles_center <= hi), axis=1)
        if keep.any():
            _add_mesh(ax, m.submesh([np.flatnonzero(keep)], append=True), "#9a9a9a", 0.25)
    if segments:
        lines = np.concatenate([_skeleton(T, w, finger) for T, w, _ in segments])
        colors = [c for _, _, c in segments for _ in range(4)]
        ax.add_collection3d(Line3DCollection(lines, colors=colors, linewidths=1.2))
        pts.append(lines.reshape(-1, 3))
    allp = np.concatenate(pts)
    centre = 0.5 * (allp.min(0) + allp.max(0))
    half = 0.5 * float(np.max(allp.max(0) - allp.min(0))) + 1e-3
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel("x (m)", fontsize=7)
    ax.set_ylabel("y (m)", fontsize=7)
    ax.set_zlabel("z (m)", fontsize=7)
    ax.tick_params(labelsize=6)


def render_grasps(
    parts: Sequence[tuple[PartModel, Sequence[Grasp]]],
    path: str | Path,
    *,
    max_shown: int = 60,
    finger: float = 0.03,
) -> Path:
    """PNG with one panel per part: its best ``max_shown`` grasps coloured by score (part frame)."""
    import matplotlib

    cmap = matplotlib.colormaps["viridis"]
    n = max(1, len(parts))
    fig = Figure(figsize=(5.2 * n, 5.0), dpi=110)
    FigureCanvasAgg(fig)
    for k, (part, grasps) in enumerate(parts):
        ax = fig.add_subplot(1, n, k + 1, projection="3d")
        shown = list(grasps)[:max_shown]
        scores = np.array([g.score for g in shown]) if shown else np.zeros(0)
        lo, hi = (scores.min(), scores.max()) if len(scores) else (0.0, 1.0)
        segs = [(g.T_part_tcp, g.width, to_hex(cmap(0.15 + 0.85 * (g.score - lo) / max(hi - lo, 1e-9)))) for g in shown]
        _draw_into(ax, part.mesh, segs, (), finger)
        ax.set_title(f"{part.name}: {len(grasps)} grasps (best {len(shown)} shown)", fontsize=9)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    return Path(path)
