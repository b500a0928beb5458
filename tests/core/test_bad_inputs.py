"""Bad inputs and faults, as a new user meets them: one line naming the cause, the right exit code, no traceback.

Table-driven (issue 26): each case makes a small input in ``tmp_path``,
optionally injects a fault (a read-only folder, a full disk), runs the
``asmteach`` command in-process and checks the exit code (2 bad input, 1 the
task failed, 0 fine) and that stderr holds exactly one ``asmteach:`` line
that says what the case expects. Every command here fails (or passes)
before any real work starts, so the whole table runs in seconds.

``CASES`` is also what ``docs/results/reliability.md`` lists
(``python tests/core/test_bad_inputs.py`` prints that table).
"""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

ROOT = Path(__file__).resolve().parents[2]
STRUCTURE = ROOT / "configs/parts/set1/peg_in_hole.yaml"
CAMERA = ROOT / "configs/cameras/c615.yaml"
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


# ---------------------------------------------------------------- input makers
def structure(tmp: Path, edit: Callable[[dict], None] | None = None, name: str = "structure.yaml") -> Path:
    """The demo's peg-in-hole structure copied into ``tmp`` (``edit`` changes its dict first)."""
    data = yaml.safe_load(STRUCTURE.read_text())
    if edit is not None:
        edit(data)
    path = tmp / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def config(tmp: Path, *, edit_structure: Callable[[dict], None] | None = None, **keys: object) -> Path:
    """A run config in ``tmp`` naming ``structure.yaml`` beside it (relative, as users write it)."""
    structure(tmp, edit_structure)
    data: dict[str, object] = {"name": "bad", "seed": 1, "structure": "structure.yaml", **keys}
    path = tmp / "run.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def write(tmp: Path, name: str, content: str | bytes) -> Path:
    path = tmp / name
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


def box_stl(tmp: Path, name: str = "box.stl", scale: float = 1.0, drop: int = 0) -> Path:
    """A 40 x 30 x 20 mm box (times ``scale``) as STL without its first ``drop`` triangles (2: one side
    missing, which the loader closes; 6: three sides, which it refuses)."""
    mesh = trimesh.creation.box(extents=[0.04 * scale, 0.03 * scale, 0.02 * scale])
    if drop:
        mesh = trimesh.Trimesh(mesh.vertices, mesh.faces[drop:], process=False)
    path = tmp / name
    mesh.export(path)
    return path


BOX_MARKERS = [  # on the faces of box_stl's box (centred on the origin)
    {"id": 0, "size": 0.015, "T_part_marker": {"xyz": [0, -0.015, 0], "rpy_deg": [90, 0, 0]}},
    {"id": 1, "size": 0.015, "T_part_marker": {"xyz": [0.02, 0, 0], "rpy_deg": [90, 0, 90]}},
]


def inline_mesh_part(data: dict, mesh: str) -> None:
    """Part A written inline as box_stl's mesh (a path relative to the structure file), with markers on it."""
    data["part_a"] = {"name": "meshy", "mesh": mesh, "markers": BOX_MARKERS}


def experiment(tmp: Path, text: str) -> Path:
    return write(tmp, "exp.yaml", text)


