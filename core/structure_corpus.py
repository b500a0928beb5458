"""Generated two-part structures, as a user's CAD would hand them to us: millimetre STL files and a structure YAML.

Issue 23: the ten hand-made structures of ``configs/parts/set1`` and ``set2``
are what the pipeline was tuned on; these families are not. Each family is a
function ``(rng) -> GeneratedStructure`` and every size, the clearance, the
hole kind and the marker layout are drawn from the seed:

====================  ==========================================================
``round_peg``         round peg with a head, in a blind or through hole
``square_peg``        square peg with a head, in a blind or through hole
``hex_peg``           hexagonal peg with a head, in a blind or through hole (a plate when A is thin)
``d_peg``             D-section peg (a flat) with a head
``keyed_peg``         round peg with a key along its side, in a keyed hole
``dovetail_slide``    dovetail slider pushed along a dovetail groove (v_a horizontal)
``t_slot_slide``      T slider pushed along a T-slot (v_a horizontal)
``side_pin``          headed pin pushed sideways into a hole in a block's face (v_a horizontal); the pin is
                      modelled standing on its head, so T_A_B holds a 90 deg rotation
``cap_on_post``       a cap with a bore lowered onto a post standing on a base
``bracket_on_block``  a U bracket lowered over a block
====================  ==========================================================

Units and frames: metres inside, millimetres only in the written STL files.
Each part's frame has its origin at the centre of its bounding box's bottom
face, z up as the part is modelled in its natural rest (the convention of the
hand-made sets). ``T_A_B`` is B's frame in A's frame, assembled: B rests on
its seat (a shoulder, a groove floor, an end stop, a post top), touching A
without interpenetrating it. ``v_a`` is the unit direction, in A's frame,
along which B moves *into* that pose. ``clearance`` is B's lateral play
along each of ``play_axes`` (A's frame) in the assembled pose, 0.2-1 mm.

Markers (``DICT_4X4_50``): 1-4 per part, each flat on an outer face that is
visible when assembled (not in a hole, not on a mating face, not under the
other part), its square plus a one-cell white quiet zone (the renderer's
default) and 1 mm inside the face's edges; ids unique across the structure;
at least one marker of A and one of B face within 90 deg of each other, so
one camera sees both parts' markers (the ArUco teacher's view choice needs that).

Graspability by the Nextage's parallel gripper (85 mm stroke,
:data:`asmteach.plugins.robots.nextage.build_urdf.GRIPPER`): every part's
narrower horizontal bounding-box side (x or y, as modelled) is at most 70 mm,
15 mm under the stroke; the assembled structure is 20-120 mm across.
"""

from __future__ import annotations

import argparse
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.corpus import _box, _clean, _cyl, _minus, _plus, _u, write_cad_stl
from asmteach.core.models import MarkerSpec

__all__ = [
    "MARKER_DICTIONARY",
    "STRUCTURE_FAMILIES",
    "GeneratedStructure",
    "add_make_structures_command",
    "generate_structure",
    "marker_problems",
    "render_structures",
    "structure_corpus",
    "write_run_config",
    "write_structure",
]

MARKER_DICTIONARY = "DICT_4X4_50"
_DICT_IDS = 50
_MARKER_CELLS = 6  # a 4x4 marker: 4 data cells and a one-cell black border on each side
_QUIET_CELLS = 1.0  # white margin the renderer draws around a marker (render.RenderObject.quiet_zone_cells)
_EDGE_MARGIN = 0.001  # m kept between a marker's quiet zone and the face's edge
_MARKER_MIN = 0.010  # m; smaller squares are too few pixels at the demonstration's 0.45 m
_MARKER_MAX = 0.035
_GRASP_WIDTH_MAX = 0.070  # m; the gripper opens 85 mm
_UP = np.array([0.0, 0.0, 1.0])


def _quiet_side(size: float) -> float:
    """Side of a marker's square with its quiet zone, metres."""
    return size * (1.0 + 2.0 * _QUIET_CELLS / _MARKER_CELLS)


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


# ---------------------------------------------------------------- marker sites
@dataclass(frozen=True)
class _Site:
    """A rectangle on a flat outer face, in the assembled frame (A's build frame), where a marker may go."""

    center: tuple[float, float, float]
    normal: tuple[float, float, float]
    half: tuple[float, float]  # half extents of the rectangle along its two in-plane axes, metres

    def max_marker(self) -> float:
        """Largest marker side (metres) whose quiet zone fits the rectangle with the edge margin."""
        room = 2.0 * (min(self.half) - _EDGE_MARGIN)
        return room / (1.0 + 2.0 * _QUIET_CELLS / _MARKER_CELLS)


