"""Sub-pixel honest rendering of marked parts: ray-cast shaded faces, projectively textured markers.

Every image pixel is the box-filtered average of ``supersample x supersample``
samples, each placed at a random point of its own cell of the pixel's
``supersample x supersample`` grid (stratified jitter from a fixed table tiled
over the image, so a pixel's samples depend only on where the pixel is).
Samples at the cell centres would put every pixel's samples on the same few
rows and columns: an edge near a pixel axis would then be found in steps of
``1 / supersample`` pixel, the same step along the whole edge, so its fitted
position is off by up to half a step (0.07 px RMS at 4 x 4, a tilt of several
degrees for a single small marker; docs/results/teaching_precision.md,
Session 14). Jittered, those errors differ from pixel to pixel and average out
along the edge.

A sample's colour comes from the exact intersection of its camera ray with the
nearest front-facing triangle (Embree ray casting through Open3D, :mod:`.raycast`); faces are
flat-shaded, and on a marker face the marker's cell grid is looked up at the
exact point in the marker frame, so marker edges are geometric edges,
anti-aliased only by the box filter. Inside a pixel that no colour boundary
crosses every sample has the colour of the pixel centre, so only the pixels
that a visible triangle edge (silhouette or crease), a marker cell boundary or
a change of colour between neighbouring pixel centres touches are
supersampled; the others take their centre's colour (the same average).
Pixel convention: OpenCV's (pixel centres at integer coordinates).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np
import trimesh

from asmteach.core.models import MarkerSpec
from asmteach.plugins.detectors.aruco.raycast import RayScene, project_points

__all__ = ["RenderObject", "Rendered", "render_scene"]

JITTER_SEED = 20261126
"""Seed of the sample jitter: the same scene renders to the same image."""
JITTER_TILE = 64
"""The jitter table covers this many pixels square and repeats over the image."""


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
    """``(h, w) int32`` id of the marker seen at each pixel centre, -1 where none."""
    marker_facing: dict[int, float] = field(default_factory=dict)
    """Marker id -> cosine between its normal and the direction from it to the camera (1: square-on)."""
    roi: tuple[int, int, int, int] = (0, 0, 0, 0)
    """``(x0, y0, x1, y1)`` of the region around the parts (image pixels)."""
    supersampled_pixels: int = 0
    """How many pixels of the region were supersampled (the others lie inside one colour)."""


def _quad_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


@lru_cache(maxsize=8)
def _jitter_table(S: int) -> np.ndarray:
    """``(2, P*S, P*S)`` offsets in [0, 1) of each sample within its grid cell (x then y), ``P = JITTER_TILE``."""
    rng = np.random.default_rng(JITTER_SEED)
    return rng.random((2, JITTER_TILE * S, JITTER_TILE * S))


def _sample_points(u: np.ndarray, v: np.ndarray, S: int) -> tuple[np.ndarray, np.ndarray]:
    """``(n, S*S)`` image coordinates (pixels) of the jittered samples of pixels ``(u, v)`` (absolute, int)."""
    if S == 1:
        return u[:, None].astype(float), v[:, None].astype(float)
    jit = _jitter_table(S)
    i, j = np.divmod(np.arange(S * S), S)  # sample row, column within the pixel
    row = (v % JITTER_TILE)[:, None] * S + i[None, :]
    col = (u % JITTER_TILE)[:, None] * S + j[None, :]
    xs = u[:, None] - 0.5 + (j[None, :] + jit[0, row, col]) / S
    ys = v[:, None] - 0.5 + (i[None, :] + jit[1, row, col]) / S
    return xs, ys


def _background_filter(S: int) -> np.ndarray:
    """1-D weights (left, centre, right) of a pixel's mean over its ``S`` bilinear-upsampled sample cells."""
    o = (np.arange(S) + 0.5) / S - 0.5
    left, right = float(np.mean(np.clip(-o, 0, None))), float(np.mean(np.clip(o, 0, None)))
    return np.array([left, 1.0 - left - right, right], np.float32)


