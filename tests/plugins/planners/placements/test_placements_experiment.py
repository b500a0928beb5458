"""The placements_vs_trimesh experiment on a small subset: targets and summary files."""

from __future__ import annotations

from pathlib import Path

import pytest

from asmteach.plugins.planners.placements.experiment import PlacementsVsTrimesh

REPO = Path(__file__).resolve().parents[4]


@pytest.mark.slow
def test_subset_meets_targets(tmp_path: Path) -> None:
    exp = PlacementsVsTrimesh(REPO / "configs/experiments")
    params = exp.Params.model_validate(
        {"structures": ["../parts/set1/t_slot.yaml"], "pybullet_meshes": ["lego/lego.obj"], "repeats": 1}
    )
    metrics = exp.run_trial(params, 0, tmp_path)
    assert metrics["meshes_compared"] == 3
    assert metrics["missed_total"] == 0
    assert metrics["ours_unstable_total"] == 0
    lego = next(m for m in metrics["meshes"] if m["mesh"] == "lego")
    assert lego["trimesh_below_margin"] > 0 and "margin" in lego["why"]
    paths = exp.summarize([{"ok": True, "metrics": metrics}], tmp_path)
    assert {p.name for p in paths} == {"placements_vs_trimesh.md", "placements_vs_trimesh.csv"}
    assert metrics["speedup_min"] > 0.0 and metrics["cpu_speedup_min"] > 0.0
    assert all(m["ms_ours"] > 0.0 and m["cpu_ms_trimesh"] >= 0.0 for m in metrics["meshes"])
    text = (tmp_path / "placements_vs_trimesh.md").read_text()
    assert "trimesh / ours" in text and "per mesh at least" in text