def _face(axis: str, value: float, lo: tuple[float, float], hi: tuple[float, float]) -> _Site:
    """A rectangle on the plane ``<axis> = value`` with outward normal ``sign(axis)`` (metres).

    ``axis`` is one of ``+x -x +y -y +z -z``; ``lo``/``hi`` bound the other two
    coordinates in order (x, y, z without the normal's one).
    """
    k = "xyz".index(axis[1])
    normal = [0.0, 0.0, 0.0]
    normal[k] = 1.0 if axis[0] == "+" else -1.0
    centre = [0.0, 0.0, 0.0]
    centre[k] = value
    for j, i in enumerate(i for i in range(3) if i != k):
        centre[i] = 0.5 * (lo[j] + hi[j])
    return _Site(tuple(centre), tuple(normal), (0.5 * (hi[0] - lo[0]), 0.5 * (hi[1] - lo[1])))


def _marker_pose(site: _Site) -> np.ndarray:
    """Marker frame on a site: z out of the face; on a vertical face y up, on a horizontal one x along +x."""
    z = np.asarray(site.normal, float)
    if abs(z[2]) > 0.9:
        x = np.array([1.0, 0.0, 0.0])
        y = np.cross(z, x)
    else:
        y = _UP
        x = np.cross(y, z)
    return geometry.from_rotation(np.column_stack([x, y, z]), site.center)


def _pick_layout(rng: np.random.Generator, sites_a: list[_Site], sites_b: list[_Site]
                 ) -> tuple[list[tuple[_Site, float]], list[tuple[_Site, float]]]:
    """1-4 sites per part with a marker size each; one A marker and one B marker face within 90 deg."""
    usable_a = [s for s in sites_a if s.max_marker() >= _MARKER_MIN]
    usable_b = [s for s in sites_b if s.max_marker() >= _MARKER_MIN]
    if not usable_a or not usable_b:
        raise RuntimeError("a generated part has no face a marker fits")  # a generator defect
    # First a pair a camera sees together (normals within 90 deg), then the rest of each part's markers.
    pairs = [(i, j) for i, sa in enumerate(usable_a) for j, sb in enumerate(usable_b)
             if float(np.dot(sa.normal, sb.normal)) >= 0.0]
    if not pairs:
        raise RuntimeError("no face of B is seen together with a face of A")  # a generator defect
    first_a, first_b = pairs[int(rng.integers(len(pairs)))]

    def fill(usable: list[_Site], first: int) -> list[_Site]:
        n = min(int(rng.integers(1, 5)), len(usable))
        rest = [i for i in range(len(usable)) if i != first]
        more = [rest[k] for k in rng.choice(len(rest), size=n - 1, replace=False)] if n > 1 else []
        return [usable[i] for i in sorted([first, *more])]

    chosen_a, chosen_b = fill(usable_a, first_a), fill(usable_b, first_b)

    def sized(s: _Site) -> tuple[_Site, float]:
        hi = min(s.max_marker(), _MARKER_MAX)
        # Markers are cut from printed sheets: a size in whole half-millimetres.
        size = np.floor(float(rng.uniform(max(_MARKER_MIN, 0.6 * hi), hi)) * 2000.0) / 2000.0
        return s, float(max(size, _MARKER_MIN))

    return [sized(s) for s in chosen_a], [sized(s) for s in chosen_b]


# ---------------------------------------------------------------- shapes
def _section(kind: str, r: float, h: float, grow: float, at: tuple[float, float, float] = (0, 0, 0),
             key: float = 0.0, flat: float = 0.0) -> trimesh.Trimesh:
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


def _reach(kind: str, r: float) -> float:
    """Largest distance of a section's outline from its axis (metres)."""
    return {"round": r, "square": r * np.sqrt(2), "hex": r / np.cos(np.pi / 6), "d": r, "keyed": 1.4 * r}[kind]


def _prism_x(profile_yz: np.ndarray, x0: float, x1: float) -> trimesh.Trimesh:
    """A convex prism along x from ``x0`` to ``x1`` of a convex (y, z) profile (metres)."""
    pts = [(x, y, z) for x in (x0, x1) for y, z in profile_yz]
    return trimesh.convex.convex_hull(np.asarray(pts, float))


# ---------------------------------------------------------------- families
@dataclass
class _Build:
    """A family's raw output, in A's build frame with B in its assembled place."""

    a: trimesh.Trimesh
    b: trimesh.Trimesh
    v_a: tuple[float, float, float]
    clearance: float
    play_axes: tuple[tuple[float, float, float], ...]
    sites_a: list[_Site]
    sites_b: list[_Site]
    name_a: str
    name_b: str
    description: str
    params: dict[str, float | str]
    R_A_B: np.ndarray = field(default_factory=lambda: np.eye(3))  # B's own axes in A's frame


def _clearance(rng: np.random.Generator) -> float:
    # whole hundredths of a millimetre, as a drawing states a fit
    return round(float(rng.uniform(0.2, 1.0)), 2) * 1e-3


def _block_sites(ax: float, ay: float, az: float, *, sides: str = "+x-x+y-y", z0: float = 0.0) -> list[_Site]:
    """The vertical faces of a box centred on x = y = 0, from z = z0 to z0 + az (metres)."""
    out = []
    for s in ("+x", "-x", "+y", "-y"):
        if s not in sides:
            continue
        k = "xyz".index(s[1])
        value = (ax if k == 0 else ay) / 2 * (1 if s[0] == "+" else -1)
        w = ay if k == 0 else ax
        out.append(_face(s, value, (-w / 2, z0), (w / 2, z0 + az)))
    return out


