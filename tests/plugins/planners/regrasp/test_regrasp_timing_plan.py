"""Plan timing: kinds of motion, both robot clocks in the plan's stats, the insertion's set speed."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.core.models import GripperEvent
from asmteach.plugins.planners.regrasp.plan_io import robot_seconds, segment_kinds, to_plan
from asmteach.plugins.planners.regrasp.realise import Step

LABELS = [
    "move to pre-grasp 3 of peg at start",
    "approach grasp 3",
    "close on peg",
    "lift peg",
    "carry peg to placement2_yaw90",
    "place peg at placement2_yaw90",
    "release peg",
    "retreat",
    "left arm home",
    "move to pre-grasp 7 of peg at placement2_yaw90",
    "approach grasp 7",
    "close on peg",
    "lift peg",
    "carry peg to assembled",
    "insert peg at assembled",
    "release peg",
    "retreat",
    "right arm home",
]


def test_segment_kinds_split_a_plan_with_one_regrasp() -> None:
    assert segment_kinds(LABELS) == [
        "transit",
        "approach",
        "gripper",
        "approach",
        "transit",
        "regrasp",
        "regrasp",
        "regrasp",
        "regrasp",
        "regrasp",
        "regrasp",
        "regrasp",
        "regrasp",
        "transit",
        "insertion",
        "gripper",
        "approach",
        "transit",
    ]
    # A placed at its goal is no regrasp; a relocated middle placement is
    assert segment_kinds(["place block at goal", "retreat"]) == ["approach", "approach"]
    assert segment_kinds(["place block at placement0_yaw0_at450_10", "retreat"]) == ["regrasp", "regrasp"]


def test_robot_seconds_sum_by_kind() -> None:
    out = robot_seconds([1.0, 2.0, 0.0, 0.5], ["transit", "regrasp", "gripper", "transit"])
    assert out == {"total": 3.5, "transit": 1.5, "approach": 0.0, "insertion": 0.0, "regrasp": 2.0}


class _Robot:
    """Three joints that move the TCP 0.1 m per radian along x (a straight line for any joint path)."""

    def speed_limits(self, arm: str) -> np.ndarray:
        return np.array([1.0, 0.8, 1.2])

    def joint_names(self, arm: str) -> list[str]:
        return ["j0", "j1", "j2"]

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[0, 3] = 0.1 * float(np.sum(q))
        return T


def _steps() -> list[Step]:
    s = np.linspace(0.0, 1.0, 15)[:, None]
    curve = np.hstack([0.4 * s, 0.3 * np.sin(2 * s), 0.2 * s**2])  # a dense, curved path
    free = np.array([[0.0, 0.0, 0.0], [0.6, 0.2, 0.0], [0.9, 0.8, 0.3], [0.4, 1.0, 0.6]])  # a few sharp corners
    line = np.linspace([0.4, 1.0, 0.6], [0.45, 1.05, 0.65], 12)  # 0.015 rad x3 joints -> 15 mm of TCP
    return [
        Step("move to pre-grasp 1 of peg at start", "path", "left", free),
        Step("close on peg", "gripper", "left", event=GripperEvent(arm="left", action="close", attach="peg")),
        Step("lift peg", "path", "left", curve),
        Step("insert peg at assembled", "path", "left", line),
        Step("release peg", "gripper", "left", event=GripperEvent(arm="left", action="open")),
    ]


def test_to_plan_records_both_clocks_and_toppra_is_shorter_on_the_same_paths() -> None:
    robot = _Robot()
    new = to_plan(_steps(), robot, 2.0)
    old = to_plan(_steps(), robot, 2.0, timing="trapezoid")
    assert [s.kind for s in new.segments] == ["transit", "gripper", "approach", "insertion", "gripper"]
    # the trapezoid figure recorded with the new timing is the old timing's, on the same paths
    assert new.stats["robot_seconds_trapezoid"] == old.stats["robot_seconds"]
    assert old.stats["robot_seconds"]["total"] == pytest.approx(old.stats["execution_seconds"], abs=2e-3)
    assert new.stats["timing"] == "toppra" and old.stats["timing"] == "trapezoid"
    assert new.stats["robot_seconds"]["total"] < old.stats["robot_seconds"]["total"]
    assert new.stats["robot_seconds"]["approach"] < 0.5 * old.stats["robot_seconds"]["approach"]
    for seg in new.segments:
        if seg.trajectory is None:
            continue
        t = np.asarray(seg.trajectory.times)
        q = np.asarray(seg.trajectory.positions)
        chord = np.diff(q, axis=0) / np.diff(t)[:, None]
        assert np.all(np.abs(chord) <= robot.speed_limits("left") * (1 + 1e-6)), seg.label
    with pytest.raises(UserError, match="timing"):
        to_plan(_steps(), robot, 2.0, timing="fast")


def test_the_insertion_keeps_its_set_tcp_speed() -> None:
    robot = _Robot()
    plan = to_plan(_steps(), robot, 2.0, insertion_speed=0.01)
    seg = next(s for s in plan.segments if s.kind == "insertion")
    t = np.asarray(seg.trajectory.times)
    x = np.array([robot.fk("left", q)[0, 3] for q in np.asarray(seg.trajectory.positions)])
    speed = np.diff(x) / np.diff(t)
    assert speed.max() <= 0.01 * (1 + 1e-4)  # toppra keeps the cap to its solver tolerance
    assert np.mean(speed >= 0.0099) > 0.5  # most of the way at the set speed: 15 mm at 10 mm/s
    assert t[-1] == pytest.approx(1.5, rel=0.1)
