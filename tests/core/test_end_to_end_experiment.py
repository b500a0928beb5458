"""The end_to_end experiment runs the pipeline of a run config per seed and records its outcome."""

from pathlib import Path

import pytest
import yaml

from asmteach.core import pipeline
from asmteach.core.end_to_end import EndToEnd
from asmteach.core.failures import FailureCause
from asmteach.core.models import RunReport, StageOutcome

ROOT = Path(__file__).resolve().parents[2]


def test_trial_runs_the_config_with_the_trial_seed_and_records_the_failure(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "run.yaml").write_text(
        yaml.safe_dump({"name": "t", "seed": 1, "structure": str(ROOT / "configs/parts/set1/peg_in_hole.yaml")})
    )
    seen = {}

    def fake_run(cfg, out_dir, pm=None):
        seen.update(seed=cfg.seed, animation=cfg.execution.animation, out=out_dir)
        return RunReport(
            config={},
            seed=cfg.seed,
            success=False,
            failed_stage="plan",
            reason="no grasp shared",
            failure_cause=FailureCause.REGRASP_GRAPH,
            stages=[
                StageOutcome(stage="teach", ok=True, seconds=2.0),
                StageOutcome(stage="plan", ok=False, seconds=1.5, reason="no grasp shared"),
            ],
            metrics={"a_goal_error_mm": 1.25},
        )

    monkeypatch.setattr(pipeline, "run_pipeline", fake_run)
    exp = EndToEnd(tmp_path)
    row = exp.run_trial(exp.Params(run_config="run.yaml"), 17, tmp_path / "trial")
    assert seen["seed"] == 17 and seen["animation"] is False and seen["out"] == tmp_path / "trial" / "run"
    assert row == {
        "success": False,
        "failed_stage": "plan",
        "failure_cause": "regrasp_graph",
        "reason": "no grasp shared",
        "a_goal_error_mm": 1.25,
        "teach_seconds": 2.0,
        "plan_seconds": 1.5,
    }