def _peg(rng: np.random.Generator, kind: str) -> _Build:
    c = _clearance(rng)
    r = _u(rng, 5, 12)
    flat = r * float(rng.uniform(0.5, 0.75)) if kind == "d" else 0.0
    key = r * float(rng.uniform(0.5, 0.8)) if kind == "keyed" else 0.0
    reach = _reach(kind, r)
    side_min = 2 * reach + 2 * c + 16e-3  # 3 mm of wall at least and room for a head 4 mm inside the top face
    ax = max(side_min, _u(rng, 30, 90))
    ay = min(max(side_min, _u(rng, 25, 70)), _GRASP_WIDTH_MAX)
    az = _u(rng, 17, 50)  # its sides hold a 10 mm marker
    through = bool(rng.random() < 0.5)
    if through:
        length = az * float(rng.uniform(0.5, 0.9))  # the shank never reaches the table under A
        hole = _section(kind, r, 2 * az + 0.01, c, (0, 0, az / 2), key, flat)
    else:
        depth = min(az * float(rng.uniform(0.45, 0.85)), az - 3e-3)
        length = depth - 1e-3  # 1 mm under the shank's tip: the head's shoulder is the seat
        hole = _section(kind, r, 2 * depth, c, (0, 0, az), key, flat)
    a = _minus(_box((ax, ay, az), (0, 0, az / 2)), hole)
    head_w = _u(rng, max(2 * reach * 1e3 + 8, 20), min(ax, ay) * 1e3 - 4)  # B is 20 mm across at least
    head_h = _u(rng, 10, 28)
    round_head = kind in ("round", "hex") and bool(rng.random() < 0.4)
    shank = _section(kind, r, length, 0.0, (0, 0, az - length / 2), key, flat)
    if round_head:
        head = _cyl(head_w / 2, head_h, (0, 0, az + head_h / 2))
    else:
        head = _box((head_w, head_w, head_h), (0, 0, az + head_h / 2))
    b = _plus(shank, head)
    sites_a = _block_sites(ax, ay, az)
    fx = head_w / 2 + 2e-3  # top-face strips keep 2 mm off the head's footprint
    sites_a += [_face("+z", az, (fx, -ay / 2), (ax / 2, ay / 2)), _face("+z", az, (-ax / 2, -ay / 2), (-fx, ay / 2)),
                _face("+z", az, (-fx, fx), (fx, ay / 2)), _face("+z", az, (-fx, -ay / 2), (fx, -fx))]
    top = az + head_h
    sites_b = [_face("+z", top, (-head_w / 2, -head_w / 2), (head_w / 2, head_w / 2))]
    if round_head:
        # the inscribed square of the round top
        s = head_w / np.sqrt(2)
        sites_b = [_face("+z", top, (-s / 2, -s / 2), (s / 2, s / 2))]
    else:
        sites_b += _block_sites(head_w, head_w, head_h, z0=az)
    noun = {"round": "round", "square": "square", "hex": "hexagonal", "d": "D-section", "keyed": "keyed"}[kind]
    return _Build(
        # a hexagon's flats face +-y; across its corners (x) the play is c / cos 30 deg
        a, b, (0.0, 0.0, -1.0), c, ((0.0, 1.0, 0.0),) if kind == "hex" else ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
        sites_a, sites_b, f"{'through' if through else 'blind'}_holed_block", f"{kind}_peg",
        f"{noun} peg with a {'round' if round_head else 'square'} head in a {'through' if through else 'blind'} hole",
        {"r_mm": r * 1e3, "block_mm": f"{ax * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}", "shank_mm": length * 1e3,
         "head_mm": f"{head_w * 1e3:.1f}x{head_h * 1e3:.1f}", "hole": "through" if through else "blind"},
    )


def _round_peg(rng: np.random.Generator) -> _Build:
    return _peg(rng, "round")


def _square_peg(rng: np.random.Generator) -> _Build:
    return _peg(rng, "square")


def _hex_peg(rng: np.random.Generator) -> _Build:
    return _peg(rng, "hex")


def _d_peg(rng: np.random.Generator) -> _Build:
    return _peg(rng, "d")


def _keyed_peg(rng: np.random.Generator) -> _Build:
    return _peg(rng, "keyed")


def _slide_frame(rng: np.random.Generator, slot_w: float, slot_h: float) -> tuple[float, float, float, float, bool]:
    """A's length, width and height, the stop wall (0 for a through slot) and whether it is stopped (metres)."""
    la = _u(rng, 45, 100)
    wall = _u(rng, 6, 16)
    ay = min(slot_w + 2 * wall, _GRASP_WIDTH_MAX)
    az = max(slot_h + _u(rng, 5, 16), 17e-3)  # its sides hold a 10 mm marker
    stopped = bool(rng.random() < 0.5)
    stop = _u(rng, 5, 10) if stopped else 0.0
    return la, ay, az, stop, stopped


