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
nearest front-facing triangle (Embree ray casting through Open3D); faces are
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
import open3d as o3d
import trimesh

from asmteach.core.models import MarkerSpec
from asmteach.plugins.detectors.aruco.markers import marker_bits

__all__ = ["RenderObject", "Rendered", "render_scene"]

PAPER_WHITE = 0.92
INK_BLACK = 0.05
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


def _project(K: np.ndarray, P: np.ndarray) -> np.ndarray:
    uvw = P @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


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


@dataclass
class _Marker:
    """A marker printed side toward the camera: its pose, cell grid and image bounding box."""

    owner: int
    spec: MarkerSpec
    R: np.ndarray
    t: np.ndarray
    bits: np.ndarray
    cell: float
    half: float
    """Half side of the paper (black square and quiet zone), metres."""
    box: tuple[float, float, float, float]
    """``(x_min, y_min, x_max, y_max)`` of the projected paper, pixels."""


class _Scene:
    """The front-facing triangles of every object in the camera frame, and what each sample ray sees."""

    def __init__(self, objects: list[RenderObject], K: np.ndarray, light: np.ndarray, ambient: float) -> None:
        self.objects, self.K = objects, K
        self.rays = o3d.t.geometry.RaycastingScene()
        self.geom_owner: list[int] = []
        self.marker_hits: dict[int, np.ndarray] = {}
        # Per geometry: each front face's shaded colour (RGB) and its shade (fourth column).
        self.face_rgbs: list[np.ndarray] = []
        self.front: list[np.ndarray] = []
        self.cam_v: list[np.ndarray] = []
        self.markers: list[_Marker] = []
        for oi, ob in enumerate(objects):
            cam_v = trimesh.transform_points(ob.mesh.vertices, ob.T_cam_obj)
            normals = ob.mesh.face_normals @ ob.T_cam_obj[:3, :3].T
            # Seen from the front when the camera (origin) lies on the normal's side of the face.
            front = np.einsum("ij,ij->i", normals, cam_v[ob.mesh.faces[:, 0]]) < 0
            self.cam_v.append(cam_v)
            self.front.append(front)
            for m in ob.markers:
                T = ob.T_cam_obj @ m.T_part_marker
                if np.dot(T[:3, 2], T[:3, 3]) >= 0:  # printed side faces away from the camera
                    continue
                bits = marker_bits(m)
                cell = m.size / bits.shape[0]
                half = 0.5 * m.size + ob.quiet_zone_cells * cell
                paper = np.array([[-1, 1, 0], [1, 1, 0], [1, -1, 0], [-1, -1, 0]]) * half
                q = _project(K, paper @ T[:3, :3].T + T[:3, 3])
                box = (*(q.min(axis=0) - 1.0), *(q.max(axis=0) + 1.0))
                self.markers.append(_Marker(oi, m, T[:3, :3], T[:3, 3], bits, cell, half, box))
            if not front.any():
                continue
            self.rays.add_triangles(
                o3d.core.Tensor(cam_v.astype(np.float32)),
                o3d.core.Tensor(ob.mesh.faces[front].astype(np.uint32)),
            )
            self.geom_owner.append(oi)
            # Lambert shading per triangle, applied to faces and markers alike.
            shade = (ambient + (1.0 - ambient) * np.clip(normals[front] @ light, 0.0, None)).astype(np.float32)
            rgb = shade[:, None] * np.asarray(ob.color_rgb, np.float32)[None, :]
            self.face_rgbs.append(np.concatenate([rgb, shade[:, None]], axis=1))

    def look(self, xs: np.ndarray, ys: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
        """What the rays through image points ``(xs, ys)`` (pixels, flat) see: colour ``(n, 3)``, hit mask
        and, per object, which of its faces were hit (bool over its faces). Also sets ``marker_hits``: marker
        id -> indices of the rays that met its black square."""
        K = self.K
        n = xs.size
        rx = (xs - K[0, 2]) / K[0, 0]
        ry = (ys - K[1, 2]) / K[1, 1]
        rays = np.zeros((n, 6), np.float32)
        rays[:, 3], rays[:, 4], rays[:, 5] = rx, ry, 1.0
        rgb = np.zeros((n, 3), np.float32)
        seen = [np.zeros(len(ob.mesh.faces), bool) for ob in self.objects]
        self.marker_hits = {}
        if not self.geom_owner:
            return rgb, np.zeros(n, bool), seen
        ans = self.rays.cast_rays(o3d.core.Tensor(rays), nthreads=1)
        depth = ans["t_hit"].numpy()  # the direction has z = 1: the hit distance is the depth (metres)
        hit = np.isfinite(depth)
        gid = ans["geometry_ids"].numpy()
        pid = ans["primitive_ids"].numpy()
        owner = np.full(n, -1, np.int64)
        shade = np.zeros(n, np.float32)
        for g, oi in enumerate(self.geom_owner):
            sel = np.flatnonzero(hit & (gid == g))
            owner[sel] = oi
            fr = self.face_rgbs[g][pid[sel]]
            rgb[sel] = fr[:, :3]
            shade[sel] = fr[:, 3]
            seen[oi][np.flatnonzero(self.front[oi])[np.unique(pid[sel])]] = True
        for mk in self.markers:
            bx0, by0, bx1, by1 = mk.box
            mine = np.flatnonzero((owner == mk.owner) & (xs >= bx0) & (xs <= bx1) & (ys >= by0) & (ys <= by1))
            if mine.size:
                self._paint_marker(mk, mine, rx, ry, depth, rgb, shade)
        return rgb, hit, seen

    def _paint_marker(
        self,
        mk: _Marker,
        mine: np.ndarray,
        rx: np.ndarray,
        ry: np.ndarray,
        depth: np.ndarray,
        rgb: np.ndarray,
        shade: np.ndarray,
    ) -> None:
        """Paper and ink of marker ``mk`` on the samples ``mine`` (indices) that see its object near it."""
        m, R, t, cell, half = mk.spec, mk.R, mk.t, mk.cell, mk.half
        nz = R[:, 2]
        ncell = mk.bits.shape[0]
        x, y = rx[mine], ry[mine]
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.dot(nz, t) / (nz[0] * x + nz[1] * y + nz[2])  # depth of the ray / marker-plane point
        # Marker-frame coordinates of that point: R^T (lam * d - t).
        lx = lam * (R[0, 0] * x + R[1, 0] * y + R[2, 0]) - np.dot(R[:, 0], t)
        ly = lam * (R[0, 1] * x + R[1, 1] * y + R[2, 1]) - np.dot(R[:, 1], t)
        on_face = (np.abs(depth[mine] - lam) < 2e-4) & (np.abs(lx) <= half) & (np.abs(ly) <= half)
        if not on_face.any():
            return
        idx = mine[on_face]
        lx, ly = lx[on_face], ly[on_face]
        col = np.floor((lx + 0.5 * m.size) / cell).astype(np.int64)
        row = np.floor((0.5 * m.size - ly) / cell).astype(np.int64)
        in_sq = (col >= 0) & (col < ncell) & (row >= 0) & (row < ncell)
        black = np.zeros(idx.size, bool)
        black[in_sq] = mk.bits[row[in_sq], col[in_sq]]
        albedo = np.where(black, np.float32(INK_BLACK), np.float32(PAPER_WHITE))
        rgb[idx] = (albedo * shade[idx])[:, None]
        self.marker_hits[m.id] = idx[in_sq]

    def footprint(self, x0: int, y0: int, h: int, w: int) -> np.ndarray:
        """``(h, w) bool`` pixels of the region at ``(x0, y0)`` whose centre a front face may cover."""
        mask = np.zeros((h, w), np.uint8)
        for oi, ob in enumerate(self.objects):
            tri = _project(self.K, self.cam_v[oi])[ob.mesh.faces[self.front[oi]]] - (x0, y0)
            # One triangle per call: fillPoly given many polygons fills their even-odd union, where two
            # overlapping faces (a wall and the one behind it) cancel.
            for t in np.round(tri * 16).astype(np.int32):
                cv2.fillConvexPoly(mask, t, 1, lineType=cv2.LINE_8, shift=4)
        # The fill's rounding at a triangle's border is within a pixel.
        return cv2.dilate(mask, np.ones((3, 3), np.uint8)).astype(bool)

    def edge_lines(self, x0: int, y0: int, seen: list[np.ndarray]) -> list[np.ndarray]:
        """Image segments (``(k, 2, 2)`` pixels relative to ``(x0, y0)``) where the colour may change.

        Edges of front faces between faces of different normals (creases,
        silhouettes) of faces ``seen`` by a pixel-centre ray or too thin to
        surely hold a pixel centre (their inscribed circle under 0.75 px), the
        outline of each marker's paper and the cell sides between ink and paper.
        """
        segs = []
        for oi, ob in enumerate(self.objects):
            front = self.front[oi]
            if not front.any():
                continue
            mesh = ob.mesh
            uv = _project(self.K, self.cam_v[oi])
            tri = uv[mesh.faces]
            e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
            area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            perimeter = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).sum(axis=1)
            thin = 2.0 * area < 0.75 * perimeter
            draw = np.zeros(len(mesh.edges_unique), bool)
            draw[mesh.faces_unique_edges[front & (seen[oi] | thin)].ravel()] = True
            draw[_flat_edges(mesh)] = False
            segs.append(uv[mesh.edges_unique[draw]] - (x0, y0))
        for mk in self.markers:
            segs.append(_project_segments(self.K, mk, _paper_lines(mk)) - (x0, y0))
        return segs


