"""Three families: a headed pin pushed sideways into a block, a cap lowered onto a post, a U bracket over a block."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
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


def side_pin(rng: np.random.Generator) -> FamilyBuild:
    c = draw_clearance(rng)
    kind = "round" if rng.random() < 0.6 else "square"
    r = _u(rng, 4, 10)
    reach = section_reach(kind, r)
    ax = _u(rng, 30, 70)
    ay = min(max(_u(rng, 25, 70), 2 * reach + 20e-3), GRASP_WIDTH_MAX)
    az = max(_u(rng, 25, 70), 2 * reach + 20e-3)
    zh = az / 2
    depth = ax * float(rng.uniform(0.4, 0.75))
    length = depth - 1e-3  # the head against A's face is the seat
    hole = section(kind, r, 2 * depth, c, (0, 0, 0))
    hole.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    hole.apply_translation((ax / 2, 0, zh))
    a = _minus(_box((ax, ay, az), (0, 0, az / 2)), hole)
    head_t = _u(rng, 8, 20)
    # within A's height, so the head's bottom stays off the table A stands on
    head_w = _u(rng, max(2 * reach * 1e3 + 8, 20), min(ay, az, 0.05) * 1e3)
    shank = section(kind, r, length, 0.0, (0, 0, 0))
    shank.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    shank.apply_translation((ax / 2 - length / 2, 0, zh))
    head = _box((head_t, head_w, head_w), (ax / 2 + head_t / 2, 0, zh))
    b = _plus(shank, head)
    sites_a = [*block_sites(ax, ay, az, sides="-x+y-y"), face_site("+z", az, (-ax / 2, -ay / 2), (ax / 2, ay / 2))]
    x1 = ax / 2 + head_t
    lo, hi = zh - head_w / 2, zh + head_w / 2
    sites_b = [
        face_site("+x", x1, (-head_w / 2, lo), (head_w / 2, hi)),
        face_site("+z", hi, (ax / 2, -head_w / 2), (x1, head_w / 2)),
        face_site("+y", head_w / 2, (ax / 2, lo), (x1, hi)),
        face_site("-y", -head_w / 2, (ax / 2, lo), (x1, hi)),
    ]
    # The pin is modelled standing on its head, shank up: B's +z is A's -x (the insertion direction).
    R = geometry.from_rpy(0.0, -np.pi / 2, 0.0)[:3, :3]
    return FamilyBuild(
        a,
        b,
        (-1.0, 0.0, 0.0),
        c,
        ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
        sites_a,
        sites_b,
        "side_holed_block",
        f"{kind}_side_pin",
        f"headed {kind} pin pushed sideways (-x) into a hole in a block's face",
        {
            "r_mm": r * 1e3,
            "block_mm": f"{ax * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}",
            "shank_mm": length * 1e3,
            "head_mm": f"{head_t * 1e3:.1f}x{head_w * 1e3:.1f}",
            "pin": kind,
        },
        R_A_B=R,
    )


def cap_on_post(rng: np.random.Generator) -> FamilyBuild:
    c = draw_clearance(rng)
    kind = "round" if rng.random() < 0.6 else "square"
    r = _u(rng, 6, 14)
    reach = section_reach(kind, r)
    wall = _u(rng, 4, 10)
    ro = reach + c + wall  # the cap's outer half size
    bx = max(_u(rng, 30, 90), 2 * ro + 10e-3)
    by = min(max(_u(rng, 30, 70), 2 * ro + 10e-3), GRASP_WIDTH_MAX)
    bz = _u(rng, 17, 28)  # the base's sides hold a 10 mm marker
    ph = _u(rng, 15, 35)
    a = _plus(_box((bx, by, bz), (0, 0, bz / 2)), section(kind, r, ph, 0.0, (0, 0, bz + ph / 2)))
    gap = _u(rng, 2, 6)  # between the cap's rim and the base: the post's top is the seat
    bore = ph - gap
    roof = _u(rng, 4, 12)
    z0, z1 = bz + gap, bz + ph + roof
    box_cap = kind == "square" or bool(rng.random() < 0.5)
    mid = (0.0, 0.0, (z0 + z1) / 2)
    outer = _box((2 * ro, 2 * ro, z1 - z0), mid) if box_cap else _cyl(ro, z1 - z0, mid)
    b = _minus(outer, section(kind, r, 2 * bore, c, (0, 0, z0)))
    sites_a = block_sites(bx, by, bz)
    fx = ro + 2e-3
    sites_a += [
        face_site("+z", bz, (fx, -by / 2), (bx / 2, by / 2)),
        face_site("+z", bz, (-bx / 2, -by / 2), (-fx, by / 2)),
    ]
    s = ro if box_cap else ro / np.sqrt(2)
    sites_b = [face_site("+z", z1, (-s, -s), (s, s))]
    if box_cap:
        sites_b += block_sites(2 * ro, 2 * ro, z1 - z0, z0=z0)
    return FamilyBuild(
        a,
        b,
        (0.0, 0.0, -1.0),
        c,
        ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
        sites_a,
        sites_b,
        f"{kind}_post_on_base",
        f"{'box' if box_cap else 'round'}_cap",
        f"{'box' if box_cap else 'round'} cap lowered onto a {kind} post",
        {
            "post_r_mm": r * 1e3,
            "post_h_mm": ph * 1e3,
            "base_mm": f"{bx * 1e3:.1f}x{by * 1e3:.1f}x{bz * 1e3:.1f}",
            "cap_mm": f"{2 * ro * 1e3:.1f}x{(z1 - z0) * 1e3:.1f}",
            "post": kind,
        },
    )


def bracket_on_block(rng: np.random.Generator) -> FamilyBuild:
    c = draw_clearance(rng)
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
    sites_a = block_sites(ax, ay, az, sides="+x-x")
    fx = bl / 2 + 2e-3
    sites_a += [
        face_site("+z", az, (fx, -ay / 2), (ax / 2, ay / 2)),
        face_site("+z", az, (-ax / 2, -ay / 2), (-fx, ay / 2)),
        face_site("+y", ay / 2, (-ax / 2, 0.0), (ax / 2, lo - 2e-3)),
        face_site("-y", -ay / 2, (-ax / 2, 0.0), (ax / 2, lo - 2e-3)),
    ]
    sites_b = [
        face_site("+z", top, (-bl / 2, -wy / 2), (bl / 2, wy / 2)),
        face_site("+y", wy / 2, (-bl / 2, lo), (bl / 2, top)),
        face_site("-y", -wy / 2, (-bl / 2, lo), (bl / 2, top)),
    ]
    return FamilyBuild(
        a,
        b,
        (0.0, 0.0, -1.0),
        c,
        ((0.0, 1.0, 0.0),),
        sites_a,
        sites_b,
        "block",
        "u_bracket",
        "U bracket lowered over a block (its legs either side)",
        {
            "block_mm": f"{ax * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}",
            "bracket_mm": f"{bl * 1e3:.1f}x{wy * 1e3:.1f}",
            "legs_mm": legs * 1e3,
            "thickness_mm": t * 1e3,
        },
    )