def _slide_sites(la: float, ay: float, az: float, mouth: float, stopped: bool) -> list[_Site]:
    sites = _block_sites(la, ay, az, sides="+y-y")
    if stopped:
        sites += _block_sites(la, ay, az, sides="-x")
    edge = mouth / 2 + 1e-3
    sites += [_face("+z", az, (-la / 2, edge), (la / 2, ay / 2)), _face("+z", az, (-la / 2, -ay / 2), (la / 2, -edge))]
    return sites


def _dovetail_slide(rng: np.random.Generator) -> _Build:
    c = _clearance(rng)
    d = _u(rng, 6, 14)  # groove depth
    alpha = np.radians(float(rng.uniform(15, 30)))  # flank angle from the vertical
    narrow = _u(rng, 12, 30)  # slider width at A's top face
    wide = narrow + 2 * d * np.tan(alpha)  # slider width at the groove floor
    la, ay, az, stop, stopped = _slide_frame(rng, wide + 2 * c, d)
    ay = max(ay, wide + 2 * c + 10e-3)
    floor = az - d
    # The groove is the slider's profile moved out by c on each side: B's sideways play is c.
    # The flanks run on 1 mm above A's top at the same slope, so the cut leaves no sliver there.
    top_half = narrow / 2 + c - 1e-3 * np.tan(alpha)
    groove = _prism_x(np.array([[-(wide / 2 + c), floor], [wide / 2 + c, floor], [top_half, az + 1e-3],
                                [-top_half, az + 1e-3]]), -la / 2 + stop, la / 2 + 1e-2)
    a = _minus(_box((la, ay, az), (0, 0, az / 2)), groove)
    lb = max(20e-3, (la - stop) * float(rng.uniform(0.45, 0.85)))
    x0 = -la / 2 + stop if stopped else -lb / 2  # stopped: B's front touches the stop wall
    neck_h = _u(rng, 16, 28)  # its sides above A hold a 10 mm marker
    body = _prism_x(np.array([[-wide / 2, floor], [wide / 2, floor], [narrow / 2, az], [-narrow / 2, az]]), x0, x0 + lb)
    neck = _box((lb, narrow, neck_h), (x0 + lb / 2, 0, az + neck_h / 2))
    b = _plus(body, neck)
    top = az + neck_h
    sites_b = [_face("+z", top, (x0, -narrow / 2), (x0 + lb, narrow / 2)),
               _face("+y", narrow / 2, (x0, az), (x0 + lb, top)), _face("-y", -narrow / 2, (x0, az), (x0 + lb, top)),
               _face("+x", x0 + lb, (-narrow / 2, az), (narrow / 2, top))]
    return _Build(
        a, b, (-1.0, 0.0, 0.0), c, ((0.0, 1.0, 0.0),), _slide_sites(la, ay, az, narrow + 2 * c, stopped), sites_b,
        f"dovetail_{'stopped' if stopped else 'through'}_block", "dovetail_slider",
        f"dovetail slider pushed along -x into a {'stopped' if stopped else 'through'} groove",
        {"groove_depth_mm": d * 1e3, "flank_deg": float(np.degrees(alpha)), "narrow_mm": narrow * 1e3,
         "block_mm": f"{la * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}", "slider_mm": lb * 1e3,
         "slot": "stopped" if stopped else "through"},
    )


def _t_slot_slide(rng: np.random.Generator) -> _Build:
    c = _clearance(rng)
    wf = _u(rng, 16, 36)  # flange width
    hf = _u(rng, 5, 10)  # flange height
    wr = max(8e-3, wf * float(rng.uniform(0.35, 0.6)))  # rib width
    lip = _u(rng, 4, 9)  # A's lip over the flange
    fl = max(_u(rng, 4, 12), 17e-3 - (hf + c + lip))  # A's floor; A's sides hold a 10 mm marker
    az = fl + hf + c + lip
    la = _u(rng, 45, 100)
    ay = min(wf + 2 * c + 2 * _u(rng, 6, 16), _GRASP_WIDTH_MAX)
    stopped = bool(rng.random() < 0.5)
    stop = _u(rng, 5, 10) if stopped else 0.0
    x_in, x_out = -la / 2 + stop, la / 2 + 1e-2
    lower = _box((x_out - x_in, wf + 2 * c, hf + c), ((x_in + x_out) / 2, 0, fl + (hf + c) / 2))
    upper = _box((x_out - x_in, wr + 2 * c, lip + 2e-3), ((x_in + x_out) / 2, 0, fl + hf + c + (lip + 2e-3) / 2))
    a = _minus(_box((la, ay, az), (0, 0, az / 2)), lower, upper)
    lb = max(20e-3, (la - stop) * float(rng.uniform(0.45, 0.85)))
    x0 = -la / 2 + stop if stopped else -lb / 2
    rib_h = _u(rng, 16, 28)  # its sides above A hold a 10 mm marker
    top = az + rib_h
    flange = _box((lb, wf, hf), (x0 + lb / 2, 0, fl + hf / 2))
    rib = _box((lb, wr, top - (fl + hf)), (x0 + lb / 2, 0, (fl + hf + top) / 2))
    b = _plus(flange, rib)
    sites_b = [_face("+z", top, (x0, -wr / 2), (x0 + lb, wr / 2)),
               _face("+y", wr / 2, (x0, az), (x0 + lb, top)), _face("-y", -wr / 2, (x0, az), (x0 + lb, top)),
               _face("+x", x0 + lb, (-wr / 2, az), (wr / 2, top))]
    return _Build(
        a, b, (-1.0, 0.0, 0.0), c, ((0.0, 1.0, 0.0),), _slide_sites(la, ay, az, wr + 2 * c, stopped), sites_b,
        f"t_slot_{'stopped' if stopped else 'through'}_block", "t_slider",
        f"T slider pushed along -x into a {'stopped' if stopped else 'through'} T-slot",
        {"flange_mm": f"{wf * 1e3:.1f}x{hf * 1e3:.1f}", "rib_mm": wr * 1e3, "lip_mm": lip * 1e3,
         "block_mm": f"{la * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}", "slider_mm": lb * 1e3,
         "slot": "stopped" if stopped else "through"},
    )


