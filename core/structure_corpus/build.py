"""What the structure families build with: peg sections, prisms, block faces, and a family's raw output."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh

from asmteach.core.corpus import _box, _cyl, _minus, _plus
from asmteach.core.structure_corpus.markers import MarkerSite, face_site

GRASP_WIDTH_MAX = 0.070  # m; the gripper opens 85 mm


# ---------------------------------------------------------------- shapes
def section(
    kind: str,
    r: float,
    h: float,
    grow: float,
    at: tuple[float, float, float] = (0, 0, 0),
    key: float = 0.0,
    flat: float = 0.0,
) -> trimesh.Trimesh:
    """A prism along z (height ``h``, centred at ``at``) of a peg section, grown outward by ``grow`` (a hole).

    ``r`` is the section's half size: radius (round, D, keyed), half side
    (square), apothem (hex). ``flat``: the D's flat distance from the axis
    (along +x). ``key``: the key's width (along y); it reaches ``1.4 r`` along +x.
    A hole is the section grown by the clearance, so every gap is ``grow``
    (metres) across the flats, sides and round parts.
    """
    if kind == "round":
        m = _cyl(r + grow, h)
    elif kind == "square":
        m = _box((2 * (r + grow), 2 * (r + grow), h))
    elif kind == "hex":
        # trimesh's 6-gon puts a vertex on +x: its flats face +-y, +-30 deg off x.
        m = _cyl((r + grow) / np.cos(np.pi / 6), h, sections=6)
    elif kind == "d":
        m = _minus(_cyl(r + grow, h), _box((2 * r, 4 * r, 2 * h), (flat + grow + r, 0, 0)))
    elif kind == "keyed":
        reach = 1.4 * r
        m = _plus(_cyl(r + grow, h), _box((reach + grow, key + 2 * grow, h), (0.5 * (reach + grow), 0, 0)))
    else:  # pragma: no cover - the families name only these
        raise ValueError(kind)
    m.apply_translation(at)
    return m


def section_reach(kind: str, r: float) -> float:
    """Largest distance of a section's outline from its axis (metres)."""
    return {"round": r, "square": r * np.sqrt(2), "hex": r / np.cos(np.pi / 6), "d": r, "keyed": 1.4 * r}[kind]


def prism_x(profile_yz: np.ndarray, x0: float, x1: float) -> trimesh.Trimesh:
    """A convex prism along x from ``x0`` to ``x1`` of a convex (y, z) profile (metres)."""
    pts = [(x, y, z) for x in (x0, x1) for y, z in profile_yz]
    return trimesh.convex.convex_hull(np.asarray(pts, float))


# ---------------------------------------------------------------- families
@dataclass
class FamilyBuild:
    """A family's raw output, in A's build frame with B in its assembled place."""

    a: trimesh.Trimesh
    b: trimesh.Trimesh
    v_a: tuple[float, float, float]
    clearance: float
    play_axes: tuple[tuple[float, float, float], ...]
    sites_a: list[MarkerSite]
    sites_b: list[MarkerSite]
    name_a: str
    name_b: str
    description: str
    params: dict[str, float | str]
    R_A_B: np.ndarray = field(default_factory=lambda: np.eye(3))  # B's own axes in A's frame


def draw_clearance(rng: np.random.Generator) -> float:
    # whole hundredths of a millimetre, as a drawing states a fit
    return round(float(rng.uniform(0.2, 1.0)), 2) * 1e-3


def block_sites(ax: float, ay: float, az: float, *, sides: str = "+x-x+y-y", z0: float = 0.0) -> list[MarkerSite]:
    """The vertical faces of a box centred on x = y = 0, from z = z0 to z0 + az (metres)."""
    out = []
    for s in ("+x", "-x", "+y", "-y"):
        if s not in sides:
            continue
        k = "xyz".index(s[1])
        value = (ax if k == 0 else ay) / 2 * (1 if s[0] == "+" else -1)
        w = ay if k == 0 else ax
        out.append(face_site(s, value, (-w / 2, z0), (w / 2, z0 + az)))
    return out
