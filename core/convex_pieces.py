"""Convex decomposition of any part, for physics engines: exact where it can be, measured always.

A physics engine collides convex shapes. Approximate decompositions (V-HACD)
fill a 0.5 mm-clearance hole and inflate faces by up to a millimetre, so a
peg can never enter its hole in simulation. This module is the one convex
decomposition of the project (PyBullet worlds, the grasp hold check); it
picks the first route that applies to a :class:`PartModel`:

``solid``
    A parametric solid ``union(add) - union(subtract)`` of boxes and
    cylinders has an exact decomposition: each added primitive ``P`` is
    convex, and for a convex cut ``C = {x : n_k . x <= d_k for all k}``

        P - C = union over k of (P and {n_k . x >= d_k})

    is a union of convex pieces (they overlap, which collision detection does
    not mind). Repeating this for every cut gives pieces whose union is
    exactly the solid (up to the cylinders' 64-sided polygons, which the
    part's mesh uses too). Pieces thinner than ``min_thickness`` are dropped.
``convex``
    A convex mesh is its own hull: one piece.
``plane_split``
    A mesh (STL/OBJ from CAD) is split recursively with manifold3d along the
    planes of its own faces until every piece is convex (:func:`split_convex`).
    Every cut runs along a face of the mesh, so the pieces' union *is* the
    mesh (to float32 rounding and the 0.2 um cut offset): no hole, slot or
    groove is filled. It is kept when its measured protrusion and uncovered
    distance are within ``tolerance`` (pieces it had to replace by their hull,
    float slivers mostly, are measured like every other).
``coacd``
    Otherwise (curved free-form meshes, whose split would need too many
    pieces) CoACD (collision-aware approximate convex decomposition) with a
    fixed seed; its concavity threshold is derived from ``tolerance`` and the
    part's size (CoACD works on the mesh normalised to its bounding box),
    bounded below by ``min_coacd_threshold`` to keep its run time in seconds.
    When the plane split, hulls and all, is closer to the mesh than CoACD's
    result (larger of protrusion and uncovered distance), it is kept.

Every result carries its measured fidelity (:func:`fidelity`): the two-sided
Hausdorff distance between the union of pieces and the mesh, the largest
protrusion of the pieces outside the mesh (what closes a clearance), the
largest distance of the mesh surface from the pieces, and the union's volume
error, by seeded surface sampling (trimesh's exact closest-point queries,
Open3D ray casting for inside/outside, vectorised).

Decompositions are cached on disk under ``convex_pieces`` in
:func:`asmteach.core.io.cache_root`, keyed by the mesh hash (and the solid
spec, for parametric parts) plus the settings; files are written atomically,
and a damaged or foreign file is rebuilt.

Planning does not use these pieces: its collision checks (FCL) test the exact
mesh's BVH (:mod:`asmteach.core.arm.collision`), which is
mesh-exact contact already. Only physics simulation needs convex pieces.

Units: metres, part frame.
"""

from __future__ import annotations

import hashlib
import json
import logging
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import manifold3d
import numpy as np
import trimesh
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from asmteach.core.interfaces import PartModel
from asmteach.core.io import atomic_path, cache_root
from asmteach.core.models import Primitive, SolidSpec

__all__ = [
    "CACHE_VERSION",
    "ConvexDecomposition",
    "DecompositionSettings",
    "coacd_pieces",
    "decompose",
    "default_cache_dir",
    "fidelity",
    "pieces_obj",
    "pieces_volume_error",
    "primitive_halfspaces",
    "solid_pieces",
    "split_convex",
]

log = logging.getLogger(__name__)

CYLINDER_SECTIONS = 64
"""Sides of the polygon standing in for a cylinder (as in :func:`asmteach.core.parts.build_solid`)."""

_MAX_TRIES = 12
"""Cutting planes tried on one piece before it is given up (replaced by its hull)."""

_CUT_OFFSET = 2e-7
"""Metres between a cutting plane and the face it is taken from (see :func:`split_convex`)."""

