"""Sub-pixel honest rendering of marked parts: z-buffered shaded faces, projectively textured markers.

Every image pixel is the box-filtered average of ``supersample x supersample``
samples, each placed at a random point of its own cell of the pixel's
``supersample x supersample`` grid (stratified jitter, fixed seed). Samples at
the cell centres would put every pixel's samples on the same few rows and
columns: an edge near a pixel axis would then be found in steps of
``1 / supersample`` pixel, the same step along the whole edge, so its fitted
position is off by up to half a step (0.07 px RMS at 4 x 4, a tilt of several
degrees for a single small marker; docs/results/teaching_precision.md,
Session 14). Jittered, those errors differ from pixel to pixel and average out
along the edge. A sample's colour comes from the exact intersection of its camera
ray with the nearest triangle (the plane equation, not interpolated depth);
on a marker face the marker's cell grid is looked up at the exact point in
the marker frame, so marker edges are geometric edges, anti-aliased only by
the box filter. Only the region around the parts is rendered at the high
resolution. Pixel convention: OpenCV's (pixel centres at integer coordinates).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import trimesh

from asmteach.core.models import MarkerSpec
from asmteach.plugins.detectors.aruco.markers import marker_bits

__all__ = ["RenderObject", "Rendered", "render_scene"]

PAPER_WHITE = 0.92
INK_BLACK = 0.05
JITTER_SEED = 20261126
"""Seed of the sample jitter: the same scene renders to the same image."""


@dataclass
class RenderObject:
    """A part to draw: its mesh and markers (part frame, metres) at ``T_cam_obj``."""

    mesh: trimesh.Trimesh
    color_rgb: tuple[float, float, float]
    markers: list[MarkerSpec]
    T_cam_obj: np.ndarray
    quiet_zone_cells: float = 1.0
    """Width of the white paper margin around each marker, in marker cells."""


@dataclass
class Rendered:
    """A rendered frame (float RGB in [0, 1], ``(h, w, 3)``) and what is visible in it."""

    image: np.ndarray
    marker_pixels: dict[int, float] = field(default_factory=dict)
    """Marker id -> visible area of its black square, in image pixels."""
    marker_area: dict[int, float] = field(default_factory=dict)
    """Marker id -> projected area of its black square, in image pixels (unoccluded)."""
    marker_mask: np.ndarray | None = None
    """``(h, w) int32`` id of the marker covering most of each pixel, -1 where none."""
    roi: tuple[int, int, int, int] = (0, 0, 0, 0)
    """``(x0, y0, x1, y1)`` of the supersampled region (image pixels)."""


def _project(K: np.ndarray, P: np.ndarray) -> np.ndarray:
    uvw = P @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def _quad_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def render_scene(
    objects: list[RenderObject],
    K: np.ndarray,
    width: int,
    height: int,
    *,
    background: np.ndarray,
    light_dir_cam: tuple[float, float, float] = (0.3, -0.5, -1.0),
    ambient: float = 0.45,
    supersample: int = 4,
) -> Rendered:
    """Draw ``objects`` over ``background`` (``(h, w, 3)`` float RGB in [0, 1]).

    ``light_dir_cam`` points from the scene toward the light, in the camera
    frame (x right, y down, z forward). Returns the image and marker visibility.
    """
    S = int(supersample)
    K = np.asarray(K, dtype=float)
    image = background.astype(np.float32).copy()
    # Region of interest: the projected extent of every object (never behind the camera).
    pts = []
    for ob in objects:
        cam = trimesh.transform_points(ob.mesh.vertices, ob.T_cam_obj)
        if np.any(cam[:, 2] <= 0.01):
            raise ValueError("an object is behind or too close to the camera")
        pts.append(_project(K, cam))
    allp = np.concatenate(pts)
    x0 = int(np.clip(np.floor(allp[:, 0].min()) - 2, 0, width))
    y0 = int(np.clip(np.floor(allp[:, 1].min()) - 2, 0, height))
    x1 = int(np.clip(np.ceil(allp[:, 0].max()) + 3, 0, width))
    y1 = int(np.clip(np.ceil(allp[:, 1].max()) + 3, 0, height))
    out = Rendered(image=image, roi=(x0, y0, x1, y1), marker_mask=np.full((height, width), -1, np.int32))
    if x1 <= x0 or y1 <= y0:
        return out
    W, H = (x1 - x0) * S, (y1 - y0) * S
    # Sample (i, j) lies in cell (i, j) of the sample grid, at (j + jx, i + jy) in grid units with jx, jy in
    # [0, 1); pixel u covers [u - 0.5, u + 0.5). One sample per pixel stays at the pixel centre (no
    # anti-aliasing to decorrelate; the visibility masks stay on the pixel grid).
    if S > 1:
        rng = np.random.default_rng(JITTER_SEED)
        gxs = np.arange(W, dtype=np.float32)[None, :] + rng.random((H, W), dtype=np.float32)
        gys = np.arange(H, dtype=np.float32)[:, None] + rng.random((H, W), dtype=np.float32)
    else:
        gxs = np.broadcast_to(np.arange(W, dtype=np.float32)[None, :] + np.float32(0.5), (H, W))
        gys = np.broadcast_to(np.arange(H, dtype=np.float32)[:, None] + np.float32(0.5), (H, W))
    # Ray direction (z = 1) of every sample.
    rx = ((x0 - 0.5 + gxs.astype(np.float64) / S - K[0, 2]) / K[0, 0]).astype(np.float32)
    ry = ((y0 - 0.5 + gys.astype(np.float64) / S - K[1, 2]) / K[1, 1]).astype(np.float32)
    depth = np.full((H, W), np.inf, np.float32)
    tri_id = np.full((H, W), -1, np.int32)  # index into the stacked triangles of all objects
    light = np.asarray(light_dir_cam, float)
    light = light / np.linalg.norm(light)
    tri_owner, tri_normal, tri_color = [], [], []
    base = 0
    for oi, ob in enumerate(objects):
        cam_v = trimesh.transform_points(ob.mesh.vertices, ob.T_cam_obj)
        tris = cam_v[ob.mesh.faces]  # (m, 3, 3)
        normals = ob.mesh.face_normals @ ob.T_cam_obj[:3, :3].T
        uv = _project(K, tris.reshape(-1, 3)).reshape(-1, 3, 2)
        # Sample-grid coordinates of the vertices (cell (i, j) spans [j, j + 1) x [i, i + 1)).
        gx = (uv[..., 0] - (x0 - 0.5)) * S
        gy = (uv[..., 1] - (y0 - 0.5)) * S
        tri_owner += [oi] * len(tris)
        tri_normal.append(normals)
        tri_color += [ob.color_rgb] * len(tris)
        for fi in range(len(tris)):
            n = normals[fi]
            p0 = tris[fi, 0]
            if np.dot(n, p0) >= 0:  # back face: seen from behind
                continue
            xa, ya = gx[fi], gy[fi]
            bx0 = max(int(np.floor(xa.min())), 0)
            bx1 = min(int(np.floor(xa.max())) + 1, W)
            by0 = max(int(np.floor(ya.min())), 0)
            by1 = min(int(np.floor(ya.max())) + 1, H)
            if bx1 <= bx0 or by1 <= by0:
                continue
            area = (xa[1] - xa[0]) * (ya[2] - ya[0]) - (ya[1] - ya[0]) * (xa[2] - xa[0])
            if abs(area) < 1e-12:
                continue
            sgn = np.sign(area)
            win_ = (slice(by0, by1), slice(bx0, bx1))
            X, Y = gxs[win_], gys[win_]
            inside = None
            for a_, b_ in ((0, 1), (1, 2), (2, 0)):
                e = (
                    np.float32(-sgn * (ya[b_] - ya[a_])) * (X - np.float32(xa[a_]))
                    + np.float32(sgn * (xa[b_] - xa[a_])) * (Y - np.float32(ya[a_]))
                ) >= 0
                inside = e if inside is None else inside & e
            # Exact ray-plane depth: z = (n . p0) / (n . (rx, ry, 1)).
            denom = np.float32(n[0]) * rx[win_] + np.float32(n[1]) * ry[win_] + np.float32(n[2])
            with np.errstate(divide="ignore", invalid="ignore"):
                z = np.float32(np.dot(n, p0)) / denom
            cur = depth[by0:by1, bx0:bx1]
            win = inside & (z > 0) & (z < cur)
            np.copyto(cur, z, where=win)
            np.copyto(tri_id[by0:by1, bx0:bx1], np.int32(base + fi), where=win)
        base += len(tris)
    hit = tri_id >= 0
    owner_of = np.array([*tri_owner, -1], np.int32)
    owner = owner_of[tri_id]  # -1 indexes the sentinel
    all_normals = np.vstack([*tri_normal, np.zeros((1, 3))])
    albedo = np.array([*tri_color, (0.0, 0.0, 0.0)], np.float32)[tri_id]
    # Lambert shading per triangle, applied to faces and markers alike.
    shade = (ambient + (1.0 - ambient) * np.clip(all_normals @ light, 0.0, None)).astype(np.float32)[tri_id]
    marker_ss = np.full((H, W), -1, np.int32)
    # Markers: exact lookup of the cell grid where the visible surface lies on the marker plane.
    for oi, ob in enumerate(objects):
        for m in ob.markers:
            T = ob.T_cam_obj @ m.T_part_marker
            R, t = T[:3, :3], T[:3, 3]
            nz = R[:, 2]
            if np.dot(nz, t) >= 0:  # printed side faces away from the camera
                continue
            bits = marker_bits(m)
            ncell = bits.shape[0]
            cell = m.size / ncell
            half = 0.5 * m.size + ob.quiet_zone_cells * cell
            corners = np.array([[-half, half, 0], [half, half, 0], [half, -half, 0], [-half, -half, 0]])
            q = _project(K, corners @ R.T + t)
            qx = (q[:, 0] - (x0 - 0.5)) * S
            qy = (q[:, 1] - (y0 - 0.5)) * S
            bx0 = max(int(np.floor(qx.min())), 0)
            bx1 = min(int(np.floor(qx.max())) + 1, W)
            by0 = max(int(np.floor(qy.min())), 0)
            by1 = min(int(np.floor(qy.max())) + 1, H)
            if bx1 <= bx0 or by1 <= by0:
                continue
            sub = (slice(by0, by1), slice(bx0, bx1))
            rxs, rys = rx[sub].astype(np.float64), ry[sub].astype(np.float64)

            def affine(v: np.ndarray, rxs: np.ndarray = rxs, rys: np.ndarray = rys) -> np.ndarray:
                return v[0] * rxs + v[1] * rys + v[2]

            with np.errstate(divide="ignore", invalid="ignore"):
                lam = np.dot(nz, t) / affine(nz)  # depth of the ray / marker-plane point
            # Marker-frame coordinates of that point: R^T (lam * d - t).
            lx = lam * affine(R[:, 0]) - np.dot(R[:, 0], t)
            ly = lam * affine(R[:, 1]) - np.dot(R[:, 1], t)
            on_face = (
                (owner[sub] == oi) & (np.abs(depth[sub] - lam) < 2e-4) & (np.abs(lx) <= half) & (np.abs(ly) <= half)
            )
            if not on_face.any():
                continue
            col = np.floor((lx + 0.5 * m.size) / cell).astype(np.int64)
            row = np.floor((0.5 * m.size - ly) / cell).astype(np.int64)
            in_sq = (col >= 0) & (col < ncell) & (row >= 0) & (row < ncell) & on_face
            black = np.zeros_like(in_sq)
            black[in_sq] = bits[row[in_sq], col[in_sq]]
            a = albedo[sub]
            a[on_face] = PAPER_WHITE
            a[black] = INK_BLACK
            marker_ss[sub][in_sq] = m.id
            square = np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]]) * 0.5 * m.size
            out.marker_area[m.id] = _quad_area(_project(K, square @ R.T + t))
            out.marker_pixels[m.id] = float(in_sq.sum()) / (S * S)
    hi = cv2.resize(image[y0:y1, x0:x1], (W, H), interpolation=cv2.INTER_LINEAR)
    np.copyto(hi, albedo * shade[..., None], where=hit[..., None])
    # Box filter over each pixel's S x S samples (INTER_AREA with an integer factor is exactly that).
    image[y0:y1, x0:x1] = cv2.resize(hi, (x1 - x0, y1 - y0), interpolation=cv2.INTER_AREA)
    # Marker label of the sample nearest each pixel centre (visibility bookkeeping and tests).
    out.marker_mask[y0:y1, x0:x1] = marker_ss[S // 2 :: S, S // 2 :: S]
    out.image = image
    return out
