"""The slide families: a dovetail slider and a T slider pushed along their groove (v_a horizontal)."""

from __future__ import annotations

import numpy as np

from asmteach.core.corpus import _box, _minus, _plus, _u
from asmteach.core.structure_corpus.build import (
    GRASP_WIDTH_MAX,
    FamilyBuild,
    block_sites,
    draw_clearance,
    prism_x,
)
from asmteach.core.structure_corpus.markers import MarkerSite, face_site


def _slide_frame(rng: np.random.Generator, slot_w: float, slot_h: float) -> tuple[float, float, float, float, bool]:
    """A's length, width and height, the stop wall (0 for a through slot) and whether it is stopped (metres)."""
    la = _u(rng, 45, 100)
    wall = _u(rng, 6, 16)
    ay = min(slot_w + 2 * wall, GRASP_WIDTH_MAX)
    az = max(slot_h + _u(rng, 5, 16), 17e-3)  # its sides hold a 10 mm marker
    stopped = bool(rng.random() < 0.5)
    stop = _u(rng, 5, 10) if stopped else 0.0
    return la, ay, az, stop, stopped


def _slide_sites(la: float, ay: float, az: float, mouth: float, stopped: bool) -> list[MarkerSite]:
    sites = block_sites(la, ay, az, sides="+y-y")
    if stopped:
        sites += block_sites(la, ay, az, sides="-x")
    edge = mouth / 2 + 1e-3
    sites += [
        face_site("+z", az, (-la / 2, edge), (la / 2, ay / 2)),
        face_site("+z", az, (-la / 2, -ay / 2), (la / 2, -edge)),
    ]
    return sites


def dovetail_slide(rng: np.random.Generator) -> FamilyBuild:
    c = draw_clearance(rng)
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
    groove = prism_x(
        np.array([[-(wide / 2 + c), floor], [wide / 2 + c, floor], [top_half, az + 1e-3], [-top_half, az + 1e-3]]),
        -la / 2 + stop,
        la / 2 + 1e-2,
    )
    a = _minus(_box((la, ay, az), (0, 0, az / 2)), groove)
    lb = max(20e-3, (la - stop) * float(rng.uniform(0.45, 0.85)))
    x0 = -la / 2 + stop if stopped else -lb / 2  # stopped: B's front touches the stop wall
    neck_h = _u(rng, 16, 28)  # its sides above A hold a 10 mm marker
    body = prism_x(np.array([[-wide / 2, floor], [wide / 2, floor], [narrow / 2, az], [-narrow / 2, az]]), x0, x0 + lb)
    neck = _box((lb, narrow, neck_h), (x0 + lb / 2, 0, az + neck_h / 2))
    b = _plus(body, neck)
    top = az + neck_h
    sites_b = [
        face_site("+z", top, (x0, -narrow / 2), (x0 + lb, narrow / 2)),
        face_site("+y", narrow / 2, (x0, az), (x0 + lb, top)),
        face_site("-y", -narrow / 2, (x0, az), (x0 + lb, top)),
        face_site("+x", x0 + lb, (-narrow / 2, az), (narrow / 2, top)),
    ]
    return FamilyBuild(
        a,
        b,
        (-1.0, 0.0, 0.0),
        c,
        ((0.0, 1.0, 0.0),),
        _slide_sites(la, ay, az, narrow + 2 * c, stopped),
        sites_b,
        f"dovetail_{'stopped' if stopped else 'through'}_block",
        "dovetail_slider",
        f"dovetail slider pushed along -x into a {'stopped' if stopped else 'through'} groove",
        {
            "groove_depth_mm": d * 1e3,
            "flank_deg": float(np.degrees(alpha)),
            "narrow_mm": narrow * 1e3,
            "block_mm": f"{la * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}",
            "slider_mm": lb * 1e3,
            "slot": "stopped" if stopped else "through",
        },
    )


def t_slot_slide(rng: np.random.Generator) -> FamilyBuild:
    c = draw_clearance(rng)
    wf = _u(rng, 16, 36)  # flange width
    hf = _u(rng, 5, 10)  # flange height
    wr = max(8e-3, wf * float(rng.uniform(0.35, 0.6)))  # rib width
    lip = _u(rng, 4, 9)  # A's lip over the flange
    fl = max(_u(rng, 4, 12), 17e-3 - (hf + c + lip))  # A's floor; A's sides hold a 10 mm marker
    az = fl + hf + c + lip
    la = _u(rng, 45, 100)
    ay = min(wf + 2 * c + 2 * _u(rng, 6, 16), GRASP_WIDTH_MAX)
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
    sites_b = [
        face_site("+z", top, (x0, -wr / 2), (x0 + lb, wr / 2)),
        face_site("+y", wr / 2, (x0, az), (x0 + lb, top)),
        face_site("-y", -wr / 2, (x0, az), (x0 + lb, top)),
        face_site("+x", x0 + lb, (-wr / 2, az), (wr / 2, top)),
    ]
    return FamilyBuild(
        a,
        b,
        (-1.0, 0.0, 0.0),
        c,
        ((0.0, 1.0, 0.0),),
        _slide_sites(la, ay, az, wr + 2 * c, stopped),
        sites_b,
        f"t_slot_{'stopped' if stopped else 'through'}_block",
        "t_slider",
        f"T slider pushed along -x into a {'stopped' if stopped else 'through'} T-slot",
        {
            "flange_mm": f"{wf * 1e3:.1f}x{hf * 1e3:.1f}",
            "rib_mm": wr * 1e3,
            "lip_mm": lip * 1e3,
            "block_mm": f"{la * 1e3:.1f}x{ay * 1e3:.1f}x{az * 1e3:.1f}",
            "slider_mm": lb * 1e3,
            "slot": "stopped" if stopped else "through",
        },
    )