CACHE_VERSION = 2
"""Bump when a change to the code changes the pieces it makes (old cache files are then ignored)."""


# ----------------------------------------------------------------------------- settings and result
@dataclass(frozen=True)
class DecompositionSettings:
    """Everything a decomposition depends on besides the part (the cache key holds all of it)."""

    tolerance: float = 1e-4
    """Largest accepted protrusion and uncovered distance of the convex and plane-split routes, metres."""
    max_pieces: int = 512
    """Most pieces the plane split may make before it gives up on a piece (replaced by its hull); a block
    with two 64-sided holes needs about 200, a plate with four holes about 430."""
    min_coacd_threshold: float = 0.02
    """Lower bound of CoACD's normalised concavity threshold (smaller ones take minutes per part)."""
    coacd_resolution: int = 2000
    """CoACD's surface samples per concavity evaluation."""
    seed: int = 0
    """Seed of CoACD's tree search and of the fidelity samples."""
    samples: int = 20000
    """Surface samples for each direction of the fidelity measure."""
    min_thickness: float = 1e-4
    """Pieces of a parametric solid thinner than this (metres) are dropped."""


@dataclass
class ConvexDecomposition:
    """Convex pieces of a part and how faithful they are (part frame, metres)."""

    pieces: list[np.ndarray]
    """Vertices ``(k, 3)`` of each convex piece."""
    method: str
    """``"solid"``, ``"convex"``, ``"plane_split"`` or ``"coacd"`` (see the module docstring)."""
    hausdorff: float
    """Two-sided Hausdorff distance between the union of pieces and the mesh, metres (sampled)."""
    protrusion: float
    """Largest distance of a piece's point outside the mesh, metres (sampled; closes clearances)."""
    volume_error: float
    """``|vol(union of pieces) - vol(mesh)| / vol(mesh)``."""
    uncovered: float = 0.0
    """Largest distance of a point of the mesh surface from the pieces, metres (sampled; 0 when covered)."""
    seconds: float = 0.0
    """Time the decomposition and its measurement took when it was built (not when read from the cache)."""
    cached: bool = field(default=False, compare=False)
    """Whether this result was read from the disk cache."""

    def hulls(self) -> list[trimesh.Trimesh]:
        """Each piece as a closed convex ``trimesh.Trimesh`` (its hull)."""
        return [_hull(v) for v in self.pieces]

    def obj(self) -> str:
        """Wavefront OBJ text, one object per piece (see :func:`pieces_obj`)."""
        return pieces_obj(self.pieces)


# ----------------------------------------------------------------------------- parametric solids
def primitive_halfspaces(p: Primitive, sections: int = CYLINDER_SECTIONS) -> np.ndarray:
    """``(m, 4)`` rows ``[n, -d]`` with ``n . x - d <= 0`` inside the primitive (part frame, metres)."""
    if p.shape == "box":
        half = 0.5 * np.asarray(p.size, dtype=float)
        normals = np.vstack([np.eye(3), -np.eye(3)])
        offsets = np.concatenate([half, half])
    else:
        # trimesh's cylinder polygon: vertices at angles 2 pi i / sections, radius r; faces between them.
        ang = 2.0 * np.pi * (np.arange(sections) + 0.5) / sections
        side = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(sections)])
        apothem = float(p.radius) * np.cos(np.pi / sections)
        normals = np.vstack([side, [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]])
        offsets = np.concatenate([np.full(sections, apothem), [0.5 * p.height, 0.5 * p.height]])
    T = np.asarray(p.pose, dtype=float)
    n_world = normals @ T[:3, :3].T
    d_world = offsets + n_world @ T[:3, 3]
    return np.column_stack([n_world, -d_world])


