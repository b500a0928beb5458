"""The scene a demonstration frame is drawn from: front faces in the camera frame, cast rays, marker paper.

:class:`RayScene` holds the front-facing triangles of every part in the
camera frame (an Open3D/Embree ``RaycastingScene``), each face's flat shade
and plane, and the markers printed side toward the camera. It answers what a
ray through an image point sees (:meth:`RayScene.look`: the face hit, its
colour, the marker ink or paper there) and where the colour may change
(:meth:`RayScene.edge_lines`: creases, silhouettes, ink/paper boundaries),
which :mod:`.render` uses to supersample only the pixels that need it.
Metres in the camera frame (x right, y down, z forward); pixels with OpenCV's
convention (pixel centres at integer coordinates).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
import open3d as o3d
import trimesh

from asmteach.core.models import MarkerSpec
from asmteach.plugins.detectors.aruco.markers import marker_bits

if TYPE_CHECKING:
    from asmteach.plugins.detectors.aruco.render import RenderObject

__all__ = ["INK_BLACK", "PAPER_WHITE", "MarkerPaper", "RayScene", "project_points"]

PAPER_WHITE = 0.92
INK_BLACK = 0.05


def project_points(K: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``(n, 2)`` pixels of ``(n, 3)`` camera-frame points (metres), pinhole ``K``."""
    uvw = P @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


@dataclass
class MarkerPaper:
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


