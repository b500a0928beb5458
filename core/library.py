"""Contact sheet of a part library: every structure assembled, with its markers.

Each cell shows part A (wood colour), part B (blue) at ``T_A_B``, the markers
as dark squares labelled with their ids, and the insertion direction ``v_a``
as an arrow ending at B's origin. Rendered with matplotlib (headless Agg).
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from asmteach.core.errors import UserError
from asmteach.core.geometry import transform_points
from asmteach.core.io import atomic_path
from asmteach.core.models import AssemblyTask, MarkerSpec
from asmteach.core.parts import build_part, load_structure

__all__ = ["draw_part", "find_structures", "render_library"]

LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def find_structures(folder: Path) -> list[Path]:
    """Structure YAML files (those with ``part_a``) below ``folder``, sorted."""
    if not folder.is_dir():
        raise UserError(f"{folder}: not a folder of part-library YAML files")
    found = [p for p in sorted(folder.rglob("*.yaml")) if "part_a:" in p.read_text(encoding="utf-8")]
    if not found:
        raise UserError(f"{folder}: holds no structure YAML (files with part_a and part_b)")
    return found


def _marker_square(marker: MarkerSpec, T_world_part: np.ndarray) -> np.ndarray:
    s = marker.size / 2.0
    corners = np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])
    corners[:, 2] = 0.0015  # lifted off the face so the painter sort puts it in front
    return transform_points(T_world_part @ marker.T_part_marker, corners)


def part_polygons(mesh, T_world_part: np.ndarray, color, markers: list[MarkerSpec] = ()) -> tuple[list, list]:
    """Shaded triangles of a mesh plus its marker squares (millimetres) and their colours.

    Everything of a scene must go into one ``Poly3DCollection``: matplotlib
    depth-sorts polygons within a collection, not across collections.
    """
    verts = list(transform_points(T_world_part, mesh.vertices)[mesh.faces] * 1000.0)
    normals = np.asarray(mesh.face_normals) @ T_world_part[:3, :3].T
    shade = 0.45 + 0.55 * np.clip(normals @ LIGHT, 0.0, 1.0)
    colors = list(np.clip(np.asarray(color)[None, :] * shade[:, None], 0, 1))
    for m in markers:
        sq = _marker_square(m, T_world_part) * 1000.0
        verts += [sq[[0, 1, 2]], sq[[0, 2, 3]]]  # triangles: the collection takes one vertex count
        colors += [np.array([0.08, 0.08, 0.08])] * 2
    return verts, colors


def draw_part(ax, mesh, T_world_part: np.ndarray, color, markers: list[MarkerSpec] = ()) -> None:
    """Draw one mesh with Lambert shading and its markers on a 3D axis (millimetres)."""
    verts, colors = part_polygons(mesh, T_world_part, color, markers)
    ax.add_collection3d(Poly3DCollection(verts, facecolors=colors, edgecolors=colors, linewidths=0.2))


def _draw_structure(ax, task: AssemblyTask) -> None:
    a, b = build_part(task.part_a), build_part(task.part_b)
    va, ca = part_polygons(a.mesh, np.eye(4), (0.85, 0.66, 0.42), task.part_a.markers)
    vb, cb = part_polygons(b.mesh, task.T_A_B, (0.45, 0.62, 0.90), task.part_b.markers)
    ax.add_collection3d(Poly3DCollection(va + vb, facecolors=ca + cb, edgecolors=ca + cb, linewidths=0.2))
    for marker, T in [(m, np.eye(4)) for m in task.part_a.markers] + [(m, task.T_A_B) for m in task.part_b.markers]:
        c = _marker_square(marker, T).mean(axis=0) * 1000.0
        ax.text(*c, str(marker.id), color="gold", fontsize=6, ha="center", va="center", zorder=10)
    tip = task.T_A_B[:3, 3] * 1000.0
    tail = tip - np.asarray(task.v_a) * 40.0
    ax.quiver(*tail, *(tip - tail), color="crimson", arrow_length_ratio=0.25, linewidth=1.5)
    pts = np.vstack([a.mesh.vertices, transform_points(task.T_A_B, b.mesh.vertices), tail / 1000.0]) * 1000.0
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    mid, half = (lo + hi) / 2.0, (hi - lo).max() / 2.0 + 5.0
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=25, azim=-60)
    ax.set_title(f"{task.name}\nA: {task.part_a.name}  B: {task.part_b.name}", fontsize=8)
    ax.tick_params(labelsize=5)
    ax.set_xlabel("x mm", fontsize=6)
    ax.set_ylabel("y mm", fontsize=6)


def render_library(folder: Path, out_png: Path, *, columns: int = 5) -> Path:
    """Render every structure below ``folder`` to one PNG; returns its path."""
    files = find_structures(folder)
    rows = math.ceil(len(files) / columns)
    fig = plt.figure(figsize=(3.2 * columns, 3.4 * rows), dpi=110)
    for i, path in enumerate(files):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        _draw_structure(ax, load_structure(path))
    fig.suptitle("asmteach part library: part A (wood), part B (blue), markers (ids), insertion v_a (red)")
    fig.tight_layout()
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
    return out_png