def _interior_point(hs: np.ndarray) -> tuple[np.ndarray, float]:
    """Chebyshev centre and radius (metres) of ``{x : A x + b <= 0}``; radius 0 when empty."""
    A, b = hs[:, :3], hs[:, 3]
    norm = np.linalg.norm(A, axis=1)
    # maximise r subject to A x + r |a| <= -b
    res = linprog(c=[0, 0, 0, -1], A_ub=np.column_stack([A, norm]), b_ub=-b,
                  bounds=[(None, None)] * 3 + [(0, None)], method="highs")
    if not res.success:
        return np.zeros(3), 0.0
    return res.x[:3], float(res.x[3])


def solid_pieces(solid: SolidSpec, min_thickness: float = 1e-4) -> list[np.ndarray]:
    """Vertices ``(k, 3)`` of convex pieces whose union is the solid (part frame, metres)."""
    # each piece: its halfspaces and an interior point (the Chebyshev centre found when it was accepted)
    pieces = [(hs, _interior_point(hs)[0]) for hs in (primitive_halfspaces(p) for p in solid.add)]
    for cut in solid.subtract:
        C = primitive_halfspaces(cut)
        out: list[tuple[np.ndarray, np.ndarray]] = []
        for hs, centre in pieces:
            if _interior_point(np.vstack([hs, C]))[1] < 0.5 * min_thickness:
                out.append((hs, centre))  # the cut misses this piece
                continue
            for row in C:
                cand = np.vstack([hs, -row])  # outside this face of the cut: n . x >= d
                inner, radius = _interior_point(cand)
                if radius >= 0.5 * min_thickness:
                    out.append((cand, inner))
        pieces = out
    result = []
    for hs, centre in pieces:
        pts = HalfspaceIntersection(hs, centre).intersections
        result.append(pts[ConvexHull(pts).vertices])
    return result


# ----------------------------------------------------------------------------- meshes: exact plane split
def _to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    return manifold3d.Manifold(
        manifold3d.Mesh(
            vert_properties=np.asarray(mesh.vertices, dtype=np.float32),
            tri_verts=np.asarray(mesh.faces, dtype=np.uint32),
        )
    )


def _to_trimesh(man: manifold3d.Manifold) -> trimesh.Trimesh:
    g = man.to_mesh()
    mesh = trimesh.Trimesh(np.asarray(g.vert_properties)[:, :3].astype(float), np.asarray(g.tri_verts), process=True)
    mesh.merge_vertices()
    # A cut through a plane that already holds faces can leave a zero-thickness sheet:
    # pairs of coincident back-to-back triangles. Remove both faces of every such pair.
    pairs = trimesh.grouping.group_rows(np.sort(mesh.faces, axis=1), require_count=2)
    if len(pairs):
        keep = np.ones(len(mesh.faces), dtype=bool)
        keep[np.asarray(pairs).ravel()] = False
        mesh.update_faces(keep)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    return mesh


def _is_convex(mesh: trimesh.Trimesh, rel_tol: float = 1e-4) -> bool:
    hull = float(mesh.convex_hull.volume)
    return hull - float(mesh.volume) <= rel_tol * hull


