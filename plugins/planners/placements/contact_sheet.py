"""PNG contact sheet of a part's placements: one small 3-D view per placement.

Drawn with matplotlib's object API (``Figure`` + Agg canvas), so no global
pyplot state is touched and it runs headless. Each panel shows the part
resting on the table (z = 0, a grey square), its support polygon in red, the
centre of mass and its projection, and a title with the placement id,
probability, margin and symmetry order.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import trimesh
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from asmteach.core import geometry
from asmteach.core.io import atomic_path
from asmteach.core.models import Placement

__all__ = ["render_contact_sheet"]

_MAX_FACES = 6000


def render_contact_sheet(
    mesh: trimesh.Trimesh,
    placements: list[Placement],
    center_of_mass: np.ndarray,
    out: str | Path,
    *,
    title: str = "",
    columns: int = 4,
) -> Path:
    """Write the contact sheet of ``placements`` of ``mesh`` (part frame, metres) to ``out`` (PNG, atomic)."""
    if len(mesh.faces) > _MAX_FACES:
        # Drawing cost grows with faces; the hull keeps the silhouette of a dense scan.
        mesh = mesh.convex_hull
    n = max(len(placements), 1)
    cols = min(columns, n)
    rows = math.ceil(n / cols)
    fig = Figure(figsize=(3.0 * cols, 3.0 * rows + 0.4), dpi=90)
    FigureCanvasAgg(fig)
    if title:
        fig.suptitle(title, fontsize=10)
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    size = float(np.max(mesh.extents))
    for k, pl in enumerate(placements):
        ax = fig.add_subplot(rows, cols, k + 1, projection="3d")
        T = pl.T_table_part
        v = geometry.transform_points(T, mesh.vertices)
        tris = v[mesh.faces]
        normals = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        shade = 0.35 + 0.65 * np.clip(normals @ light, 0.0, 1.0)
        colors = np.column_stack([0.80 * shade, 0.62 * shade, 0.40 * shade, np.ones_like(shade)])
        ax.add_collection3d(Poly3DCollection(tris, facecolors=colors, edgecolors="none"))
        half = 0.75 * size
        sq = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]])
        ax.add_collection3d(Poly3DCollection([sq], facecolors=(0.85, 0.85, 0.85, 0.5), edgecolors="none"))
        poly = np.asarray(pl.support_polygon)
        if len(poly):
            loop = np.vstack([poly, poly[:1]])
            ax.plot(loop[:, 0], loop[:, 1], np.zeros(len(loop)), color="red", lw=1.5)
        c = geometry.transform_points(T, np.asarray(center_of_mass)[None, :])[0]
        ax.plot([c[0], c[0]], [c[1], c[1]], [0.0, c[2]], color="blue", lw=1.0)
        ax.scatter([c[0]], [c[1]], [c[2]], color="blue", s=8)
        ax.set_xlim(-half, half)
        ax.set_ylim(-half, half)
        ax.set_zlim(0.0, 2 * half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=22, azim=-60)
        ax.set_axis_off()
        ax.set_title(f"#{pl.id}  p={pl.probability:.2f}  d/h={pl.margin:.2f}  C{len(pl.symmetry_yaws)}", fontsize=8)
    if not placements:
        ax = fig.add_subplot(1, 1, 1)
        ax.text(0.5, 0.5, "no stable placement", ha="center", va="center")
        ax.set_axis_off()
    with atomic_path(out) as tmp:
        fig.savefig(tmp, format="png")
    return Path(out)