class RayScene:
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
        self.markers: list[MarkerPaper] = []
        planes: list[np.ndarray] = []
        plane_ids: list[np.ndarray] = []
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
                q = project_points(K, paper @ T[:3, :3].T + T[:3, 3])
                box = (*(q.min(axis=0) - 1.0), *(q.max(axis=0) + 1.0))
                self.markers.append(MarkerPaper(oi, m, T[:3, :3], T[:3, 3], bits, cell, half, box))
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
            nf = normals[front]
            planes.append(np.column_stack([nf, np.einsum("ij,ij->i", nf, cam_v[ob.mesh.faces[front][:, 0]])]))
            plane_ids.append(_plane_ids(ob.mesh)[front] + 10**7 * oi)
        # All geometries' faces stacked, plus a sentinel row (no hit: black, no owner).
        sizes = [len(t) for t in self.face_rgbs]
        self.face_offset = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        self.face_table = np.vstack([*self.face_rgbs, np.zeros((1, 4), np.float32)])
        self.face_owner = np.array([o for o, k in zip(self.geom_owner, sizes, strict=True) for _ in range(k)] + [-1])
        # Each face's plane (camera-frame normal n and n . p, metres) and the id of the flat region it belongs to.
        self.face_plane = np.vstack([*planes, np.zeros((1, 4))])
        self.face_region = np.concatenate([*plane_ids, [-1]]).astype(np.int64)

    def look(
        self, xs: np.ndarray, ys: np.ndarray, face: np.ndarray | None = None, cast: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[np.ndarray]]:
        """What the rays through image points ``(xs, ys)`` (pixels, flat) see: colour ``(n, 3)``, hit mask, the
        row of the face hit (-1: none) and, per object, which of its faces were hit (bool over its faces). Also
        sets ``marker_hits``: marker id -> indices of the rays that met its black square.

        Rays are cast (Embree) where ``cast`` is true (all by default); the others are known to meet the plane
        of face row ``face`` (a pixel no face edge crosses lies on its centre's face), met by the plane
        equation ``z = (n . p0) / (n . d)``.
        """
        K = self.K
        n = xs.size
        rx = (xs - K[0, 2]) / K[0, 0]
        ry = (ys - K[1, 2]) / K[1, 1]
        seen = [np.zeros(len(ob.mesh.faces), bool) for ob in self.objects]
        self.marker_hits = {}
        if not self.geom_owner:
            return np.zeros((n, 3), np.float32), np.zeros(n, bool), np.full(n, -1, np.int64), seen
        cast_ix = np.arange(n) if cast is None else np.flatnonzero(cast)
        face = np.full(n, -1, np.int64) if face is None else face.astype(np.int64)
        depth = np.full(n, np.inf, np.float32)
        if cast_ix.size:
            rays = np.zeros((cast_ix.size, 6), np.float32)
            rays[:, 3], rays[:, 4], rays[:, 5] = rx[cast_ix], ry[cast_ix], 1.0
            ans = self.rays.cast_rays(o3d.core.Tensor(rays), nthreads=1)
            t_hit = ans["t_hit"].numpy()  # the direction has z = 1: the hit distance is the depth (metres)
            ok = np.isfinite(t_hit)
            gid = np.minimum(ans["geometry_ids"].numpy(), len(self.geom_owner) - 1)
            face[cast_ix] = np.where(ok, self.face_offset[gid] + ans["primitive_ids"].numpy(), -1)
            depth[cast_ix] = t_hit
        if cast is not None:
            known = np.flatnonzero(~cast)
            plane = self.face_plane[face[known]]
            with np.errstate(divide="ignore", invalid="ignore"):
                depth[known] = plane[:, 3] / (plane[:, 0] * rx[known] + plane[:, 1] * ry[known] + plane[:, 2])
        hit = face >= 0
        # Misses index the sentinel last row of the stacked tables.
        table = self.face_table[face]
        rgb = np.ascontiguousarray(table[:, :3])
        shade = table[:, 3]
        owner = self.face_owner[face]
        was_hit = np.zeros(len(self.face_owner), bool)
        was_hit[face] = True
        for g, oi in enumerate(self.geom_owner):
            rows = was_hit[self.face_offset[g] : self.face_offset[g] + len(self.face_rgbs[g])]
            seen[oi][np.flatnonzero(self.front[oi])[rows]] = True
        for mk in self.markers:
            bx0, by0, bx1, by1 = mk.box
            mine = np.flatnonzero((owner == mk.owner) & (xs >= bx0) & (xs <= bx1) & (ys >= by0) & (ys <= by1))
            if mine.size:
                self._paint_marker(mk, mine, rx, ry, depth, rgb, shade)
        return rgb, hit, face, seen

    def _paint_marker(
        self,
        mk: MarkerPaper,
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
            tri = project_points(self.K, self.cam_v[oi])[ob.mesh.faces[self.front[oi]]] - (x0, y0)
            # One triangle per call: fillPoly given many polygons fills their even-odd union, where two
            # overlapping faces (a wall and the one behind it) cancel.
            for t in np.round(tri * 16).astype(np.int32):
                cv2.fillConvexPoly(mask, t, 1, lineType=cv2.LINE_8, shift=4)
        # The fill's rounding at a triangle's border is within a pixel.
        return cv2.dilate(mask, np.ones((3, 3), np.uint8)).astype(bool)

    def edge_lines(self, x0: int, y0: int, seen: list[np.ndarray]) -> list[list[np.ndarray]]:
        """Image segments (``(k, 2, 2)`` arrays, pixels relative to ``(x0, y0)``) where the colour may change:
        ``[face edges, marker edges]``.

        Face edges: edges of front faces between faces of different normals
        (creases, silhouettes) of faces ``seen`` by a pixel-centre ray or too
        thin to surely hold a pixel centre (their inscribed circle under
        0.75 px). Marker edges: the outline of each marker's paper and the cell
        sides between ink and paper.
        """
        segs: list[np.ndarray] = []
        for oi, ob in enumerate(self.objects):
            front = self.front[oi]
            if not front.any():
                continue
            mesh = ob.mesh
            uv = project_points(self.K, self.cam_v[oi])
            tri = uv[mesh.faces]
            e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
            area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
            perimeter = np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).sum(axis=1)
            thin = 2.0 * area < 0.75 * perimeter
            draw = np.zeros(len(mesh.edges_unique), bool)
            draw[mesh.faces_unique_edges[front & (seen[oi] | thin)].ravel()] = True
            draw[_flat_edges(mesh)] = False
            segs.append(uv[mesh.edges_unique[draw]] - (x0, y0))
        paper = [_project_segments(self.K, mk, _paper_lines(mk)) - (x0, y0) for mk in self.markers]
        return [segs, paper]


def _paper_lines(mk: MarkerPaper) -> np.ndarray:
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


def _project_segments(K: np.ndarray, mk: MarkerPaper, lines: np.ndarray) -> np.ndarray:
    """Image segments (pixels) of marker-frame segments ``(k, 2, 2)`` (metres)."""
    P = np.concatenate([lines, np.zeros((*lines.shape[:2], 1))], axis=2).reshape(-1, 3)
    return project_points(K, P @ mk.R.T + mk.t).reshape(-1, 2, 2)


def _plane_ids(mesh: trimesh.Trimesh) -> np.ndarray:
    """Per face, the id of the flat region (connected coplanar faces, trimesh's facets) it belongs to."""
    ids = np.arange(len(mesh.faces))
    for facet in mesh.facets:
        ids[facet] = facet.min()
    return ids


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