def readonly(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``path`` a read-only folder; as root (who may write anyway) the file system refuses it for real
    by a patch of the calls that create files there (EACCES)."""
    path.mkdir(parents=True, exist_ok=True)
    path.chmod(0o555)
    if not IS_ROOT:
        return
    real_mkstemp, real_open, real_mkdir = tempfile.mkstemp, os.open, os.mkdir

    def under(p: object) -> bool:
        return p is not None and Path(os.fspath(p)).resolve().is_relative_to(path.resolve())  # type: ignore[arg-type]

    def mkstemp(*a, dir=None, **k):
        if under(dir):
            raise PermissionError(errno.EACCES, "Permission denied", str(dir))
        return real_mkstemp(*a, dir=dir, **k)

    def fake_open(p, flags, *a, **k):
        if under(p) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(p))
        return real_open(p, flags, *a, **k)

    def fake_mkdir(p, *a, **k):
        if under(Path(os.fspath(p)).parent):
            raise PermissionError(errno.EACCES, "Permission denied", os.fspath(p))
        return real_mkdir(p, *a, **k)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    monkeypatch.setattr(os, "open", fake_open)
    monkeypatch.setattr(os, "mkdir", fake_mkdir)


def full_disk(monkeypatch: pytest.MonkeyPatch, after: int = 0) -> None:
    """Writes fail with ENOSPC (a full disk), after ``after`` successful ``os.write`` calls to files."""
    real_write = os.write
    count = {"n": 0}

    def fake_write(fd: int, data: bytes) -> int:
        if fd > 2:  # not stdout / stderr
            count["n"] += 1
            if count["n"] > after:
                raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, data)

    monkeypatch.setattr(os, "write", fake_write)


# ---------------------------------------------------------------- the table
@dataclass
class Case:
    """One bad input or fault: what is made, the command, the exit code and what the one line must say."""

    id: str
    what: str
    """The input or fault, in words (for the results doc)."""
    argv: Callable[[Path], list[str]]
    code: int
    says: str
    """A regular expression the one error line must match (case-insensitive); empty for exit 0."""
    fault: Callable[[Path, pytest.MonkeyPatch], None] | None = None
    needs: tuple[str, ...] = field(default_factory=tuple)
    """Fixtures the case needs (``toy_dist`` for the toy experiment kind)."""


def _run(tmp: Path, cfg: Path, *extra: str) -> list[str]:
    return ["run", str(cfg), "--out", str(tmp / "out"), *extra]


def _val(cfg: Path, *extra: str) -> list[str]:
    return ["validate", str(cfg), *extra]


def _no_markers(d: dict) -> None:
    d["part_b"]["markers"] = []


def _set(path: str, value: object) -> Callable[[dict], None]:
    def edit(d: dict) -> None:
        node = d
        keys = path.split(".")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node[k]
        last = keys[-1]
        if isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value

    return edit


NAN = float("nan")
SQUARE = "experiment: toy_square\nparams: {fail_above: 2.5}\ngrid:\n  x: [1.0, 2.0]\nseeds: 1\n"

CASES: list[Case] = [
    # --- the config file itself
    Case("config-missing", "config file does not exist", lambda t: _val(t / "none.yaml"), 2, r"no such file"),
    Case("config-folder", "config path is a folder", lambda t: _val(t), 2, r"is a folder"),
    Case(
        "config-binary",
        "config is a binary file",
        lambda t: _val(write(t, "c.yaml", b"\x00\x01\x02PK\x03")),
        2,
        r"binary",
    ),
    Case(
        "config-latin1",
        "config is not UTF-8",
        lambda t: _val(write(t, "c.yaml", "name: caf\xe9\n".encode("latin-1"))),
        2,
        r"UTF-8",
    ),
    Case(
        "config-bad-yaml",
        "config is not valid YAML",
        lambda t: _val(write(t, "c.yaml", "name: [a, b\nseed: 1\n")),
        2,
        r"invalid YAML at line",
    ),
    Case("config-list", "config is a YAML list", lambda t: _val(write(t, "c.yaml", "- a\n- b\n")), 2, r"mapping"),
    Case("config-empty", "config is an empty file", lambda t: _val(write(t, "c.yaml", "")), 2, r"mapping"),
    Case(
        "config-unknown-key",
        "a misspelt top-level key (structur)",
        lambda t: _val(write(t, "c.yaml", f"structur: {STRUCTURE}\n")),
        2,
        r"structur.*unknown key|structure.*missing",
    ),
    Case("seed-negative", "seed: -1", lambda t: _val(config(t, seed=-1)), 2, r"seed.*greater than or equal"),
    Case(
        "seed-huge",
        "seed: 99999999999 (Open3D takes 32 bits)",
        lambda t: _val(config(t), "--set", "seed=99999999999"),
        2,
        r"seed: Input should be less than or equal to 2147483647",
    ),
    Case(
        "camera-device",
        "camera: /dev/null",
        lambda t: _val(config(t, camera="/dev/null")),
        2,
        r"camera: not a file /dev/null",
    ),
    Case("seed-nan", "seed: .nan", lambda t: _val(config(t, seed=NAN)), 2, r"seed: not a finite number"),
    Case(
        "structure-missing",
        "structure names no file",
        lambda t: _val(config(t, structure="nope.yaml")),
        2,
        r"structure: no such file",
    ),
    Case(
        "plugin-unknown",
        "detector.plugin misspelt",
        lambda t: _val(config(t, detector={"plugin": "cvfh_icpp"})),
        2,
        r"detector\.plugin.*cvfh_icp",
    ),
    Case(
        "plugin-setting",
        "a plugin setting misspelt",
        lambda t: _val(config(t, detector={"plugin": "cvfh_icp", "settings": {"voxl": 1}})),
        2,
        r"detector\.settings\.voxl: unknown key",
    ),
    Case(
        "plugin-setting-nan",
        "a plugin setting NaN",
        lambda t: _val(config(t, robot={"plugin": "nextage_pybullet", "settings": {"grip_force": NAN}})),
        2,
        r"robot\.settings\.grip_force: not a finite number",
    ),
    # --- execution and demo sections (plain dicts before: never checked by validate)
    Case(
        "execution-typo",
        "execution.animaton (typo)",
        lambda t: _val(config(t, execution={"animaton": False})),
        2,
        r"execution\.animaton: unknown key",
    ),
    Case(
        "execution-range",
        "execution.depth_frames: 0",
        lambda t: _val(config(t, execution={"depth_frames": 0})),
        2,
        r"execution\.depth_frames",
    ),
    Case(
        "execution-choice",
        "execution.look_again: sometimes",
        lambda t: _val(config(t, execution={"look_again": "sometimes"})),
        2,
        r"execution\.look_again.*always",
    ),
    Case(
        "scene-backwards",
        "execution.scene.x_range high before low",
        lambda t: _val(config(t, execution={"scene": {"x_range": [0.44, 0.30]}})),
        2,
        r"x_range.*backwards",
    ),
    Case(
        "scene-negative-y",
        "execution.scene.y_range below 0",
        lambda t: _val(config(t, execution={"scene": {"y_range": [-0.1, 0.2]}})),
        2,
        r"y_range.*\|y\|",
    ),
    Case(
        "demo-typo", "demo.frame (typo)", lambda t: _val(config(t, demo={"frame": 3})), 2, r"demo\.frame: unknown key"
    ),
    Case(
        "demo-range", "demo.orientation: 9", lambda t: _val(config(t, demo={"orientation": 9})), 2, r"demo\.orientation"
    ),
    Case("demo-not-mapping", "demo: a text", lambda t: _val(config(t, demo="fast")), 2, r"demo.*mapping"),
    # --- the table
    Case(
        "table-center-nan",
        "table.center has NaN",
        lambda t: _val(config(t, table={"center": [NAN, 0.0]})),
        2,
        r"table\.center\[0\]: not a finite number",
    ),
    Case(
        "table-size-negative",
        "table.size negative",
        lambda t: _val(config(t, table={"size": [-0.6, 1.2]})),
        2,
        r"table\.size\[0\].*greater than 0",
    ),
    Case(
        "table-size-one",
        "table.size with one number",
        lambda t: _val(config(t, table={"size": [0.6]})),
        2,
        r"table\.size",
    ),
    Case(
        "table-off-region",
        "table.center puts the parts' start region off the table",
        lambda t: _val(config(t, table={"center": [0.45, 0.9]})),
        2,
        r"off the table",
    ),
    Case(
        "table-too-small",
        "table.size too small for the start region",
        lambda t: _val(config(t, table={"size": [0.1, 0.1]})),
        2,
        r"off the table",
    ),
    Case(
        "table-twice",
        "table.center and robot.settings.table_center differ",
        lambda t: _val(
            config(
                t,
                table={"center": [0.45, 0.0]},
                robot={"plugin": "nextage_pybullet", "settings": {"table_center": [0.5, 0.0]}},
            )
        ),
        2,
        r"differ",
    ),
    Case(
        "scene-one-number",
        "execution.scene.x_range with one number",
        lambda t: _val(config(t), "--set", "execution.scene.x_range=[0.3]"),
        2,
        r"x_range\[1\]: too few values",
    ),
    Case(
        "teacher-null",
        "teacher: null",
        lambda t: _val(config(t), "--set", "teacher=null"),
        2,
        r"teacher: expected a mapping of keys and values, got nothing \(null\)",
    ),
    Case("table-height", "table.height: 9 m", lambda t: _val(config(t, table={"height": 9})), 2, r"table\.height"),
    Case(
        "table-height-twice",
        "table.height and robot.settings.table_height differ",
        lambda t: _val(
            config(t, table={"height": 0.1}, robot={"plugin": "nextage_pybullet", "settings": {"table_height": 0.2}})
        ),
        2,
        r"table\.height 0\.1 and robot\.settings\.table_height 0\.2 differ",
    ),
    Case(
        "table-center-null",
        "table.center: null (the robot's own table): accepted",
        lambda t: _val(config(t, table={"center": None, "size": None})),
        0,
        "",
    ),
    Case(
        "scene-typo",
        "execution.scene.min_probabilty (typo)",
        lambda t: _val(config(t, execution={"scene": {"min_probabilty": 0.1}})),
        2,
        r"execution\.scene\.min_probabilty: unknown key",
    ),
    # --- the camera
    Case(
        "camera-missing",
        "camera names no file",
        lambda t: _val(config(t, camera="cam.yaml")),
        2,
        r"camera: no such file",
    ),
    Case(
        "camera-distortion",
        "camera with distortion for the rendered demonstration",
        lambda t: _val(
            config(
                t,
                camera=str(
                    write(t, "cam.yaml", CAMERA.read_text().replace("data: [0, 0, 0, 0, 0]", "data: [0.1, 0, 0, 0, 0]"))
                ),
            )
        ),
        2,
        r"distortion",
    ),
    Case(
        "camera-focal",
        "camera with fx = 0",
        lambda t: _val(
            config(
                t, camera=str(write(t, "cam.yaml", CAMERA.read_text().replace("906.7879335, 0, 639.5", "0, 0, 639.5")))
            )
        ),
        2,
        r"fx, fy > 0",
    ),
    Case(
        "camera-binary",
        "camera file is binary",
        lambda t: _val(config(t, camera=str(write(t, "cam.yaml", b"\x00\xff")))),
        2,
        r"binary",
    ),
    # --- the structure and its parts
    Case(
        "T_A_B-nan",
        "T_A_B with NaN",
        lambda t: _val(config(t, edit_structure=_set("T_A_B.xyz.0", NAN))),
        2,
        r"T_A_B\.xyz\[0\]: not a finite number",
    ),
    Case(
        "T_A_B-mm",
        "T_A_B written in millimetres (B 15 m above A)",
        lambda t: _val(config(t, edit_structure=_set("T_A_B.xyz", [0, 0, 15]))),
        2,
        r"T_A_B puts round_peg 14\d\d\d mm away from holed_block.*millimetres written as metres",
    ),
    Case(
        "v_a-zero",
        "v_a = [0, 0, 0]",
        lambda t: _val(config(t, edit_structure=_set("v_a", [0, 0, 0]))),
        2,
        r"v_a.*non-zero",
    ),
    Case(
        "no-markers",
        "part B without markers (render would crash)",
        lambda t: _val(config(t, edit_structure=_no_markers)),
        2,
        r"no markers",
    ),
    Case(
        "marker-shared",
        "one marker id on both parts",
        lambda t: _val(config(t, edit_structure=_set("part_b.markers.0.id", 0))),
        2,
        r"marker ids? \[?0",
    ),
    Case(
        "marker-dictionary",
        "unknown ArUco dictionary",
        lambda t: _val(config(t, edit_structure=_set("part_b.markers.0.dictionary", "DICT_9X9_1"))),
        2,
        r"unknown ArUco dictionary",
    ),
    Case(
        "marker-id-range",
        "marker id beyond its dictionary",
        lambda t: _val(config(t, edit_structure=_set("part_b.markers.0.id", 900))),
        2,
        r"does not exist in",
    ),
    Case(
        "marker-off-surface",
        "a marker placed in millimetres (30 m off the part)",
        lambda t: _val(config(t, edit_structure=_set("part_a.markers.0.T_part_marker.xyz", [0, -30, 20]))),
        2,
        r"part_a\.markers\[0\] \(id 0\): its centre is 3\d\d\d\d mm off holed_block's surface",
    ),
    Case(
        "marker-size",
        "marker size negative",
        lambda t: _val(config(t, edit_structure=_set("part_b.markers.0.size", -0.02))),
        2,
        r"size",
    ),
    Case(
        "part-color",
        "part colour 255 (0..1 expected)",
        lambda t: _val(config(t, edit_structure=_set("part_a.color", [255, 0, 0]))),
        2,
        r"color",
    ),
    Case(
        "part-density",
        "part density negative",
        lambda t: _val(config(t, edit_structure=_set("part_a.density", -1))),
        2,
        r"density",
    ),
    Case(
        "part-com-outside",
        "center_of_mass outside the part",
        lambda t: _val(config(t, edit_structure=_set("part_a.center_of_mass", [1, 0, 0]))),
        2,
        r"outside the part's convex hull",
    ),
    Case(
        "solid-empty",
        "a solid whose subtract removes all of add",
        lambda t: _val(config(t, edit_structure=_set("part_b.solid.subtract", [{"shape": "box", "size": [1, 1, 1]}]))),
        2,
        r"empty or not closed",
    ),
    Case(
        "box-negative",
        "a box with a negative size",
        lambda t: _val(config(t, edit_structure=_set("part_b.solid.add.1.size", [0.04, -0.04, 0.03]))),
        2,
        r"size|greater",
    ),
    Case(
        "part-file-missing",
        "part_a names a missing part file",
        lambda t: _val(config(t, edit_structure=_set("part_a", "parts/none.yaml"))),
        2,
        r"no such file",
    ),
    Case(
        "structure-list",
        "structure file is a list",
        lambda t: _val(config(t, edit_structure=None, structure=str(write(t, "s2.yaml", "- 1\n")))),
        2,
        r"mapping",
    ),
    Case(
        "mesh-missing",
        "inline mesh path that resolves to nothing",
        lambda t: _val(config(t, edit_structure=lambda d: inline_mesh_part(d, "meshes/none.stl"))),
        2,
        r"does not exist",
    ),
    Case(
        "mesh-mm",
        "mesh in millimetres without mesh_units",
        lambda t: _val(config(t, edit_structure=lambda d: inline_mesh_part(d, box_stl(t, scale=1000).name))),
        2,
        r"millimetres",
    ),
    Case(
        "mesh-garbage",
        "mesh file holding text",
        lambda t: _val(config(t, edit_structure=lambda d: inline_mesh_part(d, write(t, "junk.stl", "hello\n").name))),
        2,
        r"cannot read the mesh|no triangles",
    ),
    Case(
        "mesh-relative-ok",
        "inline mesh relative to the structure file (cwd elsewhere): accepted",
        lambda t: _val(config(t, edit_structure=lambda d: inline_mesh_part(d, "m/" + box_stl(_mk(t / "m")).name))),
        0,
        "",
    ),
    Case(
        "part-file-mesh-ok",
        "part file's mesh relative to the part file: accepted",
        lambda t: _val(config(t, edit_structure=_set("part_a", _part_file(t)))),
        0,
        "",
    ),
    Case("demo-ok", "the demo config: accepted", lambda t: _val(ROOT / "configs/demo.yaml"), 0, ""),
    # --- --set
    Case("set-no-equals", "--set seed (no value)", lambda t: _val(config(t), "--set", "seed"), 2, r"KEY=VALUE"),
    Case(
        "set-bad-yaml",
        "--set seed=[1, (bad YAML)",
        lambda t: _val(config(t), "--set", "seed=[1,"),
        2,
        r"--set seed: the value is not valid YAML",
    ),
    Case(
        "set-not-mapping",
        "--set seed.x=1 (seed is a number)",
        lambda t: _val(config(t), "--set", "seed.x=1"),
        2,
        r"seed is not a mapping",
    ),
    Case("set-type", "--set seed=abc", lambda t: _val(config(t), "--set", "seed=abc"), 2, r"seed.*integer"),
    # --- run --out
    Case(
        "run-out-file",
        "run --out is a file",
        lambda t: ["run", str(config(t)), "--out", str(write(t, "o", "x"))],
        2,
        r"is a file, not a folder",
    ),
    Case(
        "run-out-under-file",
        "run --out under a file",
        lambda t: ["run", str(config(t)), "--out", str(write(t, "o", "x") / "sub")],
        2,
        r"is a file",
    ),
    Case(
        "run-out-readonly",
        "run --out a read-only folder",
        lambda t: _run(t, config(t)),
        2,
        r"cannot (write|create)",
        fault=lambda t, mp: readonly(t / "out", mp),
    ),
    Case(
        "run-out-sysfs",
        "run --out where folders cannot be made (/sys)",
        lambda t: ["run", str(config(t)), "--out", "/sys/asmteach-test"],
        2,
        r"cannot create the folder",
    ),
    Case(
        "run-out-other-run",
        "run --out holding another run's results",
        lambda t: _run(t, config(t)),
        2,
        r"holds the results of run 'other'.*--force",
        fault=lambda t, mp: _other_run(t / "out"),
    ),
    Case(
        "run-out-foreign",
        "run --out holding files that are no run's",
        lambda t: _run(t, config(t)),
        2,
        r"not a run's results \(no readable report\.json\); give an empty or new folder$",
        fault=lambda t, mp: write(t, "out/thesis.tex", "x") and None,
    ),
    Case(
        "run-interrupted",
        "run interrupted (Ctrl-C) into a folder of the same run's older results",
        lambda t: _run(t, config(t)),
        130,
        r"interrupted; .*out is as it was",
        fault=lambda t, mp: _interrupted_run(t, mp),
    ),
    Case(
        "run-out-foreign-force",
        "run --out . --force in a folder of other files: still refused",
        lambda t: _run(t, config(t), "--force"),
        2,
        r"not a run's results",
        fault=lambda t, mp: write(t, "out/thesis.tex", "x") and None,
    ),
    Case(
        "run-bad-input-first",
        "run with a bad structure writes nothing",
        lambda t: _run(t, config(t, edit_structure=_no_markers)),
        2,
        r"no markers",
    ),
    # --- placements
    Case(
        "placements-out-folder",
        "placements --out is a folder",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t)],
        2,
        r"is a folder",
    ),
    Case(
        "placements-out-readonly",
        "placements --out in a read-only folder",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t / "ro" / "p.json")],
        2,
        r"cannot write",
        fault=lambda t, mp: readonly(t / "ro", mp),
    ),
    Case(
        "placements-mesh-missing",
        "placements of a missing mesh",
        lambda t: ["placements", str(t / "none.stl"), "--out", str(t / "p.json")],
        2,
        r"no such file",
    ),
    Case(
        "placements-com-nan",
        "placements --com nan 0 0",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t / "p.json"), "--com", "nan", "0", "0"],
        2,
        r"center_of_mass.*finite",
    ),
    Case(
        "placements-com-outside",
        "placements --com outside the part (rtree needed: installed)",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t / "p.json"), "--com", "1", "0", "0"],
        2,
        r"outside the part's convex hull",
    ),
    Case(
        "placements-margin-nan",
        "placements --min-margin nan",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t / "p.json"), "--min-margin", "nan"],
        2,
        r"--min-margin",
    ),
    Case(
        "placements-open-mesh",
        "placements of a mesh with three sides missing",
        lambda t: ["placements", str(box_stl(t, drop=6)), "--out", str(t / "p.json")],
        2,
        r"holes cover 44% of the surface.*Export it closed",
    ),
    Case(
        "placements-hole-closed",
        "placements of a mesh with one side missing: closed, with a warning",
        lambda t: ["placements", str(box_stl(t, drop=2)), "--out", str(t / "p.json"), "--no-sheet"],
        0,
        "",
    ),
    # --- grasps
    Case(
        "grasps-out-not-json",
        "grasps --out without .json",
        lambda t: ["grasps", str(box_stl(t)), "--out", str(t / "g.txt")],
        2,
        r"\.json",
    ),
    Case(
        "grasps-out-folder",
        "grasps --out a folder named .json",
        lambda t: ["grasps", str(box_stl(t)), "--out", str(_mk(t / "g.json"))],
        2,
        r"is a folder",
    ),
    Case(
        "grasps-hand-passwd",
        "grasps --hand /etc/passwd (contents never echoed)",
        lambda t: ["grasps", str(box_stl(t)), "--out", str(t / "g.json"), "--hand", "/etc/passwd"],
        2,
        r"^(?!.*root:).*(mapping|invalid YAML)",
    ),
    Case(
        "grasps-hand-nan",
        "grasps --hand file with a NaN finger size",
        lambda t: [
            "grasps",
            str(box_stl(t)),
            "--out",
            str(t / "g.json"),
            "--hand",
            str(write(t, "hand.yaml", "name: h\nmax_width: .nan\nfinger_size: [0.01, 0.02, 0.03]\n")),
        ],
        2,
        r"hand\.yaml: max_width: not a finite number",
    ),
    Case(
        "grasps-hand-missing",
        "grasps --hand names no file",
        lambda t: ["grasps", str(box_stl(t)), "--out", str(t / "g.json"), "--hand", "gripper.yaml"],
        2,
        r"'gripper\.yaml' is neither a robot",
    ),
    Case(
        "grasps-seed-negative",
        "grasps --seed -1",
        lambda t: ["grasps", str(box_stl(t)), "--out", str(t / "g.json"), "--seed", "-1"],
        2,
        r"--seed",
    ),
    Case(
        "grasps-mu-nan",
        "grasps --mu nan",
        lambda t: ["grasps", str(box_stl(t)), "--out", str(t / "g.json"), "--mu", "nan"],
        2,
        r"mu",
    ),
    # --- teaching commands
    Case(
        "teach-out-folder",
        "teach --out is a folder",
        lambda t: ["teach", str(config(t)), "--frames", str(t), "--out", str(_mk(t / "o"))],
        2,
        r"is a folder",
    ),
    Case(
        "teach-frames-missing",
        "teach --frames names nothing",
        lambda t: ["teach", str(config(t)), "--frames", str(t / "none"), "--out", str(t / "task.json")],
        2,
        r"no such folder",
    ),
    Case(
        "teach-frames-empty",
        "teach --frames an empty folder",
        lambda t: ["teach", str(config(t)), "--frames", str(_mk(t / "f")), "--out", str(t / "task.json")],
        2,
        r"no images",
    ),
    Case(
        "teach-frame-garbage",
        "teach --frames with a garbage JPEG",
        lambda t: [
            "teach",
            str(config(t)),
            "--frames",
            str(write(t, "f/0001.jpg", b"\xff\xd8junk").parent),
            "--out",
            str(t / "task.json"),
        ],
        2,
        r"JPEG is cut short",
    ),
    Case(
        "teach-frame-truncated",
        "teach --frames with a JPEG cut short (OpenCV decodes it silently)",
        lambda t: ["teach", str(config(t)), "--frames", str(_truncated_jpeg(t / "f")), "--out", str(t / "task.json")],
        2,
        r"0001\.jpg: the JPEG is cut short",
    ),
    Case(
        "render-demo-out-file",
        "render-demo --out is a file",
        lambda t: ["render-demo", str(config(t)), "--out", str(write(t, "o", "x"))],
        2,
        r"is a file",
    ),
    Case(
        "render-demo-no-markers",
        "render-demo of a part without markers",
        lambda t: ["render-demo", str(config(t, edit_structure=_no_markers)), "--out", str(t / "o")],
        2,
        r"no markers",
    ),
    Case(
        "render-demo-typo",
        "render-demo with demo.frame (typo)",
        lambda t: ["render-demo", str(config(t, demo={"frame": 2})), "--out", str(t / "o")],
        2,
        r"demo\.frame",
    ),
    Case(
        "calibrate-out-folder",
        "calibrate --out is a folder",
        lambda t: ["calibrate", "--images", str(t), "--out", str(t)],
        2,
        r"is a folder",
    ),
    Case(
        "calibrate-truncated",
        "calibrate --images with a JPEG cut short",
        lambda t: ["calibrate", "--images", str(_truncated_jpeg(t / "f")), "--out", str(t / "c.yaml")],
        2,
        r"0001\.jpg: the JPEG is cut short",
    ),
    Case(
        "calibrate-board",
        "calibrate --board 7by5",
        lambda t: ["calibrate", "--images", str(t), "--out", str(t / "c.yaml"), "--board", "7by5"],
        2,
        r"--board",
    ),
    # --- detect (its command is the cvfh plugin's; listed here so the table covers every command)
    Case(
        "detect-garbage-pcd",
        "detect in a garbage PCD file",
        lambda t: [
            "detect",
            str(STRUCTURE),
            "--part",
            "a",
            "--cloud",
            str(write(t, "c.pcd", b"junk\x00\x01")),
            "--out",
            str(t / "d.json"),
        ],
        2,
        r"c\.pcd: .*not a PCD",
    ),
    Case(
        "detect-nan-cloud",
        "detect in a PCD whose points are all NaN",
        lambda t: [
            "detect",
            str(STRUCTURE),
            "--part",
            "a",
            "--cloud",
            str(
                write(
                    t,
                    "n.pcd",
                    "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\n"
                    "POINTS 2\nDATA ascii\nnan nan nan\nnan nan nan\n",
                )
            ),
            "--out",
            str(t / "d.json"),
        ],
        2,
        r"n\.pcd holds no finite point",
    ),
    Case(
        "detect-out-under-file",
        "detect --out under a file",
        lambda t: [
            "detect",
            str(STRUCTURE),
            "--part",
            "a",
            "--cloud",
            str(write(t, "c.pcd", b"junk")),
            "--out",
            str(write(t, "f", "x") / "d.json"),
        ],
        2,
        r"is a file",
    ),
    Case(
        "detect-out-folder",
        "detect --out is a folder",
        lambda t: [
            "detect",
            str(STRUCTURE),
            "--part",
            "a",
            "--cloud",
            str(write(t, "c.pcd", b"junk")),
            "--out",
            str(_mk(t / "o")),
        ],
        2,
        r"is a folder",
    ),
    # --- library
    Case(
        "library-out-folder",
        "library --out is a folder",
        lambda t: ["library", str(ROOT / "configs/parts/set1"), "--out", str(t)],
        2,
        r"is a folder",
    ),
    Case(
        "library-empty",
        "library of a folder without parts",
        lambda t: ["library", str(_mk(t / "e")), "--out", str(t / "s.png")],
        2,
        r".",
    ),
    # --- sweeps
    Case(
        "sweep-missing",
        "sweep file does not exist",
        lambda t: ["sweep", str(t / "x.yaml"), "--out", str(t / "o")],
        2,
        r"no such file",
    ),
    Case(
        "sweep-kind",
        "sweep of an unknown kind",
        lambda t: ["sweep", str(experiment(t, "experiment: toy_squar\n")), "--out", str(t / "o")],
        2,
        r"toy_square",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-grid-key",
        "sweep grid key misspelt",
        lambda t: ["sweep", str(experiment(t, "experiment: toy_square\ngrid: {xx: [1]}\n")), "--out", str(t / "o")],
        2,
        r"params\.xx: unknown key",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-grid-value",
        "a typo in the last grid value caught before any trial",
        lambda t: [
            "sweep",
            str(experiment(t, "experiment: toy_square\ngrid: {x: [1, 2, 3x]}\n")),
            "--out",
            str(t / "o"),
        ],
        2,
        r"params\.x.*valid number",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-grid-not-list",
        "sweep grid value not a list",
        lambda t: ["sweep", str(experiment(t, "experiment: toy_square\ngrid: {x: 3}\n")), "--out", str(t / "o")],
        2,
        r"grid\.x",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-seeds-zero",
        "sweep seeds: 0 (no trial at all)",
        lambda t: ["sweep", str(experiment(t, "experiment: toy_square\nseeds: 0\n")), "--out", str(t / "o")],
        2,
        r"seeds",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-seeds-negative",
        "sweep seeds: [-1]",
        lambda t: ["sweep", str(experiment(t, "experiment: toy_square\nseeds: [-1]\n")), "--out", str(t / "o")],
        2,
        r"seeds",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-out-file",
        "sweep --out is a file",
        lambda t: ["sweep", str(experiment(t, SQUARE)), "--out", str(write(t, "o", "x"))],
        2,
        r"is a file",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-workers",
        "sweep --workers 0",
        lambda t: ["sweep", str(experiment(t, SQUARE)), "--out", str(t / "o"), "--workers", "0"],
        2,
        r"--workers",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-all-fail",
        "sweep whose every trial fails",
        lambda t: [
            "sweep",
            str(experiment(t, "experiment: toy_square\nparams: {fail_above: 0}\ngrid: {x: [1.0, 2.0]}\n")),
            "--out",
            str(t / "o"),
        ],
        1,
        r"2 of 2 trials failed.*--retry-failed",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-some-fail",
        "sweep with one failed trial of two",
        lambda t: ["sweep", str(experiment(t, SQUARE.replace("[1.0, 2.0]", "[1.0, 3.0]"))), "--out", str(t / "o")],
        1,
        r"1 of 2 trials failed",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-corpus-part",
        "part_corpus sweep naming a part that does not exist, caught before any trial",
        lambda t: [
            "sweep",
            str(experiment(t, "experiment: part_corpus\nparams: {stage: collision}\ngrid: {part: [tube_1, tub_2]}\n")),
            "--out",
            str(t / "o"),
        ],
        2,
        r"params\.part: no corpus part 'tub_2'.*grid point part='tub_2'",
    ),
    Case(
        "sweep-out-readonly",
        "sweep --out a read-only folder",
        lambda t: ["sweep", str(experiment(t, SQUARE)), "--out", str(t / "ro")],
        2,
        r"cannot write",
        fault=lambda t, mp: readonly(t / "ro", mp),
        needs=("toy_dist",),
    ),
    Case(
        "teach-out-readonly",
        "teach --out in a read-only folder",
        lambda t: ["teach", str(config(t)), "--frames", str(t), "--out", str(t / "ro" / "task.json")],
        2,
        r"cannot write",
        fault=lambda t, mp: readonly(t / "ro", mp),
    ),
    Case(
        "render-demo-out-readonly",
        "render-demo --out a read-only folder",
        lambda t: ["render-demo", str(config(t)), "--out", str(t / "ro")],
        2,
        r"cannot write",
        fault=lambda t, mp: readonly(t / "ro", mp),
    ),
    Case(
        "placements-structure-mesh",
        "placements of a structure whose inline mesh is relative to it (cwd elsewhere): accepted, as in run",
        lambda t: [
            "placements",
            str(structure(t, lambda d: inline_mesh_part(d, "m/" + box_stl(_mk(t / "m")).name))),
            "--out",
            str(t / "p.json"),
            "--no-sheet",
        ],
        0,
        "",
    ),
    Case(
        "placements-com-inside",
        "placements --com inside the part (needed rtree before): accepted",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t / "p.json"), "--com", "0", "0", "0.002", "--no-sheet"],
        0,
        "",
    ),
    Case(
        "sweep-params-nan",
        "sweep params with NaN",
        lambda t: ["sweep", str(experiment(t, "experiment: toy_square\nparams: {x: .nan}\n")), "--out", str(t / "o")],
        2,
        r"params\.x: not a finite number",
        needs=("toy_dist",),
    ),
    Case(
        "run-stage-crash",
        "a stage raising an unforeseen error (the renderer's ValueError)",
        lambda t: _run(t, config(t)),
        1,
        r"bad failed at teach: internal error \(ValueError: no viewing direction",
        fault=lambda t, mp: _crashing_renderer(mp),
    ),
    Case(
        "run-disk-full-in-stage",
        "a full disk while the run writes its demonstration frames (ENOSPC)",
        lambda t: _run(t, config(t)),
        1,
        r"failed at teach: .*frame_0000\.jpg: No space left on device; free some",
        fault=lambda t, mp: _crashing_renderer(
            mp, OSError(errno.ENOSPC, "No space left on device", "demonstration/frame_0000.jpg")
        ),
    ),
    Case(
        "validate-experiment",
        "validate of an experiment file: every grid point checked",
        lambda t: _val(experiment(t, SQUARE)),
        0,
        "",
        needs=("toy_dist",),
    ),
    Case(
        "validate-experiment-bad",
        "validate of an experiment file with a bad grid value",
        lambda t: _val(experiment(t, "experiment: toy_square\ngrid: {x: [1, two]}\n")),
        2,
        r"params\.x: Input should be a valid number",
        needs=("toy_dist",),
    ),
    Case(
        "sweep-concurrent",
        "a second sweep into a folder another sweep is writing",
        lambda t: ["sweep", str(experiment(t, SQUARE)), "--out", str(t / "o")],
        2,
        r"another sweep is writing into this folder",
        fault=lambda t, mp: _hold_sweep_lock(t / "o", mp),
        needs=("toy_dist",),
    ),
    Case(
        "sweep-binary",
        "sweep file is binary",
        lambda t: ["sweep", str(write(t, "e.yaml", b"\x00PK")), "--out", str(t / "o")],
        2,
        r"binary",
    ),
    Case(
        "sweep-full-disk",
        "a full disk while the sweep logs its trials (ENOSPC)",
        lambda t: ["sweep", str(experiment(t, SQUARE)), "--out", str(t / "o")],
        1,
        r"No space left on device",
        fault=lambda t, mp: full_disk(mp),
        needs=("toy_dist",),
    ),
    Case(
        "placements-full-disk",
        "a full disk while placements writes its JSON (ENOSPC)",
        lambda t: ["placements", str(box_stl(t)), "--out", str(t / "p.json"), "--no-sheet"],
        1,
        r"No space left on device",
        fault=lambda t, mp: _full_disk_on_json(mp),
    ),
]


def _mk(path: Path) -> Path:
    path.mkdir(parents=True, exist_ok=True)
    return path


def _part_file(tmp: Path) -> str:
    """``parts/meshy.yaml`` naming ``meshes/box.stl`` relative to itself; returns its path from the structure."""
    mesh = box_stl(_mk(tmp / "parts" / "meshes"))
    data = {"name": "meshy", "mesh": f"meshes/{mesh.name}", "markers": BOX_MARKERS}
    write(tmp, "parts/meshy.yaml", yaml.safe_dump(data))
    return "parts/meshy.yaml"


def _truncated_jpeg(folder: Path) -> Path:
    """A folder with a whole JPEG and one cut to 60 % of its bytes."""
    import cv2

    img = (np.random.default_rng(0).random((120, 160, 3)) * 255).astype(np.uint8)
    ok, buf = cv2.imencode(".jpg", img)
    assert ok
    write(folder, "0000.jpg", buf.tobytes())
    write(folder, "0001.jpg", buf.tobytes()[: int(0.6 * len(buf))])
    return folder


def _other_run(out: Path) -> None:
    write(out, "report.json", '{"config": {"name": "other"}}')
    write(out, "task.json", "{}")


def _interrupted_run(tmp: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--out`` holds an older result of the same config; the run writes a file, then Ctrl-C comes."""
    from asmteach.core import pipeline

    write(tmp, "out/report.json", '{"config": {"name": "bad"}, "old": true}')

    def run(cfg, out, pm=None):
        write(Path(out), "report.json", "{}")
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "run_pipeline", run)