def _side_pin(rng: np.random.Generator) -> _Build:
    c = _clearance(rng)
    kind = "round" if rng.random() < 0.6 else "square"
    r = _u(rng, 4, 10)
    reach = _reach(kind, r)
    ax = _u(rng, 30, 70)
    ay = min(max(_u(rng, 25, 70), 2 * reach + 20e-3), _GRASP_WIDTH_MAX)
    az = max(_u(rng, 25, 70), 2 * reach + 20e-3)
    zh = az / 2
    depth = ax * float(rng.uniform(0.4, 0.75))
    length = depth - 1e-3  # the head against A's face is the seat
    hole = _section(kind, r, 2 * depth, c, (0, 0, 0))
    hole.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    hole.apply_translation((ax / 2, 0, zh))
    a = _minus(_box((ax, ay, az), (0, 0, az / 2)), hole)
    head_t = _u(rng, 8, 20)
    # within A's height, so the head's bottom stays off the table A stands on
    head_w = _u(rng, max(2 * reach * 1e3 + 8, 20), min(ay, az, 0.05) * 1e3)
    shank = _section(kind, r, length, 0.0, (0, 0, 0))
    shank.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    shank.apply_translation((ax / 2 - length / 2, 0, zh))
    head = _box((head_t, head_w, head_w), (ax / 2 + head_t / 2, 0, zh))
    b = _plus(shank, head)
    sites_a = [*_block_sites(ax, ay, az, sides="-x+y-y"), _face("+z", az, (-ax / 2, -ay / 2), (ax / 2, ay / 2))]
    x1 = ax / 2 + head_t
    lo, hi = zh - head_w / 2, zh + head_w / 2
    sites_b = [_face("+x", x1, (-head_w / 2, lo), (head_w / 2, hi)),
               _face("+z", hi, (ax / 2, -head_w / 2), (x1, head_w / 2)),
               _face("+y", head_w / 2, (ax / 2, lo), (x1, hi)), _face("-y", -head_w / 2, (ax / 2, lo), (x1, hi))]
    # The pin is modelled standing on its head, shank up: B's +z is A's -x (the insertion direction).
    R = geometry.from_rpy(0.0, -np.pi / 2, 0.0)[:3, :3]
    return _Build(
        a, b, (-1.0, 0.0, 0.0), c, ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), sites_a, sites_b, "side_holed_block",
        f"{kind}_side_pin", f"headed {kind} pin pushed sideways (-x) into a hole in a block's face",
        {"r_mm": r * 1e3, "block_mm": f"{ax * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}", "shank_mm": length * 1e3,
         "head_mm": f"{head_t * 1e3:.1f}x{head_w * 1e3:.1f}", "pin": kind},
        R_A_B=R,
    )


