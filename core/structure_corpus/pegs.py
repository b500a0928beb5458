"""The peg families: round, square, hexagonal, D-section and keyed pegs with a head, in a blind or through hole."""

from __future__ import annotations

import numpy as np

from asmteach.core.corpus import _box, _cyl, _minus, _plus, _u
from asmteach.core.structure_corpus.build import (
    GRASP_WIDTH_MAX,
    FamilyBuild,
    block_sites,
    draw_clearance,
    section,
    section_reach,
)
from asmteach.core.structure_corpus.markers import face_site


def _peg(rng: np.random.Generator, kind: str) -> FamilyBuild:
    c = draw_clearance(rng)
    r = _u(rng, 5, 12)
    flat = r * float(rng.uniform(0.5, 0.75)) if kind == "d" else 0.0
    key = r * float(rng.uniform(0.5, 0.8)) if kind == "keyed" else 0.0
    reach = section_reach(kind, r)
    side_min = 2 * reach + 2 * c + 16e-3  # 3 mm of wall at least and room for a head 4 mm inside the top face
    ax = max(side_min, _u(rng, 30, 90))
    ay = min(max(side_min, _u(rng, 25, 70)), GRASP_WIDTH_MAX)
    az = _u(rng, 17, 50)  # its sides hold a 10 mm marker
    through = bool(rng.random() < 0.5)
    if through:
        length = az * float(rng.uniform(0.5, 0.9))  # the shank never reaches the table under A
        hole = section(kind, r, 2 * az + 0.01, c, (0, 0, az / 2), key, flat)
    else:
        depth = min(az * float(rng.uniform(0.45, 0.85)), az - 3e-3)
        length = depth - 1e-3  # 1 mm under the shank's tip: the head's shoulder is the seat
        hole = section(kind, r, 2 * depth, c, (0, 0, az), key, flat)
    a = _minus(_box((ax, ay, az), (0, 0, az / 2)), hole)
    head_w = _u(rng, max(2 * reach * 1e3 + 8, 20), min(ax, ay) * 1e3 - 4)  # B is 20 mm across at least
    head_h = _u(rng, 10, 28)
    round_head = kind in ("round", "hex") and bool(rng.random() < 0.4)
    shank = section(kind, r, length, 0.0, (0, 0, az - length / 2), key, flat)
    if round_head:
        head = _cyl(head_w / 2, head_h, (0, 0, az + head_h / 2))
    else:
        head = _box((head_w, head_w, head_h), (0, 0, az + head_h / 2))
    b = _plus(shank, head)
    sites_a = block_sites(ax, ay, az)
    fx = head_w / 2 + 2e-3  # top-face strips keep 2 mm off the head's footprint
    sites_a += [
        face_site("+z", az, (fx, -ay / 2), (ax / 2, ay / 2)),
        face_site("+z", az, (-ax / 2, -ay / 2), (-fx, ay / 2)),
        face_site("+z", az, (-fx, fx), (fx, ay / 2)),
        face_site("+z", az, (-fx, -ay / 2), (fx, -fx)),
    ]
    top = az + head_h
    sites_b = [face_site("+z", top, (-head_w / 2, -head_w / 2), (head_w / 2, head_w / 2))]
    if round_head:
        # the inscribed square of the round top
        s = head_w / np.sqrt(2)
        sites_b = [face_site("+z", top, (-s / 2, -s / 2), (s / 2, s / 2))]
    else:
        sites_b += block_sites(head_w, head_w, head_h, z0=az)
    noun = {"round": "round", "square": "square", "hex": "hexagonal", "d": "D-section", "keyed": "keyed"}[kind]
    return FamilyBuild(
        # a hexagon's flats face +-y; across its corners (x) the play is c / cos 30 deg
        a,
        b,
        (0.0, 0.0, -1.0),
        c,
        ((0.0, 1.0, 0.0),) if kind == "hex" else ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
        sites_a,
        sites_b,
        f"{'through' if through else 'blind'}_holed_block",
        f"{kind}_peg",
        f"{noun} peg with a {'round' if round_head else 'square'} head in a {'through' if through else 'blind'} hole",
        {
            "r_mm": r * 1e3,
            "block_mm": f"{ax * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}",
            "shank_mm": length * 1e3,
            "head_mm": f"{head_w * 1e3:.1f}x{head_h * 1e3:.1f}",
            "hole": "through" if through else "blind",
        },
    )


def round_peg(rng: np.random.Generator) -> FamilyBuild:
    return _peg(rng, "round")


def square_peg(rng: np.random.Generator) -> FamilyBuild:
    return _peg(rng, "square")


def hex_peg(rng: np.random.Generator) -> FamilyBuild:
    return _peg(rng, "hex")


def d_peg(rng: np.random.Generator) -> FamilyBuild:
    return _peg(rng, "d")


def keyed_peg(rng: np.random.Generator) -> FamilyBuild:
    return _peg(rng, "keyed")
