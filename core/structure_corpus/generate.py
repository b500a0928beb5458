"""A structure from its family and seed: part frames, markers, densities; the corpus; marker checks."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.corpus import _clean
from asmteach.core.models import MarkerSpec
from asmteach.core.structure_corpus.build import FamilyBuild
from asmteach.core.structure_corpus.markers import DICT_IDS, MARKER_DICTIONARY, marker_pose, pick_layout, quiet_side
from asmteach.core.structure_corpus.pegs import d_peg, hex_peg, keyed_peg, round_peg, square_peg
from asmteach.core.structure_corpus.pin_cap_bracket import bracket_on_block, cap_on_post, side_pin
from asmteach.core.structure_corpus.slides import dovetail_slide, t_slot_slide


@dataclass(frozen=True)
class GeneratedStructure:
    """A generated two-part structure (metres; each mesh in its own part frame).

    ``T_A_B``: B's frame in A's frame, assembled. ``v_a``: unit insertion
    direction in A's frame. ``clearance``: B's lateral play (metres) along each
    of ``play_axes`` (unit vectors, A's frame). ``insertion_depth``: how far B
    travels along ``v_a`` while any part of it overlaps A's extent along ``v_a``
    (metres): retracting B by more than this along ``-v_a`` frees it.
    ``params``: the drawn sizes in millimetres (and the variant), for reports.
    """

    name: str
    family: str
    part_a: trimesh.Trimesh
    part_b: trimesh.Trimesh
    name_a: str
    name_b: str
    T_A_B: np.ndarray
    v_a: np.ndarray
    clearance: float
    play_axes: tuple[tuple[float, float, float], ...]
    insertion_depth: float
    markers_a: list[MarkerSpec]
    markers_b: list[MarkerSpec]
    density_a: float
    density_b: float
    description: str
    params: dict[str, float | str] = field(default_factory=dict)


_FAMILIES: dict[str, Callable[[np.random.Generator], FamilyBuild]] = {
    "round_peg": round_peg,
    "square_peg": square_peg,
    "hex_peg": hex_peg,
    "d_peg": d_peg,
    "keyed_peg": keyed_peg,
    "dovetail_slide": dovetail_slide,
    "t_slot_slide": t_slot_slide,
    "side_pin": side_pin,
    "cap_on_post": cap_on_post,
    "bracket_on_block": bracket_on_block,
}
STRUCTURE_FAMILIES: tuple[str, ...] = tuple(_FAMILIES)
"""Every structure family, in corpus order."""


# ---------------------------------------------------------------- assembly into part frames
def _bottom_centre(mesh: trimesh.Trimesh) -> np.ndarray:
    lo, hi = mesh.bounds
    return np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])


def _finish(build: FamilyBuild, name: str, family: str, rng: np.random.Generator) -> GeneratedStructure:
    """Put each part in its own frame (bounding-box bottom centre, z up), place markers, draw densities."""
    a = _clean(build.a, f"{name} A")
    b_asm = _clean(build.b, f"{name} B")
    o_a = _bottom_centre(a)
    T_Aframe_build = geometry.from_rotation(np.eye(3), -o_a)  # build frame -> A's part frame
    a.apply_transform(T_Aframe_build)
    R = build.R_A_B
    b = b_asm.copy()
    b.apply_transform(geometry.from_rotation(R.T))  # B's own axes
    o_b = _bottom_centre(b)
    b.apply_translation(-o_b)
    T_build_B = geometry.from_rotation(R, R @ o_b)  # B's part frame in the build frame
    T_A_B = T_Aframe_build @ T_build_B
    T_B_build = geometry.invert(T_build_B)
    layout_a, layout_b = pick_layout(rng, build.sites_a, build.sites_b)
    ids = [int(i) for i in rng.permutation(DICT_IDS)[: len(layout_a) + len(layout_b)]]
    markers_a = [
        MarkerSpec(dictionary=MARKER_DICTIONARY, id=ids[i], size=size, T_part_marker=T_Aframe_build @ marker_pose(site))
        for i, (site, size) in enumerate(layout_a)
    ]
    markers_b = [
        MarkerSpec(
            dictionary=MARKER_DICTIONARY,
            id=ids[len(layout_a) + i],
            size=size,
            T_part_marker=T_B_build @ marker_pose(site),
        )
        for i, (site, size) in enumerate(layout_b)
    ]
    v_a = np.asarray(build.v_a, float)
    # Retracting B along -v_a by more than this frees it: a plane normal to v_a then separates the parts.
    w = -v_a
    b_in_a = b.copy()
    b_in_a.apply_transform(T_A_B)
    depth = float(np.max(a.vertices @ w) - np.min(b_in_a.vertices @ w))
    # Hardwood (700 kg/m^3) or printed plastic (1100-1250): what a user's parts weigh.
    density = [700.0 if rng.random() < 0.5 else round(float(rng.uniform(1100, 1250)), 0) for _ in range(2)]
    return GeneratedStructure(
        name=name,
        family=family,
        part_a=a,
        part_b=b,
        name_a=build.name_a,
        name_b=build.name_b,
        T_A_B=T_A_B,
        v_a=v_a,
        clearance=build.clearance,
        play_axes=build.play_axes,
        insertion_depth=depth,
        markers_a=markers_a,
        markers_b=markers_b,
        density_a=density[0],
        density_b=density[1],
        description=build.description,
        params={k: (round(v, 3) if isinstance(v, float) else v) for k, v in build.params.items()},
    )


def generate_structure(family: str, seed: int = 0, index: int = 0) -> GeneratedStructure:
    """One structure of ``family``; ``seed`` and ``index`` draw its sizes, clearance, variant and markers."""
    if family not in _FAMILIES:
        raise ValueError(f"no structure family {family!r}; families: {', '.join(STRUCTURE_FAMILIES)}")
    # One stream per (seed, family, index): adding a family leaves every other structure as it was.
    rng = np.random.default_rng([seed, index, *family.encode()])
    build = _FAMILIES[family](rng)
    return _finish(build, f"gen_{family}_s{seed}_{index}", family, rng)


def structure_corpus(seed: int = 0, count: int = 10) -> list[GeneratedStructure]:
    """``count`` structures cycling over :data:`STRUCTURE_FAMILIES` (the k-th of a family has index k)."""
    n = len(STRUCTURE_FAMILIES)
    return [generate_structure(STRUCTURE_FAMILIES[i % n], seed, i // n) for i in range(count)]


# ---------------------------------------------------------------- checks
def marker_problems(gs: GeneratedStructure, tol: float = 5e-5) -> list[str]:
    """What is wrong with the markers of ``gs`` (empty: nothing), tested with rays on the assembled pair.

    For a 3 x 3 grid over each marker's quiet-zone square: the part's surface
    lies on the marker plane there (a ray down the normal from 0.5 mm above
    meets the part 0.5 mm away, ``tol`` metres), and a ray from the face out
    along the normal meets neither part (nothing covers it).
    """
    b_in_a = gs.part_b.copy()
    b_in_a.apply_transform(gs.T_A_B)
    both = trimesh.util.concatenate([gs.part_a, b_in_a])
    out: list[str] = []
    ids = [m.id for m in gs.markers_a + gs.markers_b]
    if len(ids) != len(set(ids)):
        out.append(f"marker ids repeat: {ids}")
    for role, markers, T, own in (("A", gs.markers_a, np.eye(4), gs.part_a), ("B", gs.markers_b, gs.T_A_B, b_in_a)):
        if not 1 <= len(markers) <= 4:
            out.append(f"{role} has {len(markers)} markers")
        for m in markers:
            M = T @ m.T_part_marker
            n = M[:3, 2]
            h = quiet_side(m.size) / 2 - 2e-4
            g = np.array([(u, v, 0.0) for u in (-h, 0, h) for v in (-h, 0, h)])
            pts = g @ M[:3, :3].T + M[:3, 3]
            down = own.ray.intersects_location(pts + 5e-4 * n, np.tile(-n, (len(pts), 1)), multiple_hits=False)
            loc, ray_idx = down[0], down[1]
            dist = np.full(len(pts), np.inf)
            if len(ray_idx):
                dist[ray_idx] = np.linalg.norm(np.reshape(loc, (-1, 3)) - (pts[ray_idx] + 5e-4 * n), axis=1)
            if np.any(np.abs(dist - 5e-4) > tol):
                out.append(f"marker {m.id} ({role}) is not flat on a face of the part")
            up = both.ray.intersects_any(pts + 2e-5 * n, np.tile(n, (len(pts), 1)))
            if np.any(up):
                out.append(f"marker {m.id} ({role}) is covered along its normal")
    return out