def _crashing_renderer(monkeypatch: pytest.MonkeyPatch, error: Exception | None = None) -> None:
    """The teacher's renderer raises ``error`` (default: the ValueError it raised for a part without markers)."""
    from asmteach.plugins.detectors.aruco.teacher import ArucoTeacher

    def demonstrate(self, task, demo, camera_file=None, out_dir=None):
        raise error or ValueError("no viewing direction shows markers of both parts")

    monkeypatch.setattr(ArucoTeacher, "demonstrate", demonstrate)


def _hold_sweep_lock(out: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Another sweep holds ``out``'s lock (an open file description of this process stands for it)."""
    import fcntl

    fd = os.open(_mk(out) / ".sweep.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    _OPEN_FDS.append(fd)  # closed when the case ends


_OPEN_FDS: list[int] = []


def _full_disk_on_json(monkeypatch: pytest.MonkeyPatch) -> None:
    """The JSON writer's file fails with ENOSPC (as ``write`` does on a full disk)."""
    from asmteach.core import io

    real = io.write_bytes

    def fail(path, data):
        if str(path).endswith(".json"):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, data)

    monkeypatch.setattr(io, "write_bytes", fail)


# ---------------------------------------------------------------- the test
@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_gives_one_line_and_the_right_exit_code(
    case: Case, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture, request
) -> None:
    from asmteach.core.cli import main

    for name in case.needs:
        request.getfixturevalue(name)
    work = _mk(tmp_path / "w")
    monkeypatch.chdir(_mk(tmp_path / "elsewhere"))  # paths must not depend on the working directory
    argv = case.argv(work)
    if case.fault is not None:
        case.fault(work, monkeypatch)
    try:
        code = main(argv)
    finally:
        monkeypatch.undo()  # before the tmp folder is cleaned up (a read-only folder must be writable again)
        while _OPEN_FDS:
            os.close(_OPEN_FDS.pop())
        for p in work.rglob("*"):
            if p.is_dir():
                p.chmod(0o755)
    err = capsys.readouterr().err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("asmteach:")]
    if os.environ.get("ASMTEACH_CASES_LOG"):  # outcomes for the results doc (see markdown_table)
        with open(os.environ["ASMTEACH_CASES_LOG"], "a") as fh:
            fh.write(
                json.dumps({"id": case.id, "code": code, "line": lines[0] if lines else "", "work": str(work)}) + "\n"
            )
    assert code == case.code, f"exit {code}, stderr: {err}"
    if case.code == 0:
        assert not lines, err
        return
    assert len(lines) == 1, err
    others = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("asmteach:", "WARNING", "pybullet"))]
    if not (argv[0] == "run" and code == 1):  # a run that started shows its progress display on stderr too
        assert not others, err  # nothing but the one line (and log warnings)
    assert re.search(case.says, lines[0], re.IGNORECASE), lines[0]
    if case.id == "run-stage-crash":  # the run still wrote its report, with the traceback
        report = json.loads((work / "out" / "report.json").read_text())
        assert report["failed_stage"] == "teach" and "ValueError" in report["stages"][0]["details"]["traceback"]
        assert report["failure_cause"] == "teach"  # an exception that is no StageFailed: the cause by stage
    if case.id == "run-interrupted":
        assert sorted(p.name for p in (work / "out").iterdir()) == ["report.json"]
        assert '"old"' in (work / "out" / "report.json").read_text()


