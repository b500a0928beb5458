"""The detection stage of the part_corpus experiment: seeded scenes of a user's STL, symmetry-aware errors."""

from __future__ import annotations

from pathlib import Path

from asmteach.core.corpus_sweep import PartCorpus, PartCorpusParams


def test_a_hex_peg_given_as_cad_stl_is_found_in_its_scenes_up_to_its_symmetry(tmp_path: Path) -> None:
    m = PartCorpus(tmp_path).run_trial(PartCorpusParams(part="hex_peg_0", stage="detection", scenes=2),
                                       seed=0, workdir=tmp_path)
    assert m["scenes"] == 2 and m["wrong_found"] == 0
    assert m["success"] == 2 and m["passed"], m
    assert m["max_pos_mm_found"] < 5.0 and m["max_rot_deg_found"] < 5.0
