"""The part-corpus detection measure: seeded scenes of one part, scored symmetry-aware."""

from __future__ import annotations

from pathlib import Path

from asmteach.core.parts import build_part, load_structure
from asmteach.plugins.detectors.cvfh.corpus_measure import asmteach_measure_part

STRUCTURE = Path(__file__).resolve().parents[4] / "configs/parts/set1/peg_in_hole.yaml"


def test_a_plain_part_is_found_in_its_scenes(tmp_path: Path) -> None:
    part = build_part(load_structure(STRUCTURE).part_a)
    out = asmteach_measure_part(part=part, stage="detection", seed=0, workdir=tmp_path, options={"scenes": 2})
    assert out is not None and out["scenes"] == 2
    assert out["success"] == 2 and out["wrong_found"] == 0
    assert out["max_pos_mm_found"] <= 5.0 and out["max_rot_deg_found"] <= 5.0
    assert asmteach_measure_part(part=part, stage="grasps", seed=0, workdir=tmp_path, options={}) is None