def test_the_table_covers_at_least_sixty_cases() -> None:
    assert len(CASES) >= 60 and len({c.id for c in CASES}) == len(CASES)


def test_run_into_a_used_folder_replaces_it_whole_or_not_at_all(tmp_path: Path, monkeypatch) -> None:
    """An interrupted run leaves --out as it was; a finished one replaces the same run's results whole."""
    from asmteach.core.io import run_folder

    out = tmp_path / "out"
    write(out, "report.json", '{"config": {"name": "demo"}}')
    write(out, "frame_0041.jpg", "old")
    with pytest.raises(KeyboardInterrupt), run_folder(out, "demo") as stage:
        write(stage, "report.json", '{"config": {"name": "demo"}}')
        raise KeyboardInterrupt
    assert sorted(p.name for p in out.iterdir()) == ["frame_0041.jpg", "report.json"]  # as it was
    with run_folder(out, "demo") as stage:
        write(stage, "report.json", '{"config": {"name": "demo"}, "new": 1}')
    assert sorted(p.name for p in out.iterdir()) == ["report.json"]  # no stale frame mixed in
    assert '"new"' in (out / "report.json").read_text()
    # a staging folder left by a run killed with -9 (its pid gone) is removed by the next run
    dead = _mk(out / ".partial-999999999")
    with run_folder(out, "demo") as stage:
        write(stage, "report.json", '{"config": {"name": "demo"}}')
    assert not dead.exists()
    with pytest.raises(Exception, match="--force"), run_folder(out, "other"):
        pass
    with run_folder(out, "other", force=True) as stage:
        write(stage, "report.json", '{"config": {"name": "other"}}')
    assert '"other"' in (out / "report.json").read_text()


