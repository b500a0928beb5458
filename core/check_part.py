"""``asmteach check-part MESH``: what the pipeline will do with one part, as lines a user can act on.

The core reports what it owns: the units (guessed from the size when not
given), the repairs made to the mesh, the part's symmetry group and the
fidelity of its convex decomposition (the collision pieces of simulation).
Every stage plugin then adds its own lines through the
``asmteach_check_part`` hook (the placements plugin: the stable placements
and a picture of them; the grasp planner: how many grasps, or why none).

Each line is ``(stage, level, text)`` with ``level`` one of ``ok``,
``warn`` (works, but look) and ``fail`` (this stage will fail on the part);
the command exits 1 when any line fails, 0 otherwise, 2 on bad input.
Units in the text: millimetres and degrees.
"""

from __future__ import annotations

import argparse
import logging
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from asmteach.core.errors import UserError

__all__ = ["CheckLine", "add_check_part_command", "check_part"]

Level = Literal["ok", "warn", "fail"]


@dataclass(frozen=True)
class CheckLine:
    """One finding about a part: the stage it concerns, how bad it is, and what to do."""

    stage: str
    level: Level
    text: str


class _Collect(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())


@contextmanager
def _warnings_of(logger: str) -> Iterator[list[str]]:
    handler = _Collect()
    log = logging.getLogger(logger)
    log.addHandler(handler)
    propagate, log.propagate = log.propagate, False  # printed as findings, not twice
    try:
        yield handler.messages
    finally:
        log.removeHandler(handler)
        log.propagate = propagate


def _guess_units(path: Path) -> tuple[str, float]:
    """``("m" | "mm", largest extent in file units)``: parts of this library are 2 mm to 2 m."""
    import trimesh

    from asmteach.core.parts import MAX_EXTENT_M

    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # noqa: BLE001 - any loader failure is a bad file
        raise UserError(f"{path}: cannot read the mesh ({type(exc).__name__}: {exc})") from None
    if not hasattr(mesh, "extents") or mesh.extents is None:
        raise UserError(f"{path}: the file holds no triangles")
    extent = float(np.max(mesh.extents))
    return ("mm" if extent > MAX_EXTENT_M else "m"), extent


def _symmetry_text(count: int) -> str:
    if count == 1:
        return "no symmetry: every pose of the part is distinct"
    return (
        f"{count} proper rotations map the part onto itself; poses that differ by one are the same answer "
        "in detection, correction and every error figure"
    )


def check_part(
    path: str | Path, *, units: str | None = None, out_dir: Path | None = None, pm: Any = None
) -> list[CheckLine]:
    """Findings about the mesh file ``path`` (``units`` ``"m"``/``"mm"``, guessed when ``None``).

    ``out_dir`` receives pictures (the placements' contact sheet); ``pm`` is
    the plugin manager whose ``asmteach_check_part`` implementations add the
    stages' lines.
    """
    from asmteach.core.convex_pieces import decompose
    from asmteach.core.models import PartSpec
    from asmteach.core.parts import build_part
    from asmteach.core.symmetry import part_symmetries

    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: no such file")
    lines: list[CheckLine] = []
    if units is None:
        units, extent = _guess_units(path)
        lines.append(
            CheckLine(
                "units",
                "warn" if units == "mm" else "ok",
                f"guessed {units}: the largest extent is {extent:.4g} file units "
                f"(pass --units m|mm to say so; parts are 2 mm to 2 m)",
            )
        )
    else:
        lines.append(CheckLine("units", "ok", f"{units}, as given"))
    with _warnings_of("asmteach.core.parts") as repairs:
        part = build_part(PartSpec(name=path.stem, mesh=str(path.resolve()), mesh_units=units))
    lines += [CheckLine("repair", "warn", text.split(": ", 1)[-1]) for text in repairs]
    if not repairs:
        lines.append(CheckLine("repair", "ok", "the mesh is closed and consistently wound; nothing changed"))
    ext = np.asarray(part.mesh.extents) * 1000.0
    lines.append(
        CheckLine(
            "mass",
            "ok",
            f"{ext[0]:.1f} x {ext[1]:.1f} x {ext[2]:.1f} mm, volume "
            f"{part.mesh.volume * 1e6:.2f} cm3, mass {part.mass * 1000:.1f} g "
            f"(set mass or density in a part YAML if the material differs)",
        )
    )
    syms = part_symmetries(part.mesh, np.asarray(part.center_of_mass, dtype=float))
    lines.append(CheckLine("symmetry", "ok", _symmetry_text(len(syms))))
    dec = decompose(part)
    level: Level = "ok" if dec.protrusion <= 1e-4 else "warn"
    lines.append(
        CheckLine(
            "collision",
            level,
            f"{len(dec.pieces)} convex pieces ({dec.method}): Hausdorff {dec.hausdorff * 1000:.3f} mm, "
            f"protrusion {dec.protrusion * 1000:.3f} mm, volume error {dec.volume_error * 100:.2f} %"
            + ("" if level == "ok" else "; clearances below the protrusion will close in simulation"),
        )
    )
    if pm is not None:
        for found in pm.hook.asmteach_check_part(part=part, out_dir=out_dir):
            lines += [CheckLine(*row) for row in found]
    return lines


def _cmd_check_part(args: argparse.Namespace) -> int:
    out = Path(args.out) if args.out else None
    if out is not None:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise UserError(f"--out {out}: cannot create the folder ({exc.strerror})") from None
    lines = check_part(args.mesh, units=args.units, out_dir=out, pm=args.plugin_manager)
    mark = {"ok": "ok  ", "warn": "WARN", "fail": "FAIL"}
    for line in lines:
        print(f"{mark[line.level]} {line.stage:<10} {line.text}")
    failed = [line for line in lines if line.level == "fail"]
    print(
        f"{Path(args.mesh).name}: {len(failed)} stage(s) will fail"
        if failed
        else f"{Path(args.mesh).name}: every stage can use this part"
    )
    return 1 if failed else 0


def add_check_part_command(sub: argparse._SubParsersAction, pm: Any) -> None:
    """Register ``check-part`` on the CLI's sub-parsers."""
    p = sub.add_parser(
        "check-part",
        help="what each stage will do with one part: units, repairs, symmetry, collision pieces, placements, grasps",
    )
    p.add_argument("mesh", help="STL/OBJ/PLY/OFF mesh file")
    p.add_argument("--units", choices=("m", "mm"), default=None, help="mesh units (default: guessed from its size)")
    p.add_argument("--out", default=None, help="folder for pictures (placements contact sheet)")
    p.set_defaults(func=_cmd_check_part, plugin_manager=pm)
