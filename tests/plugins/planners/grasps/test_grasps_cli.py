"""``asmteach grasps`` in-process: JSON and PNG out, one-line errors with exit code 2 on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from asmteach.core.cli import main

REPO = Path(__file__).resolve().parents[4]


@pytest.fixture
def hand_file(hand, tmp_path) -> Path:
    p = tmp_path / "hand.yaml"
    p.write_text(yaml.safe_dump(hand.model_dump(mode="json")))
    return p


def _run(args: list[str], capsys) -> tuple[int, str, str]:
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_mesh_file_to_json_and_png(hand_file, tmp_path, capsys) -> None:
    mesh = tmp_path / "block.stl"
    trimesh.creation.box([0.04, 0.05, 0.03]).export(mesh)
    out = tmp_path / "res" / "grasps.json"
    code, stdout, _ = _run(["grasps", str(mesh), "--out", str(out), "--hand", str(hand_file), "--no-cache"], capsys)
    assert code == 0, stdout
    doc = json.loads(out.read_text())
    assert doc["units"] == "m" and doc["hand"]["name"] == "test_2f"
    (rec,) = doc["parts"]
    assert rec["name"] == "block" and len(rec["grasps"]) >= 40
    for e in rec["grasps"]:
        assert set(e) == {"id", "p0", "p1", "R", "width", "score"}
        R = np.array(e["R"])
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-6)
        assert e["width"] == pytest.approx(np.linalg.norm(np.subtract(e["p1"], e["p0"])), abs=1e-6)
        assert min(abs(e["width"] - w) for w in (0.04, 0.05, 0.03)) < 1e-5
    assert (tmp_path / "res" / "grasps.png").stat().st_size > 10_000


def test_mm_mesh_with_units_flag(hand_file, tmp_path, capsys) -> None:
    mesh = tmp_path / "block_mm.stl"
    trimesh.creation.box([40.0, 50.0, 30.0]).export(mesh)
    out = tmp_path / "g.json"
    code, _, err = _run(["grasps", str(mesh), "--out", str(out), "--hand", str(hand_file), "--no-cache"], capsys)
    assert code == 2 and "millimetres" in err and "--units mm" in err and "Traceback" not in err
    code, _, _ = _run(
        ["grasps", str(mesh), "--units", "mm", "--out", str(out), "--hand", str(hand_file), "--no-cache"], capsys
    )
    assert code == 0
    widths = {round(e["width"], 4) for e in json.loads(out.read_text())["parts"][0]["grasps"]}
    assert widths <= {0.04, 0.05, 0.03}


def test_structure_yaml_one_part(hand_file, tmp_path, capsys) -> None:
    out = tmp_path / "cube.json"
    args = ["grasps", str(REPO / "configs/parts/set1/l_corner.yaml"), "--part", "cube", "--out", str(out)]
    code, _, _ = _run([*args, "--hand", str(hand_file), "--no-cache"], capsys)
    assert code == 0
    (rec,) = json.loads(out.read_text())["parts"]
    assert rec["name"] == "cube" and len(rec["grasps"]) >= 40
    code, _, err = _run([*args[:2], "--part", "lid", "--out", str(out), "--hand", str(hand_file)], capsys)
    assert code == 2 and "lid" in err


def _open_box(path: Path) -> None:
    m = trimesh.creation.box([0.04, 0.04, 0.04])
    m.update_faces(np.arange(len(m.faces)) > 1)
    m.export(path)


@pytest.mark.parametrize(
    ("writer", "message"),
    [
        (lambda p: trimesh.creation.box([0.15, 0.12, 0.10]).export(p), "no graspable width"),
        (lambda p: trimesh.creation.box([0.06, 0.06, 0.0008]).export(p), "thin shell"),
        (_open_box, "open shell"),
    ],
)
def test_bad_meshes_exit_2(writer, message, hand_file, tmp_path, capsys) -> None:
    mesh = tmp_path / "bad.stl"
    writer(mesh)
    code, _, err = _run(["grasps", str(mesh), "--out", str(tmp_path / "g.json"), "--hand", str(hand_file)], capsys)
    assert code == 2
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "g.json").exists()


def test_hand_from_a_registered_robot_or_refused_in_one_line(tmp_path) -> None:
    """``--hand`` names a robot plugin (the grasp planner imports no robot module) or a HandSpec file."""
    from asmteach.core.errors import UserError
    from asmteach.plugins.planners.grasps.commands import load_hand

    nextage = load_hand("nextage")
    assert nextage.model_dump_json() == load_hand("nextage_pybullet").model_dump_json()
    assert nextage.name == "nextage_2f85" and nextage.max_width == pytest.approx(0.085)
    with pytest.raises(UserError, match=r"neither a robot \(.*nextage_pybullet.*\) nor an existing HandSpec"):
        load_hand(str(tmp_path / "no_such_hand.yaml"))