def _paper_lines(mk: _Marker) -> np.ndarray:
    """``(k, 2, 2)`` segments (marker frame, metres) where a marker's colour changes: the paper's outline and
    every cell side between ink and paper (the black square's outline included)."""
    n = mk.bits.shape[0]
    ink = np.pad(mk.bits, 1)  # the quiet zone around the square is paper
    edge = -0.5 * n * mk.cell + np.arange(n + 3) * mk.cell - mk.cell  # cell sides, x to the right
    r, c = np.nonzero(ink[:, 1:] != ink[:, :-1])  # side between columns c and c + 1 of row r
    vert = np.stack([np.column_stack([edge[c + 1], -edge[r]]), np.column_stack([edge[c + 1], -edge[r + 1]])], 1)
    r, c = np.nonzero(ink[1:, :] != ink[:-1, :])  # side between rows r and r + 1 of column c
    horiz = np.stack([np.column_stack([edge[c], -edge[r + 1]]), np.column_stack([edge[c + 1], -edge[r + 1]])], 1)
    h = mk.half
    outline = np.array([[[-h, -h], [h, -h]], [[h, -h], [h, h]], [[h, h], [-h, h]], [[-h, h], [-h, -h]]])
    return np.concatenate([vert, horiz, outline])


def _project_segments(K: np.ndarray, mk: _Marker, lines: np.ndarray) -> np.ndarray:
    """Image segments (pixels) of marker-frame segments ``(k, 2, 2)`` (metres)."""
    P = np.concatenate([lines, np.zeros((*lines.shape[:2], 1))], axis=2).reshape(-1, 3)
    return _project(K, P @ mk.R.T + mk.t).reshape(-1, 2, 2)


