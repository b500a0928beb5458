"""``asmteach placements`` in-process: outputs, exit codes and messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core.cli import main

REPO = Path(__file__).resolve().parents[4]


def test_mesh_file_writes_json_and_sheet(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mesh = tmp_path / "block.stl"
    trimesh.creation.box(extents=(0.08, 0.05, 0.03)).export(mesh)
    out = tmp_path / "placements.json"
    assert main(["placements", str(mesh), "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert len(data["placements"]) == 6
    for p in data["placements"]:
        T = np.asarray(p["T_table_part"])
        assert T.shape == (4, 4)
        assert 0.0 <= p["probability"] <= 1.0 and p["margin"] >= 0.1
    assert (tmp_path / "placements.png").stat().st_size > 1000
    assert "6 stable placements" in capsys.readouterr().out


def test_structure_yaml_gives_both_parts(tmp_path: Path) -> None:
    out = tmp_path / "lc.json"
    assert main(["placements", str(REPO / "configs/parts/set1/l_corner.yaml"), "--out", str(out), "--no-sheet"]) == 0
    data = json.loads(out.read_text())
    assert [p["part"] for p in data["parts"]] == ["l_block", "cube"]


def test_millimetre_mesh_is_detected(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mesh = tmp_path / "mm.stl"
    trimesh.creation.box(extents=(80.0, 50.0, 30.0)).export(mesh)
    out = tmp_path / "p.json"
    assert main(["placements", str(mesh), "--out", str(out)]) == 2
    assert "millimetres" in capsys.readouterr().err
    assert not out.exists()
    assert main(["placements", str(mesh), "--units", "mm", "--out", str(out), "--no-sheet"]) == 0


def test_flat_mesh_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # A two-triangle sheet is refused by the mesh loader (not a solid), a closed box of no thickness by
    # the planner (flat); both exit 2 with the cause, no traceback.
    sheet = tmp_path / "sheet.stl"
    trimesh.Trimesh([[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0], [0, 0.1, 0]], [[0, 1, 2], [0, 2, 3]]).export(sheet)
    assert main(["placements", str(sheet), "--out", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err
    assert "not a solid" in err and "Traceback" not in err
    flat = tmp_path / "flat.stl"
    trimesh.creation.box(extents=(0.1, 0.1, 1e-9)).export(flat)
    assert main(["placements", str(flat), "--out", str(tmp_path / "p.json")]) == 2
    err = capsys.readouterr().err
    assert "flat or degenerate" in err and "Traceback" not in err


def test_com_outside_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mesh = tmp_path / "cube.stl"
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(mesh)
    assert main(["placements", str(mesh), "--com", "0.2", "0", "0", "--out", str(tmp_path / "p.json")]) == 2
    assert "outside" in capsys.readouterr().err


def test_open_mesh_warns_and_is_repaired(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    box = trimesh.creation.box(extents=(0.07, 0.05, 0.03))
    mesh = tmp_path / "open.stl"
    trimesh.Trimesh(box.vertices, box.faces[:-2]).export(mesh)
    out = tmp_path / "p.json"
    assert main(["placements", str(mesh), "--out", str(out), "--no-sheet"]) == 0
    # The loader fills the missing side (core.mesh_repair) and says so.
    assert any("filled 1 hole" in r.getMessage() for r in caplog.records)
    assert len(json.loads(out.read_text())["placements"]) == 6


def test_missing_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["placements", str(tmp_path / "nope.stl"), "--out", str(tmp_path / "p.json")]) == 2
    assert "no such file" in capsys.readouterr().err
