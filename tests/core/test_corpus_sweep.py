"""The ``part_corpus`` experiment: a user's STL per part, each stage measured by the plugin that owns it."""

from __future__ import annotations

from pathlib import Path

import pytest

from asmteach.core.corpus_sweep import PartCorpus, PartCorpusParams, passed
from asmteach.core.errors import UserError


@pytest.mark.slow
def test_collision_and_placements_of_one_part_through_its_cad_stl(tmp_path: Path) -> None:
    exp = PartCorpus(tmp_path)
    rows = []
    for stage in ("collision", "placements"):
        m = exp.run_trial(PartCorpusParams(part="prism_slot_0", stage=stage), seed=0, workdir=tmp_path / stage)
        assert m["part"] == "prism_slot_0" and m["family"] == "prism_slot" and m["stage"] == stage
        rows.append({"ok": True, "metrics": m, "point": {"stage": stage}})
    collision, placements = rows[0]["metrics"], rows[1]["metrics"]
    assert collision["method"] == "plane_split" and collision["protrusion_mm"] < 0.1 and collision["passed"]
    assert placements["reported"] >= 4 and placements["agree"] and placements["passed"]
    paths = exp.summarize(rows, tmp_path)
    text = (tmp_path / "part_corpus.md").read_text()
    assert "prism_slot_0" in text and "collision**: 1/1" in text and len(paths) == 2


def test_an_unknown_part_is_a_user_error(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="families"):
        PartCorpus(tmp_path).run_trial(PartCorpusParams(part="gear_0", stage="collision"), seed=0, workdir=tmp_path)


def test_targets_per_stage() -> None:
    assert passed("grasps", {"fits_hand": True, "holding": 30, "reason": ""})
    assert not passed("grasps", {"fits_hand": True, "holding": 29, "reason": ""})
    assert passed("grasps", {"fits_hand": False, "holding": 0, "reason": "too wide for the hand: ..."})
    assert not passed("detection", {"wrong_found": 1, "success": 5, "scenes": 5})
    assert passed("detection", {"wrong_found": 0, "success": 5, "scenes": 5})
    assert not passed("collision", {"protrusion_mm": 0.3, "max_protrusion_mm": 0.1})


def test_the_detection_sweep_config_detects_as_a_run_does() -> None:
    """configs/experiments/part_corpus_detection.yaml: the detection stage of every corpus part, with a run's four
    stacked Kinect frames and two wrist looks (the defaults, written out)."""
    import yaml

    from asmteach.core.corpus import part_corpus
    from asmteach.core.corpus_sweep import PartCorpusParams

    root = Path(__file__).resolve().parents[2]
    cfg = yaml.safe_load((root / "configs/experiments/part_corpus_detection.yaml").read_text())
    assert cfg["experiment"] == "part_corpus"
    params = PartCorpusParams(**cfg["params"])
    assert params.stage == "detection" and params.frames == 4 and params.close_looks == 2
    assert PartCorpusParams(part="tube_0", stage="detection").frames == params.frames
    assert sorted(cfg["grid"]["part"]) == sorted(p.name for p in part_corpus(seed=0))