def _flat_edges(mesh: trimesh.Trimesh) -> np.ndarray:
    """Indices into ``mesh.edges_unique`` of edges between two coplanar faces (no crease: no colour change)."""
    flat = mesh.face_adjacency_angles < 1e-9
    pairs = np.sort(mesh.face_adjacency_edges[flat], axis=1)
    if len(pairs) == 0:
        return np.zeros(0, np.int64)
    eu = mesh.edges_unique  # sorted vertex pairs
    key_all = eu[:, 0].astype(np.int64) * len(mesh.vertices) + eu[:, 1]
    key = pairs[:, 0].astype(np.int64) * len(mesh.vertices) + pairs[:, 1]
    order = np.argsort(key_all)
    return order[np.searchsorted(key_all[order], key)]


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
    scene: _Scene, rgb: np.ndarray, hit: np.ndarray, seen: list[np.ndarray], x0: int, y0: int, h: int, w: int
) -> np.ndarray:
    """``(h, w) bool``: the region's pixels that a colour boundary may cross (from the pixel-centre pass)."""
    mask = np.zeros((h, w), np.uint8)
    for s in scene.edge_lines(x0, y0, seen):
        # 1/16 px fixed point; pixel centres at integers as OpenCV draws.
        cv2.polylines(mask, list(np.round(s * 16).astype(np.int32)), False, 1, lineType=cv2.LINE_8, shift=4)
    # LINE_8 marks one pixel per step along the line's major axis; the pixels the line crosses are that
    # one and its neighbours along the minor axis.
    mask = cv2.dilate(mask, np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], np.uint8))
    # Colour changes between neighbouring centres that no line explains (parts meeting mid-face): a
    # boundary crossing a pixel leaves the centre of the pixel or of one of its 4 neighbours on its other side.
    col = np.where(hit[:, None], rgb, np.float32(-1.0)).reshape(h, w, 3)
    for ax in (0, 1):
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[ax], b[ax] = slice(1, None), slice(None, -1)
        d = np.any(col[tuple(a)] != col[tuple(b)], axis=2)
        mask[tuple(a)][d] = 1
        mask[tuple(b)][d] = 1
    return mask.astype(bool)


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
        pts.append(_project(K, cam))
    allp = np.concatenate(pts)
    x0 = int(np.clip(np.floor(allp[:, 0].min()) - 2, 0, width))
    y0 = int(np.clip(np.floor(allp[:, 1].min()) - 2, 0, height))
    x1 = int(np.clip(np.ceil(allp[:, 0].max()) + 3, 0, width))
    y1 = int(np.clip(np.ceil(allp[:, 1].max()) + 3, 0, height))
    out = Rendered(image=image, roi=(x0, y0, x1, y1), marker_mask=np.full((height, width), -1, np.int32))
    if x1 <= x0 or y1 <= y0:
        return out
    light = np.asarray(light_dir_cam, float)
    scene = _Scene(objects, K, light / np.linalg.norm(light), ambient)
    h, w = y1 - y0, x1 - x0
    bg = image[y0:y1, x0:x1].copy()
    # Pass 1: one ray through each pixel centre that a front face may cover (every centre for the reference).
    inside = np.flatnonzero(scene.footprint(x0, y0, h, w) if edges_only else np.ones((h, w), bool))
    cv_, cu_ = np.divmod(inside, w)
    rgb_in, hit_in, seen = scene.look((cu_ + x0).astype(float), (cv_ + y0).astype(float))
    rgb = np.zeros((h * w, 3), np.float32)
    hit = np.zeros(h * w, bool)
    rgb[inside], hit[inside] = rgb_in, hit_in
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
    if S > 1:
        redo = _edge_pixels(scene, rgb, hit, seen, x0, y0, h, w).ravel() if edges_only else ~redo
    counts = {i: float(np.count_nonzero(~redo[ix])) for i, ix in centre_hits.items()}
    if redo.any():
        # Pass 2: S x S jittered rays through each pixel that a boundary may cross.
        ev, eu = np.divmod(np.flatnonzero(redo), w)
        out.supersampled_pixels = int(ev.size)
        xs, ys = _sample_points(eu + x0, ev + y0, S)
        samples, fhit, _ = scene.look(xs.ravel(), ys.ravel())
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
            out.marker_area[m.id] = _quad_area(_project(K, square @ mk.R.T + mk.t))
            out.marker_pixels[m.id] = counts[m.id]
            out.marker_facing[m.id] = float(-np.dot(mk.R[:, 2], mk.t) / np.linalg.norm(mk.t))
    out.image = image
    return out