def _cap_on_post(rng: np.random.Generator) -> _Build:
    c = _clearance(rng)
    kind = "round" if rng.random() < 0.6 else "square"
    r = _u(rng, 6, 14)
    reach = _reach(kind, r)
    wall = _u(rng, 4, 10)
    ro = reach + c + wall  # the cap's outer half size
    bx = max(_u(rng, 30, 90), 2 * ro + 10e-3)
    by = min(max(_u(rng, 30, 70), 2 * ro + 10e-3), _GRASP_WIDTH_MAX)
    bz = _u(rng, 17, 28)  # the base's sides hold a 10 mm marker
    ph = _u(rng, 15, 35)
    a = _plus(_box((bx, by, bz), (0, 0, bz / 2)), _section(kind, r, ph, 0.0, (0, 0, bz + ph / 2)))
    gap = _u(rng, 2, 6)  # between the cap's rim and the base: the post's top is the seat
    bore = ph - gap
    roof = _u(rng, 4, 12)
    z0, z1 = bz + gap, bz + ph + roof
    box_cap = kind == "square" or bool(rng.random() < 0.5)
    mid = (0.0, 0.0, (z0 + z1) / 2)
    outer = _box((2 * ro, 2 * ro, z1 - z0), mid) if box_cap else _cyl(ro, z1 - z0, mid)
    b = _minus(outer, _section(kind, r, 2 * bore, c, (0, 0, z0)))
    sites_a = _block_sites(bx, by, bz)
    fx = ro + 2e-3
    sites_a += [_face("+z", bz, (fx, -by / 2), (bx / 2, by / 2)), _face("+z", bz, (-bx / 2, -by / 2), (-fx, by / 2))]
    s = ro if box_cap else ro / np.sqrt(2)
    sites_b = [_face("+z", z1, (-s, -s), (s, s))]
    if box_cap:
        sites_b += _block_sites(2 * ro, 2 * ro, z1 - z0, z0=z0)
    return _Build(
        a, b, (0.0, 0.0, -1.0), c, ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)), sites_a, sites_b, f"{kind}_post_on_base",
        f"{'box' if box_cap else 'round'}_cap", f"{'box' if box_cap else 'round'} cap lowered onto a {kind} post",
        {"post_r_mm": r * 1e3, "post_h_mm": ph * 1e3, "base_mm": f"{bx * 1e3:.1f}x{by * 1e3:.1f}x{bz * 1e3:.1f}",
         "cap_mm": f"{2 * ro * 1e3:.1f}x{(z1 - z0) * 1e3:.1f}", "post": kind},
    )


def _bracket_on_block(rng: np.random.Generator) -> _Build:
    c = _clearance(rng)
    ax = _u(rng, 40, 90)
    ay = _u(rng, 20, 48)
    az = _u(rng, 24, 50)
    t = _u(rng, 3, 8)
    legs = az * float(rng.uniform(0.35, 0.7))  # the legs stop short of the table
    bl = ax * float(rng.uniform(0.4, 0.75))
    wy = ay + 2 * c + 2 * t
    a = _box((ax, ay, az), (0, 0, az / 2))
    outer = _box((bl, wy, legs + t), (0, 0, az - legs + (legs + t) / 2))
    inner = _box((bl + 2e-2, ay + 2 * c, 2 * legs), (0, 0, az - legs))
    b = _minus(outer, inner)
    top = az + t
    lo = az - legs
    sites_a = _block_sites(ax, ay, az, sides="+x-x")
    fx = bl / 2 + 2e-3
    sites_a += [_face("+z", az, (fx, -ay / 2), (ax / 2, ay / 2)), _face("+z", az, (-ax / 2, -ay / 2), (-fx, ay / 2)),
                _face("+y", ay / 2, (-ax / 2, 0.0), (ax / 2, lo - 2e-3)),
                _face("-y", -ay / 2, (-ax / 2, 0.0), (ax / 2, lo - 2e-3))]
    sites_b = [_face("+z", top, (-bl / 2, -wy / 2), (bl / 2, wy / 2)),
               _face("+y", wy / 2, (-bl / 2, lo), (bl / 2, top)), _face("-y", -wy / 2, (-bl / 2, lo), (bl / 2, top))]
    return _Build(
        a, b, (0.0, 0.0, -1.0), c, ((0.0, 1.0, 0.0),), sites_a, sites_b, "block", "u_bracket",
        "U bracket lowered over a block (its legs either side)",
        {"block_mm": f"{ax * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}", "bracket_mm": f"{bl * 1e3:.1f}x{wy * 1e3:.1f}",
         "legs_mm": legs * 1e3, "thickness_mm": t * 1e3},
    )


_FAMILIES: dict[str, Callable[[np.random.Generator], _Build]] = {
    "round_peg": _round_peg,
    "square_peg": _square_peg,
    "hex_peg": _hex_peg,
    "d_peg": _d_peg,
    "keyed_peg": _keyed_peg,
    "dovetail_slide": _dovetail_slide,
    "t_slot_slide": _t_slot_slide,
    "side_pin": _side_pin,
    "cap_on_post": _cap_on_post,
    "bracket_on_block": _bracket_on_block,
}
STRUCTURE_FAMILIES: tuple[str, ...] = tuple(_FAMILIES)
"""Every structure family, in corpus order."""


# ---------------------------------------------------------------- assembly into part frames
def _bottom_centre(mesh: trimesh.Trimesh) -> np.ndarray:
    lo, hi = mesh.bounds
    return np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])


