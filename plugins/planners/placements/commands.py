"""``asmteach placements MESH --out placements.json``: stable placements of any mesh or library part.

``MESH`` is a mesh file (STL/OBJ/PLY; ``--units m|mm``), a part YAML or a
structure YAML of the part library (both of its parts). The JSON holds, per
part, the placements (``T_table_part`` 4x4 in metres with the part resting on
z = 0 at its canonical yaw, ``probability``, ``margin``, ``support_polygon``,
``symmetry_yaws``) and the facets refused by the margin test; a contact-sheet
PNG is written next to it.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import PartModel
from asmteach.core.io import check_out_file, write_json
from asmteach.core.parts import load_parts as load_library_parts
from asmteach.core.rests.placements import PlacementResult, placement_result
from asmteach.plugins.planners.placements.contact_sheet import render_contact_sheet

__all__ = ["asmteach_add_commands", "load_parts"]


def load_parts(source: str | Path, *, units: str = "m", com: list[float] | None = None) -> list[PartModel]:
    """Parts named by ``source``: a mesh file, a part YAML or a structure YAML (its two parts)."""
    return load_library_parts(source, units=units, center_of_mass=None if com is None else np.asarray(com, float))


def _part_record(part: PartModel, result: PlacementResult) -> dict[str, Any]:
    return {
        "part": part.name,
        "mesh_hash": part.source_hash,
        "units": "m",
        "mass": part.mass,
        "center_of_mass": np.asarray(part.center_of_mass).tolist(),
        "seconds": result.seconds,
        "notes": result.notes,
        "placements": [p.model_dump(mode="json") for p in result.placements],
        "rejected": [vars(r) for r in result.rejected],
    }


def _cmd_placements(args: argparse.Namespace) -> int:
    out = check_out_file(args.out, example="placements.json")  # a wrong --out costs one line, before any work
    if not (math.isfinite(args.min_margin) and args.min_margin >= 0):
        raise UserError(f"--min-margin {args.min_margin}: give a number >= 0 (d/h, e.g. 0.1)")
    if not (math.isfinite(args.angle_tol_deg) and 0 < args.angle_tol_deg <= 45):
        raise UserError(f"--angle-tol-deg {args.angle_tol_deg}: give degrees in (0, 45], e.g. 1")
    parts = load_parts(args.mesh, units=args.units, com=args.com)
    records = []
    for part in parts:
        result = placement_result(part, min_margin=args.min_margin, angle_tol_deg=args.angle_tol_deg)
        records.append(_part_record(part, result))
        sheet = out.with_suffix(".png") if len(parts) == 1 else out.with_name(f"{out.stem}_{part.name}.png")
        if not args.no_sheet:
            render_contact_sheet(
                part.mesh, result.placements, part.center_of_mass, sheet, title=f"{part.name}: stable placements"
            )
        probs = ", ".join(f"{p.probability:.2f}" for p in result.placements)
        print(
            f"{part.name}: {len(result.placements)} stable placements (p = {probs}); "
            f"{len(result.rejected)} refused by the margin test" + ("" if args.no_sheet else f"; sheet {sheet}")
        )
        if not result.placements:
            print(f"{part.name}: no facet passes d/h >= {args.min_margin}; lower --min-margin to see marginal ones")
    payload: dict[str, Any] = records[0] if len(records) == 1 else {"source": str(args.mesh), "parts": records}
    write_json(out, payload)
    print(f"placements: {out}")
    return 0


@hookimpl
def asmteach_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Add ``asmteach placements``."""
    p = subparsers.add_parser("placements", help="stable placements of a mesh or library part (JSON + PNG)")
    p.add_argument("mesh", help="mesh file (STL/OBJ/PLY) or a part/structure YAML of the library")
    p.add_argument("--out", required=True, help="placements JSON; the contact sheet PNG goes next to it")
    p.add_argument("--units", choices=["m", "mm"], default="m", help="units of a mesh file (default m)")
    p.add_argument(
        "--com",
        type=float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=None,
        help="centre of mass in the part frame, metres (default: uniform density)",
    )
    p.add_argument("--min-margin", type=float, default=0.1, help="stability margin d/h (default 0.1)")
    p.add_argument("--angle-tol-deg", type=float, default=1.0, help="coplanar-face tolerance, degrees")
    p.add_argument("--no-sheet", action="store_true", help="skip the contact-sheet PNG")
    p.set_defaults(func=_cmd_placements)


@hookimpl
def asmteach_check_part(part: PartModel, out_dir: Path | None) -> list[tuple[str, str, str]]:
    """Stable placements of ``part`` for ``asmteach check-part``, with a contact sheet in ``out_dir``."""
    result = placement_result(part)
    n = len(result.placements)
    if n == 0:
        return [
            (
                "placements",
                "fail",
                "no facet of the convex hull holds the centre of mass with d/h >= 0.1: "
                "the part cannot rest on the table (check center_of_mass)",
            )
        ]
    margins = ", ".join(f"{p.margin:.2f}" for p in result.placements)
    text = f"{n} stable placements (d/h {margins})"
    if out_dir is not None:
        sheet = render_contact_sheet(
            part.mesh,
            result.placements,
            part.center_of_mass,
            Path(out_dir) / f"{part.name}_placements.png",
            title=f"{part.name}: stable placements",
        )
        text += f"; picture {sheet}"
    rows = [("placements", "ok", text)]
    if n == 1:
        rows.append(
            (
                "placements",
                "warn",
                "only one stable placement: the regrasp graph has no intermediate rest to turn the part over",
            )
        )
    return rows
