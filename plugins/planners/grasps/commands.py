"""``asmteach grasps MESH --out grasps.json``: parallel-jaw grasps of any mesh or library part.

``MESH`` is an STL/OBJ/PLY file (``--units m|mm``), a part YAML, or a
structure YAML of the library (both parts, or ``--part``). The JSON holds, per
part, entries ``{id, p0, p1, R, width, score}`` (metres, part frame; ``R`` the
3x3 TCP rotation); a PNG of the grasps on the part is written next to it.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from pydantic import ValidationError

from asmteach.core import registry
from asmteach.core.config import check_finite, format_validation_error
from asmteach.core.errors import UserError
from asmteach.core.hooks import hookimpl
from asmteach.core.interfaces import PartModel
from asmteach.core.io import check_out_file, read_yaml, write_json
from asmteach.core.models import HandSpec
from asmteach.core.parts import MESH_SUFFIXES
from asmteach.core.parts import load_parts as load_library_parts
from asmteach.plugins.planners.grasps.checks import check_mesh
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner
from asmteach.plugins.planners.grasps.render import render_grasps
from asmteach.plugins.planners.grasps.settings import AntipodalSettings

__all__ = ["asmteach_add_commands", "load_hand", "load_parts", "run_grasps"]

# Names kept from before the hand came from the robot registry (configs and scripts say "nextage").
_ROBOT_ALIASES = {"nextage": "nextage_pybullet"}


def load_hand(spec: str) -> HandSpec:
    """The gripper of a registered robot plugin (``"nextage_pybullet"``, ``"urdf_arm"``; ``"nextage"`` is
    the Nextage's) or a YAML/JSON file of :class:`HandSpec` fields.

    A robot's hand is read from the robot built with its default settings,
    then closed again, so the grasp planner names no robot module.
    """
    robots = [info.name for info in registry.discover("robots", load=False)]
    name = _ROBOT_ALIASES.get(spec, spec)
    if name in robots:
        robot = registry.create("robots", name)
        try:
            return robot.hand
        finally:
            close = getattr(robot, "close", None)
            if callable(close):
                close()
    path = Path(spec)
    if not path.is_file():
        raise UserError(
            f"--hand: {spec!r} is neither a robot ({', '.join(sorted(robots))}, or nextage) "
            "nor an existing HandSpec YAML/JSON file"
        )
    raw = read_yaml(path)
    check_finite(raw, str(path))  # a NaN passes every bound of the hand's geometry
    try:
        return HandSpec.model_validate(raw)
    except ValidationError as exc:
        raise UserError(f"{path}: {format_validation_error(exc)}") from None


def _check_mesh_file(path: Path, units: str) -> None:
    try:
        raw = trimesh.load(path, force="mesh")
    except Exception as exc:  # noqa: BLE001 - any loader failure is a bad file
        raise UserError(f"{path}: cannot read the mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(raw, trimesh.Trimesh) or len(raw.faces) == 0:
        raise UserError(f"{path}: the file holds no triangles")
    if units == "mm":
        raw.apply_scale(0.001)
    # Checked before the part loader, which would quietly replace an open shell by its hull.
    check_mesh(raw, path.stem)


def load_parts(source: str, units: str = "m", part: str | None = None) -> list[PartModel]:
    """Parts named by ``source`` (mesh file, part YAML or structure YAML), optionally only ``part``."""
    path = Path(source)
    if path.is_file() and path.suffix.lower() in MESH_SUFFIXES:
        _check_mesh_file(path, units)
    return load_library_parts(source, units=units, select=part)


def _entry(g: Any) -> dict[str, Any]:
    return {
        "id": g.id,
        "p0": np.round(g.p0, 9).tolist(),
        "p1": np.round(g.p1, 9).tolist(),
        "R": np.round(g.R, 9).tolist(),
        "width": round(g.width, 9),
        "score": round(g.score, 6),
    }


def run_grasps(args: argparse.Namespace) -> int:
    """The ``grasps`` command."""
    out = Path(args.out)
    if out.suffix.lower() != ".json":
        raise UserError(f"--out {args.out}: give a .json file name")
    check_out_file(out, example="grasps.json")  # a read-only or wrong --out costs one line, before any work
    if args.seed < 0:
        raise UserError(f"--seed {args.seed}: give a whole number >= 0")
    hand = load_hand(args.hand)
    overrides: dict[str, Any] = {"mu": args.mu, "cache": not args.no_cache}
    if args.pad_min_support is not None:
        overrides["pad_min_support"] = args.pad_min_support
    try:
        settings = AntipodalSettings.model_validate(overrides)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc)) from None
    planner = AntipodalGraspPlanner(settings, seed=args.seed)
    parts = load_parts(args.mesh, args.units, args.part)
    records, panels = [], []
    for part in parts:
        grasps = planner.plan(part, hand)
        stats = dict(planner.last_stats)
        records.append(
            {
                "name": part.name,
                "mesh_hash": part.source_hash,
                "center_of_mass": np.round(part.center_of_mass, 9).tolist(),
                "stats": stats,
                "grasps": [_entry(g) for g in grasps],
            }
        )
        panels.append((part, grasps))
        took = "cached" if stats.get("cache_hit") else f"{stats.get('seconds', 0.0):.2f} s"
        print(f"{part.name}: {len(grasps)} grasps ({took})")
    doc = {
        "units": "m",
        "frame": "part (R: TCP axes as columns; y from p0 to p1; z approach)",
        "hand": hand.model_dump(mode="json"),
        "planner": {"name": "antipodal", "seed": args.seed, "settings": settings.model_dump(mode="json")},
        "parts": records,
    }
    write_json(out, doc)
    png = render_grasps(panels, out.with_suffix(".png"))
    print(f"wrote {out} and {png}")
    return 0


@hookimpl
def asmteach_add_commands(subparsers: argparse._SubParsersAction) -> None:
    """Register ``asmteach grasps``."""
    p = subparsers.add_parser("grasps", help="parallel-jaw grasps of a mesh or library part (JSON + PNG)")
    p.add_argument("mesh", help="mesh file (STL/OBJ/PLY) or part/structure YAML")
    p.add_argument("--out", required=True, help="JSON file to write; the PNG goes next to it")
    p.add_argument("--units", choices=["m", "mm"], default="m", help="units of a mesh file's coordinates")
    p.add_argument("--part", default=None, help="for a structure: a, b or the part's name (default both)")
    p.add_argument(
        "--hand", default="nextage", help="a robot whose gripper to use (nextage, urdf_arm) or a HandSpec YAML/JSON"
    )
    p.add_argument("--mu", type=float, default=0.3, help="friction coefficient of the antipodal test")
    p.add_argument(
        "--pad-min-support",
        type=float,
        default=None,
        help="optional share of each pad in contact (default 0: the contact model decides; 1: pads fully on a face)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-cache", action="store_true", help="plan again even when a cached result exists")
    p.set_defaults(func=run_grasps)