def split_convex(mesh: trimesh.Trimesh, max_pieces: int = 128) -> tuple[list[trimesh.Trimesh], int]:
    """Convex pieces whose union is ``mesh`` (cut along its own face planes), and how many are hulls.

    A piece is cut along the plane of its largest face that cuts it; a piece
    that no face plane splits any more (float32 slivers) or that would exceed
    ``max_pieces`` is replaced by its convex hull; the count of those is
    returned. Hulls of slivers are usually exact to a micrometre, which
    :func:`fidelity` measures.
    """
    # Coordinates are snapped to float32 first, as manifold3d stores them, so a cutting
    # plane through a face passes exactly through its vertices and leaves no sliver.
    start = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=np.float32).astype(float), mesh.faces, process=True)
    todo, done, approx = [start], [], 0
    while todo:
        m = todo.pop()
        if _is_convex(m):
            done.append(m)
            continue
        if len(done) + len(todo) + 2 > max_pieces:
            done.append(m.convex_hull)
            approx += 1
            continue
        normals, offsets = m.face_normals, np.einsum("ij,ij->i", m.face_normals, m.triangles_center)
        signed = np.asarray(m.vertices) @ normals.T - offsets[None, :]
        cuts = (signed > 1e-7).any(axis=0) & (signed < -1e-7).any(axis=0)
        if not cuts.any():
            done.append(m.convex_hull)
            approx += 1
            continue
        # Faces on one plane share its area; cut along the plane with the most first. A plane whose cut
        # only shaves float noise off (its vertices beyond it are rounding) is skipped for the next one.
        key = np.round(np.c_[normals, offsets], 6)
        planes, inverse = np.unique(key, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        area = np.bincount(inverse, weights=m.area_faces, minlength=len(planes))
        usable = np.zeros(len(planes), dtype=bool)
        usable[inverse[cuts]] = True
        man, split = _to_manifold(m), None
        for best in np.argsort(-np.where(usable, area, -1.0))[: min(int(usable.sum()), _MAX_TRIES)]:
            # the plane's exact equation is its largest face's: the rounded key (1 um) only groups faces
            members = np.flatnonzero(inverse == best)
            f = int(members[np.argmax(m.area_faces[members])])
            # The cut runs 0.2 um off the face, on its open side: cut exactly through it, the face would stay
            # behind as a zero-thickness sheet joining the bodies beyond it (the two sides of a slot) into one
            # piece, whose hull then fills the slot. Off the face, the other side gains a 0.2 um slab at most.
            a, b = man.split_by_plane(normals[f].tolist(), float(offsets[f]) + _CUT_OFFSET)
            if min(a.volume(), b.volume()) >= 1e-6 * float(m.volume):
                split = (a, b)
                break
        if split is None:
            done.append(m.convex_hull)
            approx += 1
            continue
        for half in split:
            # A cut along a plane holding a face of the other side leaves a float-thin sheet there, a body of
            # its own: a further cut cannot part it from the rest, whose hull would then fill the gap. Drop
            # such sheets (under a micrometre thick on average); keep every real body as a piece of its own.
            for body in half.decompose():
                t = _to_trimesh(body)
                if len(t.faces) >= 4 and float(t.volume) > 1e-6 * float(t.area):
                    todo.append(t)
    return done, approx



# ----------------------------------------------------------------------------- meshes: CoACD
def coacd_threshold(mesh: trimesh.Trimesh, settings: DecompositionSettings) -> float:
    """CoACD's concavity threshold for ``settings.tolerance`` metres on this mesh.

    CoACD measures concavity on the mesh scaled so its largest extent spans
    [-1, 1], so one normalised unit is half the largest extent.
    """
    half = 0.5 * float(np.max(mesh.extents))
    return float(np.clip(settings.tolerance / half, settings.min_coacd_threshold, 1.0))


def coacd_pieces(mesh: trimesh.Trimesh, settings: DecompositionSettings) -> list[np.ndarray]:
    """CoACD's convex pieces of a closed mesh (vertices ``(k, 3)``, same frame and units)."""
    import coacd

    coacd.set_log_level("error")
    # CoACD normalises internally; millimetres keep its absolute epsilons away from float noise.
    scale = 1000.0
    m = coacd.Mesh(np.asarray(mesh.vertices, dtype=float) * scale, np.asarray(mesh.faces, dtype=np.int32))
    # a part's mesh is closed and manifold already: the voxel remeshing of preprocessing would only blur it
    mode = "off" if mesh.is_watertight and mesh.is_winding_consistent else "on"
    parts = coacd.run_coacd(m, threshold=coacd_threshold(mesh, settings), preprocess_mode=mode,
                            resolution=settings.coacd_resolution, seed=settings.seed, max_convex_hull=-1)
    out = []
    for v, _ in parts:
        v = np.asarray(v, dtype=float) / scale
        if len(v) >= 4:
            out.append(_hull_vertices(v))
    return [v for v in out if v is not None]


# ----------------------------------------------------------------------------- fidelity
def _hull(v: np.ndarray) -> trimesh.Trimesh:
    return trimesh.convex.convex_hull(np.asarray(v, dtype=float))


def _hull_vertices(v: np.ndarray) -> np.ndarray | None:
    """The hull's corner vertices; ``None`` for a flat or degenerate point set."""
    try:
        h = ConvexHull(v)
    except Exception:  # noqa: BLE001 - qhull refuses flat sets with several error types
        return None
    return np.asarray(v)[h.vertices] if h.volume > 0 else None


def _outside(mesh: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    """Whether each point is outside the closed mesh (Open3D ray parity; only its sign is used)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)))
    return scene.compute_occupancy(o3d.core.Tensor(np.asarray(pts, dtype=np.float32))).numpy() < 0.5


def _distance(mesh: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    """Exact distance (float64, metres) of each point to the mesh surface.

    trimesh's closest-point query, not Open3D's: Open3D's answers on the long
    thin triangles of CAD meshes are off by tens of micrometres.
    """
    if len(pts) == 0:
        return np.zeros(0)
    return np.asarray(trimesh.proximity.closest_point(mesh, np.asarray(pts, dtype=float))[1], dtype=float)


def _inside_any(hulls: list[trimesh.Trimesh], pts: np.ndarray, tol: float,
                skip: np.ndarray | None = None) -> np.ndarray:
    """Whether each point is within ``tol`` of the inside of some hull (but the one ``skip`` names)."""
    inside = np.zeros(len(pts), dtype=bool)
    for i, h in enumerate(hulls):
        n, d = h.face_normals, np.einsum("ij,ij->i", h.face_normals, h.triangles[:, 0])
        lo, hi = h.bounds
        near = np.all((pts >= lo - tol) & (pts <= hi + tol), axis=1) & ~inside
        if skip is not None:
            near &= skip != i
        idx = np.flatnonzero(near)
        if len(idx):
            inside[idx[np.all(pts[idx] @ n.T - d <= tol, axis=1)]] = True
    return inside


def fidelity(pieces: list[np.ndarray], mesh: trimesh.Trimesh, samples: int = 20000,
             seed: int = 0) -> tuple[float, float, float, float]:
    """``(hausdorff, protrusion, volume_error, uncovered)`` of convex pieces against a closed mesh (metres,
    metres, ratio, metres).

    * mesh to pieces: ``samples`` points on the mesh surface; each one's
      distance to the union of pieces (0 inside a piece);
    * pieces to mesh: ``samples`` points on the pieces' outer surface (points
      inside another piece are interior, not surface); each one's distance
      to the mesh surface;
    * ``hausdorff`` is the larger maximum of the two; ``protrusion`` the
      largest distance outside the mesh of those points and of every piece
      vertex (a convex piece's farthest reach past a flat face is a vertex; this
      is what closes a clearance; 0 when all lie inside);
    * ``volume_error``: volume of the pieces' union (manifold3d, exact) against the mesh's;
    * ``uncovered``: the mesh-to-pieces maximum alone.

    The Hausdorff distance also counts gaps between pieces deep inside the
    material (their faces are the union's surface too); no other body can
    reach those, so a decomposition is judged by ``protrusion`` and
    ``uncovered``.
    """
    hulls = [_hull(v) for v in pieces]
    tol = 1e-7  # metres: on a shared face of two pieces counts as inside the other
    rng = np.random.default_rng(seed)
    mesh_pts = np.asarray(trimesh.sample.sample_surface(mesh, samples, seed=rng)[0])
    union = trimesh.util.concatenate(hulls)
    outside = ~_inside_any(hulls, mesh_pts, tol)
    # outside every piece, the distance to the union is the distance to the nearest piece triangle
    d_mesh = np.zeros(len(mesh_pts))
    d_mesh[outside] = _distance(union, mesh_pts[outside])
    pts, face = trimesh.sample.sample_surface(union, samples, seed=rng)
    owner = np.searchsorted(np.cumsum([len(h.faces) for h in hulls]), face, side="right")
    outer = ~_inside_any(hulls, np.asarray(pts), tol, skip=owner)
    piece_pts = np.vstack([np.asarray(pts)[outer], union.vertices])
    d_piece = _distance(mesh, piece_pts)
    out = d_piece > 1e-7
    protruding = np.zeros(len(piece_pts), dtype=bool)
    protruding[out] = _outside(mesh, piece_pts[out])
    # corners deep in the material are no surface: vertices count for the protrusion only
    hausdorff = float(max(d_mesh.max(initial=0.0), d_piece[: int(outer.sum())].max(initial=0.0)))
    protrusion = float(d_piece[protruding].max(initial=0.0))
    man = manifold3d.Manifold.batch_boolean([manifold3d.Manifold.hull_points(np.asarray(v, dtype=float))
                                             for v in pieces], manifold3d.OpType.Add)
    volume_error = abs(man.volume() - float(mesh.volume)) / float(mesh.volume)
    return hausdorff, protrusion, float(volume_error), float(d_mesh.max(initial=0.0))


def pieces_volume_error(part: PartModel, pieces: list[trimesh.Trimesh] | list[np.ndarray]) -> float:
    """Relative volume difference between the pieces' sum of volumes (overlaps counted twice) and the part."""
    vols = [float(p.volume) if isinstance(p, trimesh.Trimesh) else float(ConvexHull(p).volume) for p in pieces]
    return abs(sum(vols) - float(part.mesh.volume)) / float(part.mesh.volume)


# ----------------------------------------------------------------------------- the one entry point
def default_cache_dir() -> Path:
    """``convex_pieces`` in :func:`asmteach.core.io.cache_root` (``$ASMTEACH_CACHE_DIR``, ``$XDG_CACHE_HOME``)."""
    return cache_root() / "convex_pieces"


def cache_key(part: PartModel, settings: DecompositionSettings) -> str:
    """Hash of everything the decomposition depends on: mesh, solid spec (if any), settings, code version."""
    from asmteach.core.parts import mesh_hash

    solid = part.spec.solid.model_dump(mode="json") if part.spec.solid is not None else None
    blob = json.dumps({"v": CACHE_VERSION, "mesh": part.source_hash or mesh_hash(part.mesh), "solid": solid,
                       "settings": asdict(settings)}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def _cache_path(part: PartModel, key: str, cache_dir: Path | None) -> Path:
    safe = "".join(c if c.isalnum() or c in "-_" else "_" for c in part.name)[:40]
    return (cache_dir or default_cache_dir()) / f"{safe}-{key}.npz"


def _save(path: Path, key: str, d: ConvexDecomposition) -> None:
    counts = np.array([len(v) for v in d.pieces], dtype=np.int64)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, key=np.array(key), method=np.array(d.method), counts=counts,
                 vertices=np.vstack(d.pieces).astype("<f8"),
                 figures=np.array([d.hausdorff, d.protrusion, d.volume_error, d.uncovered, d.seconds]))


def _load(path: Path, key: str) -> ConvexDecomposition | None:
    """The cached decomposition, or ``None`` when the file is missing, damaged or of another key."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["key"]) != key:
                raise ValueError("the file holds another part's or settings' pieces")
            counts, verts, figures = z["counts"], z["vertices"], z["figures"]
            method = str(z["method"])
        if counts.sum() != len(verts) or verts.ndim != 2 or verts.shape[1] != 3 or (counts < 4).any():
            raise ValueError("piece counts do not match the vertices")
        if not np.all(np.isfinite(verts)) or len(figures) != 5:
            raise ValueError("non-finite vertices or missing figures")
        pieces = np.split(verts, np.cumsum(counts)[:-1])
        h, p, v, u, s = (float(x) for x in figures)
        return ConvexDecomposition(pieces, method, h, p, v, u, s, cached=True)
    except Exception as exc:  # noqa: BLE001 - zip, npy and key errors alike: a damaged cache is rebuilt, not fatal
        log.warning("convex pieces cache %s is unreadable (%s); rebuilding it", path, exc)
        return None


_MEMO: dict[str, ConvexDecomposition] = {}
"""Decompositions already made or read in this process (plan re-checks spawn the same parts many times)."""


def decompose(part: PartModel, settings: DecompositionSettings | None = None, *, cache: bool = True,
              cache_dir: Path | None = None) -> ConvexDecomposition:
    """Convex pieces of ``part`` (part frame, metres) by the first route that applies (module docstring).

    ``cache``: read and write the on-disk cache (``cache_dir``, default
    :func:`default_cache_dir`); a failed write only costs a rebuild next time.
    """
    s = settings or DecompositionSettings()
    key = cache_key(part, s)
    if cache and key in _MEMO:
        return _MEMO[key]
    path = _cache_path(part, key, cache_dir)
    result = _load(path, key) if cache else None
    if result is None:
        result = _build(part, s)
        if cache:
            try:
                _save(path, key, result)
            except OSError as exc:
                log.warning("cannot cache convex pieces at %s: %s", path, exc)
    if cache:
        _MEMO[key] = result
    return result


def _build(part: PartModel, s: DecompositionSettings) -> ConvexDecomposition:
    t0 = time.perf_counter()
    mesh = part.mesh

    def done(pieces: list[np.ndarray], method: str, figures: tuple[float, float, float, float] | None = None
             ) -> ConvexDecomposition:
        h, p, v, u = figures or fidelity(pieces, mesh, s.samples, s.seed)
        return ConvexDecomposition(pieces, method, h, p, v, u, time.perf_counter() - t0)

    if part.spec.solid is not None:
        return done(solid_pieces(part.spec.solid, s.min_thickness), "solid")
    hull = mesh.convex_hull
    if float(hull.volume) - float(mesh.volume) <= 1e-6 * float(hull.volume):
        # nearly convex by volume; a long part can still hide a shallow dent the hull would fill: measure
        hull_v = [np.asarray(hull.vertices, dtype=float)]
        hull_fig = fidelity(hull_v, mesh, s.samples, s.seed)
        if hull_fig[1] <= s.tolerance:
            return done(hull_v, "convex", hull_fig)
    split, approx = split_convex(mesh, s.max_pieces)
    split_v = [v for v in (_hull_vertices(np.asarray(p.vertices)) for p in split) if v is not None]
    split_fig = fidelity(split_v, mesh, s.samples, s.seed)
    # judged by what collides: protrusion and uncovered surface (module docstring of fidelity)
    if max(split_fig[1], split_fig[3]) <= s.tolerance:
        return done(split_v, "plane_split", split_fig)
    co = coacd_pieces(mesh, s)
    co_fig = fidelity(co, mesh, s.samples, s.seed) if co else (np.inf, np.inf, np.inf, np.inf)
    log.info("%s: plane split left %d hulls (protrusion %.3g mm), CoACD protrusion %.3g mm", part.name, approx,
             1e3 * split_fig[1], 1e3 * co_fig[1])
    if max(split_fig[1], split_fig[3]) <= max(co_fig[1], co_fig[3]):
        return done(split_v, "plane_split", split_fig)
    return done(co, "coacd", co_fig)


def pieces_obj(pieces: list[np.ndarray]) -> str:
    """Wavefront OBJ text with one object (a triangulated convex hull) per piece, as engines load compounds."""
    lines: list[str] = []
    base = 1
    for i, v in enumerate(pieces):
        hull = ConvexHull(v)
        lines.append(f"o piece_{i}")
        lines += [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in hull.points]
        lines += [f"f {a + base} {b + base} {c + base}" for a, b, c in hull.simplices]
        base += len(hull.points)
    return "\n".join(lines) + "\n"
