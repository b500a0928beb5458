"""A failed run's report.json names its cause (FailureCause), decided by the failing stage, not from its reason."""

import json
from pathlib import Path

import pytest
import yaml

from asmteach.core.cli import main
from asmteach.core.failures import FailureCause
from asmteach.core.models import Detection, RunReport
from asmteach.core.pipeline import detect as detect_module

ROOT = Path(__file__).resolve().parents[3]
STRUCTURE = ROOT / "configs/parts/set1/peg_in_hole.yaml"


def _run(tmp_path: Path) -> dict:
    cfg = tmp_path / "run.yaml"
    # six demonstration frames, not thirty: the run only has to get to the stage that fails
    cfg.write_text(yaml.safe_dump({"name": "t", "seed": 3, "structure": str(STRUCTURE), "demo": {"frames": 6}}))
    out = tmp_path / "out"
    assert main(["run", str(cfg), "--out", str(out)]) == 1
    report = json.loads((out / "report.json").read_text())
    RunReport.model_validate(report)  # the cause reads back as the enum
    return report


def test_a_detection_that_lists_rivals_is_ambiguous_else_not_found() -> None:
    def det(details: dict) -> Detection:
        return Detection(part="p", found=False, reason="ambiguous: the reason is never read", details=details)

    assert detect_module.not_found_cause(det({})) is FailureCause.DETECT_NOT_FOUND
    assert detect_module.not_found_cause(det({"ambiguous": [{"fitness": 0.9}]})) is FailureCause.DETECT_AMBIGUOUS


def test_a_part_not_found_fails_the_run_with_its_detections_cause(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    def not_found(detector, corrector, cloud, part, table, **kwargs: object) -> Detection:
        # the reason says neither word: the cause comes from the detection's details alone
        return Detection(part=part.name, found=False, reason="nothing verified", details={"ambiguous": [{}]})

    monkeypatch.setattr(detect_module, "detect_and_correct", not_found)
    report = _run(tmp_path)
    assert report["failed_stage"] == "detect" and report["failure_cause"] == "detect_ambiguous"
    assert report["reason"].endswith("not found: nothing verified")


def test_a_part_without_grasps_is_recorded_as_no_grasp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from asmteach.core.pipeline.stage import Run

    real = Run.plugin

    class NoGrasps:
        def plan(self, part, hand) -> list:
            return []

    monkeypatch.setattr(Run, "plugin", lambda run, key: NoGrasps() if key == "grasp_planner" else real(run, key))
    report = _run(tmp_path)
    assert report["failed_stage"] == "grasps" and report["failure_cause"] == "no_grasp"
    assert [s["stage"] for s in report["stages"]][-1] == "grasps"


def test_a_failed_assembly_plan_records_the_planners_cause(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from asmteach.core.interfaces import AssemblyResult
    from asmteach.core.models import Plan
    from asmteach.core.pipeline.stage import Run

    real = Run.plugin

    class CutGraph:
        def plan(self, problem, robot, motion, progress=None) -> AssemblyResult:
            # the reason's words would read as a motion failure: only the result's cause may decide
            return AssemblyResult(False, Plan(), reason="motion path IK", cause=FailureCause.REGRASP_GRAPH)

        def write_figures(self, result, out_dir) -> dict:
            return {}

    monkeypatch.setattr(Run, "plugin", lambda run, key: CutGraph() if key == "assembly_planner" else real(run, key))
    report = _run(tmp_path)
    assert report["failed_stage"] == "plan" and report["failure_cause"] == "regrasp_graph"