def test_a_camera_file_without_distortion_is_named(tmp_path: Path, caplog) -> None:
    from asmteach.core.config import load_run_config
    from asmteach.plugins.detectors.aruco.commands import resolve_camera

    cam = write(
        tmp_path,
        "cam.yaml",
        "\n".join(ln for ln in CAMERA.read_text().splitlines() if not ln.startswith("distortion")) + "\n",
    )
    cfg = load_run_config(config(tmp_path, camera=cam.name), check_plugins=False)
    camera, _ = resolve_camera(None, cfg, None)
    assert np.allclose(camera.dist, 0.0)
    assert any("no distortion_coefficients" in r.getMessage() for r in caplog.records)


def markdown_table(outcomes: dict[str, dict]) -> str:
    """The cases and their outcomes (``id -> {code, line, work}`` from a run with ``ASMTEACH_CASES_LOG``) as a
    markdown table for docs/results/reliability.md; the cases' temporary folder is written ``<tmp>``."""
    rows = ["| # | input or fault | command | exit | the line printed |", "|---|---|---|---|---|"]
    tmp = Path(tempfile.mkdtemp())
    try:
        for i, c in enumerate(CASES, 1):
            try:
                cmd = c.argv(_mk(tmp / c.id))[0]
            except Exception:  # noqa: BLE001 - a case needing a fixture still has a command name
                cmd = "sweep"
            got = outcomes.get(c.id, {})
            line = got.get("line", "").replace(got.get("work", "<none>"), "<tmp>").removeprefix("asmteach: error: ")
            line = line.replace(str(ROOT) + "/", "").replace("|", "\\|") or "(none: accepted)"
            mark = "" if got.get("code") == c.code else f" (expected {c.code})"
            rows.append(f"| {i} | {c.what} | `{cmd}` | {got.get('code', '?')}{mark} | {line} |")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    # python tests/core/test_bad_inputs.py OUTCOMES.jsonl  (written by ASMTEACH_CASES_LOG=... pytest this file)
    found = {}
    for ln in Path(sys.argv[1]).read_text().splitlines():
        rec = json.loads(ln)
        found[rec["id"]] = rec
    sys.stdout.write(markdown_table(found))