def _background_samples(bg: np.ndarray, u: np.ndarray, v: np.ndarray, cell: np.ndarray, S: int) -> np.ndarray:
    """``(n, 3)`` backdrop under sample cells ``cell`` (``row * S + column``) of pixels ``(u, v)`` (relative to
    ``bg``): bilinear at the cell centre, edges replicated (``cv2.resize`` ``INTER_LINEAR`` by ``S``)."""
    h, w = bg.shape[:2]
    i, j = np.divmod(cell, S)
    sx = np.clip(u + (j + 0.5) / S - 0.5, 0, w - 1)
    sy = np.clip(v + (i + 0.5) / S - 0.5, 0, h - 1)
    xa = np.minimum(sx.astype(np.int64), max(w - 2, 0))
    ya = np.minimum(sy.astype(np.int64), max(h - 2, 0))
    fx, fy = (sx - xa)[:, None], (sy - ya)[:, None]
    xb, yb = np.minimum(xa + 1, w - 1), np.minimum(ya + 1, h - 1)
    top = bg[ya, xa] * (1 - fx) + bg[ya, xb] * fx
    bot = bg[yb, xa] * (1 - fx) + bg[yb, xb] * fx
    return (top * (1 - fy) + bot * fy).astype(np.float32)


def _edge_pixels(
    scene: RayScene, rgb: np.ndarray, face: np.ndarray, seen: list[np.ndarray], x0: int, y0: int, h: int, w: int
) -> tuple[np.ndarray, np.ndarray]:
    """Two ``(h, w) bool`` masks of the region from the pixel-centre pass: the pixels a colour boundary may
    cross, and among them those a face boundary may cross (the others lie on their centre's flat region)."""
    cross = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8)
    masks = []
    for segs in scene.edge_lines(x0, y0, seen):
        mask = np.zeros((h, w), np.uint8)
        for s in segs:
            # 1/16 px fixed point; pixel centres at integers as OpenCV draws.
            cv2.polylines(mask, list(np.round(s * 16).astype(np.int32)), False, 1, lineType=cv2.LINE_8, shift=4)
        # LINE_8 marks one pixel per step along the line's major axis; the pixels the line crosses are that
        # one and its neighbours along the minor axis.
        masks.append(cv2.dilate(mask, cross).astype(bool))
    faces, any_change = masks
    # Changes between neighbouring centres that no line explains (parts meeting mid-face): a boundary
    # crossing a pixel leaves the centre of the pixel or of one of its 4 neighbours on its other side.
    region = scene.face_region[face].reshape(h, w)
    col = rgb.reshape(h, w, 3)
    for ax in (0, 1):
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[ax], b[ax] = slice(1, None), slice(None, -1)
        a_, b_ = tuple(a), tuple(b)
        d_region = region[a_] != region[b_]
        d_colour = d_region | np.any(col[a_] != col[b_], axis=2)
        faces[a_] |= d_region
        faces[b_] |= d_region
        any_change[a_] |= d_colour
        any_change[b_] |= d_colour
    return any_change | faces, faces


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
    edges_only: bool = True,
) -> Rendered:
    """Draw ``objects`` over ``background`` (``(h, w, 3)`` float RGB in [0, 1]).

    ``light_dir_cam`` points from the scene toward the light, in the camera
    frame (x right, y down, z forward). ``edges_only=False`` casts rays
    through every pixel centre of the region and supersamples every pixel
    (the reference the default must equal).
    Returns the image and marker visibility.
    """
    S = int(supersample)
    K = np.asarray(K, dtype=float)
    image = np.array(background, dtype=np.float32)
    # Region of interest: the projected extent of every object (never behind the camera).
    pts = []
    for ob in objects:
        cam = trimesh.transform_points(ob.mesh.vertices, ob.T_cam_obj)
        if np.any(cam[:, 2] <= 0.01):
            raise ValueError("an object is behind or too close to the camera")
        pts.append(project_points(K, cam))
    allp = np.concatenate(pts)
    x0 = int(np.clip(np.floor(allp[:, 0].min()) - 2, 0, width))
    y0 = int(np.clip(np.floor(allp[:, 1].min()) - 2, 0, height))
    x1 = int(np.clip(np.ceil(allp[:, 0].max()) + 3, 0, width))
    y1 = int(np.clip(np.ceil(allp[:, 1].max()) + 3, 0, height))
    out = Rendered(image=image, roi=(x0, y0, x1, y1), marker_mask=np.full((height, width), -1, np.int32))
    if x1 <= x0 or y1 <= y0:
        return out
    light = np.asarray(light_dir_cam, float)
    scene = RayScene(objects, K, light / np.linalg.norm(light), ambient)
    h, w = y1 - y0, x1 - x0
    bg = image[y0:y1, x0:x1].copy()
    # Pass 1: one ray through each pixel centre that a front face may cover (every centre for the reference).
    inside = np.flatnonzero(scene.footprint(x0, y0, h, w) if edges_only else np.ones((h, w), bool))
    cv_, cu_ = np.divmod(inside, w)
    rgb_in, hit_in, face_in, seen = scene.look((cu_ + x0).astype(float), (cv_ + y0).astype(float))
    rgb = np.zeros((h * w, 3), np.float32)
    hit = np.zeros(h * w, bool)
    face = np.full(h * w, -1, np.int64)
    rgb[inside], hit[inside], face[inside] = rgb_in, hit_in, face_in
    centre_hits = {mid: inside[ix] for mid, ix in scene.marker_hits.items()}
    cells = np.full(h * w, -1, np.int32)
    for mid, ix in centre_hits.items():
        cells[ix] = mid
    out.marker_mask[y0:y1, x0:x1] = cells.reshape(h, w)
    if S > 1:
        k = _background_filter(S)
        roi = cv2.sepFilter2D(bg, -1, k, k, borderType=cv2.BORDER_REPLICATE).reshape(-1, 3)
    else:
        roi = bg.reshape(-1, 3)
    roi[hit] = rgb[hit]
    # Marker pixels: one per centre outside the supersampled pixels, 1 / S^2 per sample inside them.
    redo = np.zeros(h * w, bool)
    cast = None
    if S > 1 and edges_only:
        redo, cast = (m.ravel() for m in _edge_pixels(scene, rgb, face, seen, x0, y0, h, w))
    elif S > 1:
        redo = ~redo
    counts = {i: float(np.count_nonzero(~redo[ix])) for i, ix in centre_hits.items()}
    if redo.any():
        # Pass 2: S x S jittered rays through each pixel that a boundary may cross; cast where a face boundary
        # may cross it, met on the centre's face plane elsewhere (there only marker cells change).
        redo_ix = np.flatnonzero(redo)
        ev, eu = np.divmod(redo_ix, w)
        out.supersampled_pixels = int(ev.size)
        xs, ys = _sample_points(eu + x0, ev + y0, S)
        if cast is None:
            samples, fhit, _, _ = scene.look(xs.ravel(), ys.ravel())
        else:
            per_sample = np.repeat(redo_ix, S * S)
            samples, fhit, _, _ = scene.look(xs.ravel(), ys.ravel(), face=face[per_sample], cast=cast[per_sample])
        miss = np.flatnonzero(~fhit)
        samples[miss] = _background_samples(bg, eu[miss // (S * S)], ev[miss // (S * S)], miss % (S * S), S)
        roi[redo] = samples.reshape(-1, S * S, 3).mean(axis=1)
        for mid, ix in scene.marker_hits.items():
            counts[mid] = counts.get(mid, 0.0) + ix.size / (S * S)
    image[y0:y1, x0:x1] = roi.reshape(h, w, 3)
    for mk in scene.markers:
        m = mk.spec
        if m.id in counts:  # some ray met its paper
            square = np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]]) * 0.5 * m.size
            out.marker_area[m.id] = _quad_area(project_points(K, square @ mk.R.T + mk.t))
            out.marker_pixels[m.id] = counts[m.id]
            out.marker_facing[m.id] = float(-np.dot(mk.R[:, 2], mk.t) / np.linalg.norm(mk.t))
    out.image = image
    return out