def _finish(build: _Build, name: str, family: str, rng: np.random.Generator) -> GeneratedStructure:
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
    layout_a, layout_b = _pick_layout(rng, build.sites_a, build.sites_b)
    ids = [int(i) for i in rng.permutation(_DICT_IDS)[: len(layout_a) + len(layout_b)]]
    markers_a = [MarkerSpec(dictionary=MARKER_DICTIONARY, id=ids[i], size=size,
                            T_part_marker=T_Aframe_build @ _marker_pose(site))
                 for i, (site, size) in enumerate(layout_a)]
    markers_b = [MarkerSpec(dictionary=MARKER_DICTIONARY, id=ids[len(layout_a) + i], size=size,
                            T_part_marker=T_B_build @ _marker_pose(site))
                 for i, (site, size) in enumerate(layout_b)]
    v_a = np.asarray(build.v_a, float)
    # Retracting B along -v_a by more than this frees it: a plane normal to v_a then separates the parts.
    w = -v_a
    b_in_a = b.copy()
    b_in_a.apply_transform(T_A_B)
    depth = float(np.max(a.vertices @ w) - np.min(b_in_a.vertices @ w))
    # Hardwood (700 kg/m^3) or printed plastic (1100-1250): what a user's parts weigh.
    density = [700.0 if rng.random() < 0.5 else round(float(rng.uniform(1100, 1250)), 0) for _ in range(2)]
    return GeneratedStructure(
        name=name, family=family, part_a=a, part_b=b, name_a=build.name_a, name_b=build.name_b, T_A_B=T_A_B,
        v_a=v_a, clearance=build.clearance, play_axes=build.play_axes, insertion_depth=depth,
        markers_a=markers_a, markers_b=markers_b, density_a=density[0], density_b=density[1],
        description=build.description, params={k: (round(v, 3) if isinstance(v, float) else v)
                                               for k, v in build.params.items()},
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
            h = _quiet_side(m.size) / 2 - 2e-4
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


# ---------------------------------------------------------------- files
def _pose_yaml(T: np.ndarray) -> str:
    """``{xyz: [m], rpy_deg: [deg]}`` to 10 nm and 1e-6 deg (``+ 0.0`` writes -0 as 0)."""
    xyz = [round(float(v), 8) + 0.0 for v in T[:3, 3]]
    with warnings.catch_warnings():
        # A pin turned on its side has pitch -90 deg: scipy warns of gimbal lock, the rotation is still exact.
        warnings.simplefilter("ignore", UserWarning)
        rpy = [round(float(np.degrees(v)), 6) + 0.0 for v in geometry.rpy(T)]
    return f"{{xyz: [{', '.join(f'{v:.9g}' for v in xyz)}], rpy_deg: [{', '.join(f'{v:.9g}' for v in rpy)}]}}"


def _part_yaml(name: str, mesh_file: str, density: float, color: tuple[float, float, float],
               markers: list[MarkerSpec]) -> list[str]:
    lines = [f"  name: {name}", f"  mesh: {mesh_file}", "  mesh_units: mm", f"  density: {density:g}",
             f"  color: [{', '.join(f'{v:g}' for v in color)}]", "  markers:"]
    for m in markers:
        lines.append(f"    - {{dictionary: {m.dictionary}, id: {m.id}, size: {m.size:.4g}, "
                     f"T_part_marker: {_pose_yaml(m.T_part_marker)}}}")
    return lines


def _open_faces(mesh: trimesh.Trimesh) -> int:
    """Triangles left out of a part's STL: 3 on a fine mesh, 1 on a coarse one.

    A box-like part is a few dozen triangles; two adjacent ones missing are a
    quarter of a face, which :func:`asmteach.core.mesh_repair.repair_mesh`
    refuses to guess (issue 23 finding). One missing triangle comes back exactly.
    """
    return 3 if len(mesh.faces) >= 200 else 1


def write_structure(gs: GeneratedStructure, folder: str | Path) -> Path:
    """Write ``A.stl`` and ``B.stl`` (millimetres, 1-3 open triangles as CAD exports have) and ``structure.yaml``.

    The YAML names the meshes by relative path with ``mesh_units: mm``;
    ``T_A_B`` is written as xyz (metres) and rpy_deg, ``v_a`` in A's frame.
    Returns the structure file's path. The same structure writes the same bytes.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    # The dropped faces are drawn from the structure's name, so a structure always writes the same files.
    face_seed = int.from_bytes(gs.name.encode()[-8:].rjust(8, b"\0"), "little") % (2**32)
    for k, (mesh, file) in enumerate(((gs.part_a, "A.stl"), (gs.part_b, "B.stl"))):
        write_cad_stl(mesh, out / file, open_faces=_open_faces(mesh), seed=face_seed + k)
    p = gs.params
    lines = [
        f"# Generated by asmteach.core.structure_corpus ({gs.family}): {gs.description}.",
        f"# Clearance {gs.clearance * 1e3:.2f} mm (B's sideways play); B travels {gs.insertion_depth * 1e3:.1f} mm "
        "along v_a into A.",
        f"# Sizes (mm): {', '.join(f'{k}={v}' for k, v in p.items())}",
        "# Part frames: origin at the centre of the part's bounding box bottom face, z up. Meshes in millimetres.",
        f"name: {gs.name}",
        "part_a:",
        *_part_yaml(gs.name_a, "A.stl", gs.density_a, (0.80, 0.62, 0.40), gs.markers_a),
        "part_b:",
        *_part_yaml(gs.name_b, "B.stl", gs.density_b, (0.45, 0.60, 0.80), gs.markers_b),
        f"T_A_B: {_pose_yaml(gs.T_A_B)}",
        f"v_a: [{', '.join(f'{float(v):g}' for v in gs.v_a)}]",
        "",
    ]
    path = out / "structure.yaml"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path


_RUN_CONFIG = """\
# Run config for a generated structure ({family}); as configs/demo.yaml, with the structure next to this file.
# Run: asmteach run {folder}/run.yaml --out <folder>
name: {name}
seed: {seed}
structure: structure.yaml
teacher:
  plugin: aruco
detector:
  plugin: cvfh_icp
corrector:
  plugin: stable_placements
grasp_planner:
  plugin: antipodal
motion_planner:
  plugin: trrt
assembly_planner:
  plugin: regrasp
robot:
  plugin: nextage_pybullet
  settings:
    ik: {{max_starts: 4}}
    start_tolerance: 0.06
execution:
  animation: false
"""


def write_run_config(gs: GeneratedStructure, folder: str | Path, seed: int = 7) -> Path:
    """Write ``run.yaml`` next to ``structure.yaml``: the demo's plugins, the given run seed, no animation."""
    out = Path(folder)
    path = out / "run.yaml"
    path.write_text(_RUN_CONFIG.format(family=gs.family, folder=out.name, name=gs.name, seed=seed),
                    encoding="utf-8")
    return path


# ---------------------------------------------------------------- picture
def render_structures(structures: list[GeneratedStructure], out_png: str | Path, *, columns: int = 5,
                      colors: int = 96) -> Path:
    """A contact sheet: each structure with B pulled back along ``-v_a`` out of A (an exploded view, millimetres).

    A is wood-coloured, B blue, markers dark squares; the red arrow is ``v_a``
    ending where B's origin sits when assembled. Saved as a palette PNG of
    ``colors`` colours (a few hundred kB less than full colour).
    """
    import math

    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from PIL import Image

    from asmteach.core.library import part_polygons

    rows = math.ceil(len(structures) / columns)
    fig = plt.figure(figsize=(3.2 * columns, 3.3 * rows), dpi=100)
    for i, gs in enumerate(structures):
        ax = fig.add_subplot(rows, columns, i + 1, projection="3d")
        T_out = gs.T_A_B.copy()
        T_out[:3, 3] -= (gs.insertion_depth + 0.010) * gs.v_a  # 10 mm clear of A
        va, ca = part_polygons(gs.part_a, np.eye(4), (0.85, 0.66, 0.42), gs.markers_a)
        vb, cb = part_polygons(gs.part_b, T_out, (0.45, 0.62, 0.90), gs.markers_b)
        ax.add_collection3d(Poly3DCollection(va + vb, facecolors=ca + cb, edgecolors=ca + cb, linewidths=0.2))
        tip = gs.T_A_B[:3, 3] * 1000.0
        tail = tip - gs.v_a * 30.0
        ax.quiver(*tail, *(tip - tail), color="crimson", arrow_length_ratio=0.25, linewidth=1.5)
        pts = np.vstack([np.vstack(va), np.vstack(vb)])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        mid, half = (lo + hi) / 2.0, (hi - lo).max() / 2.0 + 3.0
        ax.set_xlim(mid[0] - half, mid[0] + half)
        ax.set_ylim(mid[1] - half, mid[1] + half)
        ax.set_zlim(mid[2] - half, mid[2] + half)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=28, azim=-55)
        variant = next((str(gs.params[k]) for k in ("hole", "slot", "pin", "post") if k in gs.params), "")
        ax.set_title(f"{gs.family}: c = {gs.clearance * 1e3:.2f} mm\n"
                     f"{len(gs.markers_a)}+{len(gs.markers_b)} markers {variant}", fontsize=8)
        ax.tick_params(labelsize=5)
    fig.suptitle("generated structures (B pulled out along -v_a): A wood, B blue, markers black, v_a red (mm)")
    fig.tight_layout()
    out = Path(out_png)
    tmp = out.with_suffix(".full.png")
    fig.savefig(tmp, format="png")
    plt.close(fig)
    with Image.open(tmp) as im:
        im.convert("RGB").quantize(colors=colors, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
    tmp.unlink()
    return out


# ---------------------------------------------------------------- command
def _cmd_make_structures(args: argparse.Namespace) -> int:
    out = Path(args.out)
    for gs in structure_corpus(args.seed, args.count):
        folder = out / gs.name
        write_structure(gs, folder)
        write_run_config(gs, folder, seed=args.run_seed)
        print(f"{folder}: {gs.description}; clearance {gs.clearance * 1e3:.2f} mm, "
              f"{len(gs.markers_a)}+{len(gs.markers_b)} markers")
    return 0


def add_make_structures_command(sub: argparse._SubParsersAction) -> None:
    """Register ``asmteach make-structures OUT --seed N --count K``."""
    p = sub.add_parser("make-structures",
                       help="write generated two-part structures (mm STL + structure.yaml + run.yaml) to a folder")
    p.add_argument("out", help="folder; one sub-folder per structure")
    p.add_argument("--seed", type=int, default=0, help="draws every structure's sizes, clearance and markers")
    p.add_argument("--count", type=int, default=10, help="structures, cycling over the families")
    p.add_argument("--run-seed", type=int, default=7, help="the seed written in each run.yaml")
    p.set_defaults(func=_cmd_make_structures)
