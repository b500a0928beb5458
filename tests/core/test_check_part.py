"""``asmteach check-part``: one line per finding, units guessed, repairs named, every stage heard from."""

from __future__ import annotations

from pathlib import Path

import pytest

from asmteach.core.cli import main
from asmteach.core.corpus import corpus_part, write_cad_stl


@pytest.mark.slow
def test_a_cad_stl_is_checked_stage_by_stage(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stl = write_cad_stl(corpus_part("prism_slot_0").mesh, tmp_path / "slotted.stl", open_faces=2, seed=3)
    code = main(["check-part", str(stl), "--out", str(tmp_path / "pics")])
    out = capsys.readouterr().out
    assert code == 0, out
    assert "guessed mm" in out
    assert "filled 2 hole(s)" in out
    assert "symmetry   2 proper rotations" in out  # a slotted block: the half-turn about the slot's axis
    assert "convex pieces" in out and "protrusion" in out
    assert "stable placements" in out and (tmp_path / "pics" / "slotted_placements.png").is_file()
    assert "grasps" in out
    assert out.strip().endswith("every stage can use this part")


def test_a_file_that_is_not_a_mesh_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "part.stl"
    bad.write_text("solid nothing\nendsolid nothing\n")
    assert main(["check-part", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "part.stl" in err[0]
    assert main(["check-part", str(tmp_path / "missing.stl")]) == 2
