"""The execution trace records every motion that moved or toppled a part no hand held, with the robot's clock."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from asmteach.core.models import GripperEvent, Plan, PlanSegment, Trajectory
from asmteach.core.pipeline.monitor import ExecutionTrace, plan_parts


class _World:
    """Parts at poses the test sets; one arm whose TCP is the identity."""

    def __init__(self) -> None:
        self.poses = {"block": np.eye(4), "peg": np.eye(4)}

    def part_pose(self, name: str) -> np.ndarray:
        return self.poses[name].copy()

    def current(self, arm: str) -> np.ndarray:
        return np.zeros(2)

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        return np.eye(4)


def _traj(seconds: float) -> Trajectory:
    return Trajectory(arm="a", joint_names=["j0", "j1"], times=[0.0, seconds], positions=np.zeros((2, 2)))


def _tipped(deg: float) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    T[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    return T


def test_a_free_part_moved_or_toppled_by_a_motion_is_an_event_with_its_time() -> None:
    world = _World()
    trace = ExecutionTrace(world, ["block", "peg"], t0_s=10.0)  # type: ignore[arg-type]
    trace.before_grip("close on peg", "a", True, "peg")
    trace.after_grip("a", True, "peg")
    trace.before_path()
    trace.after_path(_traj(2.0), "carry peg", "transit")  # nothing moved
    trace.before_path()
    world.poses["block"][:3, 3] = [0.08, 0.0, 0.0]  # the block is shoved 80 mm while the peg goes in
    world.poses["peg"][:3, 3] = [0.5, 0.0, 0.0]  # the held peg moves with the hand: not an event
    trace.after_path(_traj(1.5), "insert peg", "insertion", seconds=3.0)
    trace.before_path()
    world.poses["block"] = _tipped(35.0) @ world.poses["block"]
    trace.after_path(_traj(1.0), "retreat", "approach")
    moved = [e for e in trace.events if "pushed_mm" in e]
    assert [(e["part"], e["by"], e["t_s"], e["toppled"]) for e in moved] == [
        ("block", "insert peg", 12.0, False),
        ("block", "retreat", 15.0, True),
    ]
    assert moved[0]["pushed_mm"] == 80.0 and moved[0]["holding"] == "peg"
    assert abs(moved[1]["tilted_deg"] - 35.0) < 1e-6
    assert trace.t_s == 16.0  # the insertion's own seconds, not its trajectory's


def test_the_plan_names_its_parts_in_order() -> None:
    plan = Plan(
        segments=[
            PlanSegment(label="move", trajectory=_traj(1.0), part="block"),
            PlanSegment(label="close", gripper=GripperEvent(arm="a", action="close", attach="peg")),
            PlanSegment(label="carry", trajectory=_traj(1.0), part="peg"),
        ]
    )
    assert plan_parts(plan) == ["block", "peg"]


def test_an_insertion_that_stops_short_fails_the_execute_stage_as_a_jam(monkeypatch: pytest.MonkeyPatch) -> None:
    """The plan goes on from where the insertion should have ended: the stage stops with the jam's evidence."""
    from asmteach.core.arm.insertion_records import InsertionOutcome
    from asmteach.core.failures import FailureCause
    from asmteach.core.models import RunReport
    from asmteach.core.pipeline import execute
    from asmteach.core.pipeline.stage import StageFailed

    world = _World()
    trace = ExecutionTrace(world, ["block", "peg"], t0_s=40.0)  # type: ignore[arg-type]
    trace.before_grip("close on peg", "a", True, "peg")
    trace.after_grip("a", True, "peg")
    stuck = InsertionOutcome(inserted=False, depth_m=0.006, length_m=0.015, reason="still resisted")
    stuck.contacts = []
    report = RunReport(config={}, seed=0)
    seg = PlanSegment(label="insert peg at assembled", trajectory=_traj(1.0), kind="insertion")
    monkeypatch.setattr(
        execute, "guarded_insert", lambda robot, traj, part, other, line_end=None, centre_tcp=None: stuck
    )
    run = SimpleNamespace(report=report, symmetries=lambda part: [], execution=SimpleNamespace(in_hand="measure"))
    with pytest.raises(StageFailed) as failed:
        execute._insert(run, world, seg, trace, {})  # type: ignore[arg-type]
    assert failed.value.cause is FailureCause.JAM
    assert failed.value.reason.startswith(
        "peg jammed at 6.0 of 15.0 mm depth in 'insert peg at assembled' at t = 40.0 s"
    )
    assert report.failure_details["event"]["insertion"]["depth_mm"] == 6.0


@pytest.mark.parametrize("mode", ["off", "measure", "reaim"])
def test_the_look_in_the_hand_reaims_only_when_asked(monkeypatch: pytest.MonkeyPatch, mode: str) -> None:
    """``execution.in_hand``: 'off' does not look, 'measure' looks and runs the planned line, 'reaim' re-aims it."""
    from asmteach.core.arm.insertion_records import InsertionOutcome
    from asmteach.core.models import RunReport
    from asmteach.core.pipeline import execute

    world = _World()
    trace = ExecutionTrace(world, ["block", "peg"], t0_s=40.0)  # type: ignore[arg-type]
    trace.before_grip("close on peg", "a", True, "peg")
    trace.after_grip("a", True, "peg")
    looked: list[str] = []
    aimed = np.eye(4)
    aimed[0, 3] = 0.003
    measured = SimpleNamespace(T_world_part=np.eye(4), chi2=lambda T: 1000.0)
    monkeypatch.setattr(execute, "_measure_in_hand", lambda *a: looked.append("look") or measured)
    monkeypatch.setattr(execute, "_line_end", lambda *a: aimed)
    monkeypatch.setattr(execute, "_compliance_centre", lambda *a: None)
    got: dict[str, object] = {}

    def insert(robot, traj, part, other, line_end=None, centre_tcp=None):  # type: ignore[no-untyped-def]
        got["line_end"] = line_end
        return InsertionOutcome(inserted=True, depth_m=0.015, length_m=0.015, reason=None)

    monkeypatch.setattr(execute, "guarded_insert", insert)
    run = SimpleNamespace(
        report=RunReport(config={}, seed=0), symmetries=lambda part: [], execution=SimpleNamespace(in_hand=mode)
    )
    seg = PlanSegment(label="insert peg at assembled", trajectory=_traj(1.0), kind="insertion")
    execute._insert(run, world, seg, trace, {})  # type: ignore[arg-type]
    assert looked == ([] if mode == "off" else ["look"])
    assert (got["line_end"] is aimed) == (mode == "reaim")
