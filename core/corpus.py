"""A corpus of parts no one here tuned to: seeded CSG solids and the closed meshes of ``pybullet_data``.

Every stage that claims to work on "any part" is measured over this corpus
(placements against a drop test, grasps that hold, decomposition fidelity,
detection). The CSG families are what a user's CAD produces; each size is
drawn from the seed, so another seed is another corpus of the same families:

==============  =============================================================
``prism_hole``  block with one or two round through-holes
``prism_slot``  block with a rectangular slot through it
``chamfered``   block with its four vertical edges chamfered
``filleted``    rounded-rectangle prism (vertical fillets), with a bore
``tube``        long round tube
``wheel``       disc with a hub bore and 3-6 spoke windows
``plate``       thin plate (2-4 mm) with holes
``hex_peg``     hexagonal prism
``d_peg``       round peg with a flat (D section)
``keyed_peg``   round peg with a key along its side
``l_bracket``   L-shaped bracket with a hole in each leg
``rod``         long thin square or round bar (length over width 6-12)
``free_form``   a closed single-body mesh shipped in ``pybullet_data``
==============  =============================================================

``pybullet_data``'s meshes have no units; each is scaled so its largest
extent is a seeded 30-100 mm. Meshes made of several overlapping bodies
(``teddy2_VHACD_CHs.obj``, the trays) or open ones are left out.

Units: metres; part frame = the mesh's own frame (CSG parts: centred on
their bounding box, z up as they were modelled).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

__all__ = ["FAMILIES", "PYBULLET_MESHES", "CorpusPart", "corpus_part", "part_corpus", "write_cad_stl"]

log = logging.getLogger(__name__)

PYBULLET_MESHES: tuple[str, ...] = (
    "bunny.obj",
    "duck.obj",
    "domino/domino.obj",
    "laikago/hip_motor.obj",
    "laikago/lower_leg3.obj",
    "quadruped/tmotor3.obj",
    "soccerball.obj",
    "stone.obj",
    "torus/torus_textured.obj",
    "toys/concave_box.obj",
    "toys/cylinder.obj",
    "toys/prism.obj",
    "toys/shape_sorter.obj",
)
"""Closed single-body meshes of ``pybullet_data`` (after merging vertices split by texture seams)."""


@dataclass(frozen=True)
class CorpusPart:
    """One part of the corpus.

    ``mesh`` is watertight, in metres, in the part frame; ``family`` is one of
    :data:`FAMILIES`; ``source`` is ``"csg"`` or ``"pybullet_data:<file>"``.
    """

    name: str
    family: str
    mesh: trimesh.Trimesh
    source: str


_SECTIONS = 64


def _box(
    size: tuple[float, float, float], at: tuple[float, float, float] = (0, 0, 0), rot: np.ndarray | None = None
) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=size)
    if rot is not None:
        m.apply_transform(rot)
    m.apply_translation(at)
    return m


def _cyl(
    r: float, h: float, at: tuple[float, float, float] = (0, 0, 0), axis: str = "z", sections: int = _SECTIONS
) -> trimesh.Trimesh:
    m = trimesh.creation.cylinder(radius=r, height=h, sections=sections)
    if axis == "x":
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    elif axis == "y":
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    m.apply_translation(at)
    return m


def _minus(a: trimesh.Trimesh, *cuts: trimesh.Trimesh) -> trimesh.Trimesh:
    return trimesh.boolean.difference([a, *cuts], engine="manifold")


def _plus(*parts: trimesh.Trimesh) -> trimesh.Trimesh:
    return trimesh.boolean.union(list(parts), engine="manifold")


def _u(rng: np.random.Generator, lo_mm: float, hi_mm: float) -> float:
    """A length drawn uniformly in ``[lo_mm, hi_mm]`` millimetres, returned in metres."""
    return float(rng.uniform(lo_mm, hi_mm)) * 1e-3


def _prism_hole(rng: np.random.Generator) -> trimesh.Trimesh:
    x, y, z = _u(rng, 30, 80), _u(rng, 25, 60), _u(rng, 15, 40)
    n = int(rng.integers(1, 3))
    r = min(x / (2.5 * n), y / 2.5) * float(rng.uniform(0.5, 0.9))
    xs = [0.0] if n == 1 else [-x / 4, x / 4]
    return _minus(_box((x, y, z)), *[_cyl(r, 2 * z, (cx, 0, 0)) for cx in xs])


def _prism_slot(rng: np.random.Generator) -> trimesh.Trimesh:
    x, y, z = _u(rng, 40, 90), _u(rng, 25, 50), _u(rng, 20, 40)
    w, d = x * float(rng.uniform(0.2, 0.4)), z * float(rng.uniform(0.3, 0.6))
    return _minus(_box((x, y, z)), _box((w, 2 * y, 2 * d), (0, 0, z / 2)))


def _chamfered(rng: np.random.Generator) -> trimesh.Trimesh:
    x, y, z = _u(rng, 25, 70), _u(rng, 25, 70), _u(rng, 15, 50)
    c = min(x, y) * float(rng.uniform(0.1, 0.25))
    cuts = []
    for sx in (-1, 1):
        for sy in (-1, 1):
            R = trimesh.transformations.rotation_matrix(np.pi / 4, [0, 0, 1])
            cuts.append(_box((c * np.sqrt(2), c * np.sqrt(2), 2 * z), (sx * x / 2, sy * y / 2, 0), R))
    return _minus(_box((x, y, z)), *cuts)


def _filleted(rng: np.random.Generator) -> trimesh.Trimesh:
    x, y, z = _u(rng, 30, 80), _u(rng, 25, 60), _u(rng, 10, 30)
    r = min(x, y) * float(rng.uniform(0.1, 0.3))
    corners = [_cyl(r, z, (sx * (x / 2 - r), sy * (y / 2 - r), 0)) for sx in (-1, 1) for sy in (-1, 1)]
    body = trimesh.util.concatenate(corners).convex_hull
    return _minus(body, _cyl(min(x, y) * 0.2, 2 * z))


def _tube(rng: np.random.Generator) -> trimesh.Trimesh:
    r, length = _u(rng, 8, 25), _u(rng, 60, 120)
    wall = max(0.0015, r * float(rng.uniform(0.12, 0.3)))
    return _minus(_cyl(r, length), _cyl(r - wall, 2 * length))


def _wheel(rng: np.random.Generator) -> trimesh.Trimesh:
    R, t = _u(rng, 30, 60), _u(rng, 8, 20)
    hub, rim = R * 0.3, R * 0.8
    spokes = int(rng.integers(3, 7))
    windows = []
    half = np.pi / spokes * 0.55
    for k in range(spokes):
        a = 2 * np.pi * k / spokes + np.pi / spokes
        ang = np.linspace(a - half, a + half, 12)
        # a convex window (the hull of an annular sector), so no 2-D polygon library is needed
        ring = np.r_[np.c_[np.cos(ang), np.sin(ang)] * hub * 1.3, np.c_[np.cos(ang), np.sin(ang)] * rim]
        win = trimesh.convex.convex_hull(np.r_[np.c_[ring, np.full(len(ring), -t)], np.c_[ring, np.full(len(ring), t)]])
        windows.append(win)
    return _minus(_cyl(R, t), _cyl(hub * 0.5, 2 * t), *windows)


def _plate(rng: np.random.Generator) -> trimesh.Trimesh:
    x, y, t = _u(rng, 40, 110), _u(rng, 30, 80), _u(rng, 2, 4)
    r = min(x, y) * 0.08
    holes = [_cyl(r, 4 * t, (sx * x * 0.35, sy * y * 0.35, 0)) for sx in (-1, 1) for sy in (-1, 1)]
    return _minus(_box((x, y, t)), *holes)


def _hex_peg(rng: np.random.Generator) -> trimesh.Trimesh:
    return _cyl(_u(rng, 8, 25), _u(rng, 25, 90), sections=6)


def _d_peg(rng: np.random.Generator) -> trimesh.Trimesh:
    r, h = _u(rng, 8, 22), _u(rng, 25, 90)
    flat = r * float(rng.uniform(0.55, 0.8))
    return _minus(_cyl(r, h), _box((2 * r, 2 * r, 2 * h), (flat + r, 0, 0)))


def _keyed_peg(rng: np.random.Generator) -> trimesh.Trimesh:
    r, h = _u(rng, 8, 20), _u(rng, 30, 90)
    k = r * float(rng.uniform(0.3, 0.5))
    return _plus(_cyl(r, h), _box((k, k, h), (r, 0, 0)))


def _l_bracket(rng: np.random.Generator) -> trimesh.Trimesh:
    a, b, w, t = _u(rng, 30, 80), _u(rng, 25, 70), _u(rng, 20, 50), _u(rng, 4, 10)
    base = _box((a, w, t), (a / 2, 0, t / 2))
    leg = _box((t, w, b), (t / 2, 0, b / 2))
    r = min(w, a, b) * 0.12
    holes = _cyl(r, 4 * t, (a * 0.65, 0, t / 2)), _cyl(r, 4 * t, (t / 2, 0, b * 0.65), axis="x")
    body = _minus(_plus(base, leg), *holes)
    body.apply_translation(-body.bounds.mean(axis=0))
    return body


def _rod(rng: np.random.Generator) -> trimesh.Trimesh:
    w = _u(rng, 6, 16)
    length = w * float(rng.uniform(6, 12))
    if rng.random() < 0.5:
        return _box((length, w, w * float(rng.uniform(0.6, 1.0))))
    return _cyl(w / 2, length, axis="x")


_CSG: dict[str, Callable[[np.random.Generator], trimesh.Trimesh]] = {
    "prism_hole": _prism_hole,
    "prism_slot": _prism_slot,
    "chamfered": _chamfered,
    "filleted": _filleted,
    "tube": _tube,
    "wheel": _wheel,
    "plate": _plate,
    "hex_peg": _hex_peg,
    "d_peg": _d_peg,
    "keyed_peg": _keyed_peg,
    "l_bracket": _l_bracket,
    "rod": _rod,
}
FAMILIES: tuple[str, ...] = (*_CSG, "free_form")
"""Every family of the corpus, in corpus order."""


def _clean(mesh: trimesh.Trimesh, what: str) -> trimesh.Trimesh:
    mesh = trimesh.Trimesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), process=True)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.remove_unreferenced_vertices()
    trimesh.repair.fix_normals(mesh)
    if not (mesh.is_watertight and mesh.is_volume):
        raise RuntimeError(f"corpus part {what} is not a closed volume")  # a generator defect, not user input
    return mesh


def _pybullet_mesh(rel: str, rng: np.random.Generator) -> trimesh.Trimesh:
    import pybullet_data

    loaded = trimesh.load(Path(pybullet_data.getDataPath()) / rel, force="mesh", process=False)
    mesh = _clean(loaded, rel)
    mesh.apply_translation(-mesh.bounds.mean(axis=0))
    mesh.apply_scale(_u(rng, 30, 100) / float(np.max(mesh.extents)))
    return mesh


def _family_rng(seed: int, key: str) -> np.random.Generator:
    # one stream per part, so adding a family or a mesh leaves every other part as it was
    return np.random.default_rng([seed, *key.encode()])


def part_corpus(seed: int = 0, per_family: int = 3, free_form: bool = True) -> list[CorpusPart]:
    """The corpus: ``per_family`` parts of each CSG family, then the ``pybullet_data`` meshes.

    With the defaults, 12 x 3 + 13 = 49 parts. ``seed`` draws every size;
    ``free_form=False`` leaves out the ``pybullet_data`` meshes.
    """
    parts = [corpus_part(f"{family}_{i}", seed) for family in _CSG for i in range(per_family)]
    if free_form:
        parts += [corpus_part(_free_form_name(rel), seed) for rel in PYBULLET_MESHES]
    return parts


def _free_form_name(rel: str) -> str:
    return "ff_" + Path(rel).stem


def corpus_part(name: str, seed: int = 0) -> CorpusPart:
    """One corpus part by name (``"<family>_<index>"`` or ``"ff_<mesh stem>"``), as :func:`part_corpus` makes it."""
    rng = _family_rng(seed, name)
    if name.startswith("ff_"):
        for rel in PYBULLET_MESHES:
            if _free_form_name(rel) == name:
                return CorpusPart(name, "free_form", _pybullet_mesh(rel, rng), f"pybullet_data:{rel}")
    family, _, index = name.rpartition("_")
    if family in _CSG and index.isdigit():
        return CorpusPart(name, family, _clean(_CSG[family](rng), name), "csg")
    known = ", ".join(FAMILIES)
    raise ValueError(f"no corpus part {name!r}: give '<family>_<index>' (families: {known}) or 'ff_<mesh stem>'")


def write_cad_stl(mesh: trimesh.Trimesh, path: str | Path, *, open_faces: int = 3, seed: int = 0) -> Path:
    """Write ``mesh`` (metres) as a binary STL in millimetres with ``open_faces`` triangles missing.

    This is what CAD exports often look like: millimetre units and a few open
    edges. The removed faces are drawn from ``seed``; ``open_faces=0`` writes
    the closed mesh.
    """
    out = Path(path)
    m = mesh.copy()
    m.apply_scale(1000.0)
    if open_faces > 0:
        rng = np.random.default_rng(seed)
        drop = rng.choice(len(m.faces), size=min(open_faces, len(m.faces) - 4), replace=False)
        keep = np.ones(len(m.faces), dtype=bool)
        keep[drop] = False
        m.update_faces(keep)
    out.parent.mkdir(parents=True, exist_ok=True)
    m.export(out, file_type="stl")
    return out
