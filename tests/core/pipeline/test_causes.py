"""A run outside tolerance names what happened from the execution trace's events (issue 23, item 5).

Every case is a made-up trace: a jammed guarded insertion, a toppled part, a part moved by a named motion,
a part pushed in the hand, a part that tilted as it was let go; the cause comes from the events' structure,
never from their labels.
"""

from __future__ import annotations

import numpy as np

from asmteach.core.failures import FailureCause
from asmteach.core.models import AssemblyTask, PartSpec, RunReport, StageOutcome
from asmteach.core.pipeline.causes import failure_story, insertion_error


def _report(*events: dict) -> RunReport:
    return RunReport(
        config={},
        seed=0,
        stages=[
            StageOutcome(stage="plan", ok=True, details={"trace": [{"label": "not an execution", "toppled": True}]}),
            StageOutcome(stage="execute", ok=True, details={"trace": list(events)}),
        ],
    )


def _jam(inserted: bool) -> dict:
    return {
        "label": "insert round_peg at assembled",
        "part": "round_peg",
        "t_s": 31.25,
        "insertion": {
            "inserted": inserted,
            "depth_mm": 6.04,
            "length_mm": 15.0,
            "max_force_n": 38.2,
            "tries": 16,
            "correction_mm": [1.2, 0.5, 0.0],
            "reason": "still resisted after 16 sideways corrections",
        },
    }


def test_a_guarded_insertion_that_did_not_get_in_is_a_jam_with_depth_force_and_time() -> None:
    text, cause, evidence = failure_story(_report(_jam(False)), None)
    assert cause is FailureCause.JAM
    assert text.startswith("round_peg jammed at 6.0 of 15.0 mm depth, contact force 38 N in ")
    assert "t = 31.2 s" in text
    assert evidence["event"]["insertion"]["depth_mm"] == 6.04
    # an insertion that got in explains nothing: no event left, so the story says so
    text, cause, _ = failure_story(_report(_jam(True)), None)
    assert cause is FailureCause.OFF_GOAL and text.startswith("no execution event explains it")


def test_a_jam_at_the_same_depth_through_every_shift_says_so() -> None:
    ev = _jam(False)
    ev["insertion"].update(contact_depth_mm=[20.39, 20.95], max_offset_mm=2.35)
    text, _, _ = failure_story(_report(ev), None)
    assert "met the resistance at 20.4-20.9 mm depth through every shift (up to 2.4 mm)" in text
    # resistance that moved with the shifts (a rim it slid along) says nothing of the kind
    ev["insertion"].update(contact_depth_mm=[4.96, 11.67])
    assert "through every shift" not in failure_story(_report(ev), None)[0]
    ev["insertion"].update(realigned_mm=6.01, realigned_deg=16.0)
    assert "re-aimed 6.0 mm / 16.0 deg for the part as measured in the hand" in failure_story(_report(ev), None)[0]


def _moved(part: str, mm: float, tilt: float, by: str, t: float, kind: str = "insertion") -> dict:
    return {
        "label": by,
        "part": part,
        "pushed_mm": mm,
        "tilted_deg": tilt,
        "toppled": tilt > 20.0,
        "by": by,
        "by_kind": kind,
        "holding": "t_slider",
        "t_s": t,
    }


def test_a_toppled_part_names_the_motion_and_time_before_a_larger_push() -> None:
    report = _report(
        _moved("block", 80.0, 2.0, "insert t_slider at assembled", 20.0),
        _moved("block", 12.0, 35.0, "retreat", 24.4, "approach"),
    )
    text, cause, evidence = failure_story(report, None)
    assert cause is FailureCause.TOPPLE
    assert text.startswith("block toppled at t = 24.4 s while 'retreat' ran (tilted 35 deg")
    assert evidence["event"]["by"] == "retreat"


def test_a_moved_part_names_the_largest_push_its_motion_and_time() -> None:
    report = _report(
        _moved("block", 3.0, 0.5, "carry t_slider to assembled", 12.0, "transit"),
        _moved("block", 80.4, 2.0, "insert t_slider at assembled", 20.04),
    )
    text, cause, _ = failure_story(report, None)
    assert cause is FailureCause.OFF_GOAL
    assert text == "block moved 80.4 mm during 'insert t_slider at assembled' (holding t_slider) at t = 20.0 s"


def test_a_push_in_the_hand_is_a_jam_only_during_an_insertion() -> None:
    def release(kind: str) -> dict:
        return {"label": "release p", "part": "p", "slip_in_hand_mm": 7.5, "after": "insert-like", "after_kind": kind}

    assert failure_story(_report(release("insertion")), None)[1] is FailureCause.JAM
    text, cause, _ = failure_story(_report(release("approach")), None)
    assert cause is FailureCause.OFF_GOAL and "pushed 7.5 mm in the hand by 'insert-like'" in text
    # a slip under the limit is no evidence
    small = {"label": "release p", "part": "p", "slip_in_hand_mm": 0.2, "after": "x", "after_kind": "insertion"}
    assert failure_story(_report(small), None)[1] is FailureCause.OFF_GOAL


def test_a_part_that_tilts_as_it_is_let_go_is_named() -> None:
    ev = {"label": "release round_peg", "part": "round_peg", "dropped_mm": 1.1, "tilted_deg": 2.9, "t_s": 40.0}
    text, cause, _ = failure_story(_report(ev), None)
    assert cause is FailureCause.OFF_GOAL
    assert text == "round_peg tilted 2.9 deg and dropped 1.1 mm as 'release round_peg' let it go at t = 40.0 s"
    # a planned ~1 mm drop with no tilt is how every placement ends: no evidence
    ev = {"label": "release round_peg", "part": "round_peg", "dropped_mm": 1.0, "tilted_deg": 0.1, "t_s": 40.0}
    assert failure_story(_report(ev), None)[0].startswith("no execution event")


def _T(xyz: tuple[float, float, float], yaw_deg: float = 0.0) -> np.ndarray:
    T = np.eye(4)
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = xyz
    return T


def _inserted(T_end: np.ndarray, T_tcp_part: np.ndarray, T_world_other: np.ndarray) -> dict:
    """A guarded insertion that got in: a 30 mm straight-down TCP line ending at ``T_end``."""
    T_start = T_end.copy()
    T_start[2, 3] += 0.03
    return {
        "label": "insert p",
        "part": "p",
        "insertion": {"inserted": True},
        "T_world_tcp_start": T_start.tolist(),
        "T_world_tcp_end": T_end.tolist(),
        "T_tcp_part": T_tcp_part.tolist(),
        "T_world_other": T_world_other.tolist(),
    }


def test_the_insertion_error_is_split_into_grasp_placement_and_teaching() -> None:
    """A peg inserted straight down: the hand holds it 0.3 mm off in x, A stands 0.2 mm off its goal in y,
    the taught seat is 0.4 mm off the true one in x; a 5 mm error along the insertion line is no error."""
    spec = PartSpec(name="p", solid=None, mesh="p.stl")
    seat = _T((0.0, 0.0, 0.015))
    taught = _T((0.0004, 0.0, 0.020))  # 0.4 mm across, 5 mm along the line
    true_task = AssemblyTask(name="t", part_a=spec, part_b=spec, T_A_B=seat, v_a=[0.0, 0.0, 1.0])
    learned = true_task.model_copy(update={"T_A_B": taught})
    a_goal = _T((0.4, 0.0, 0.0))
    a_now = _T((0.4, 0.0002, 0.0))
    # the TCP 100 mm above the part, pointing down; the plan aims the part at A's goal @ taught
    T_tcp_part = _T((0.0, 0.0, -0.1))
    T_tcp_part[:3, 3] += [0.0003, 0.0, 0.0]  # held 0.3 mm off in x
    ev = _inserted(a_goal @ taught @ np.linalg.inv(_T((0.0, 0.0, -0.1))), T_tcp_part, a_now)
    split = insertion_error(_report(ev), learned, true_task, a_goal)
    assert split is not None
    assert abs(split["grasp_mm"] - 0.3) < 1e-6
    assert abs(split["a_place_mm"] - 0.2) < 1e-6
    assert abs(split["taught_mm"] - 0.4) < 1e-6
    # the hand's 0.3 mm and the taught pose's 0.4 mm both push the part +x of the true seat, A's 0.2 mm is -y
    assert abs(split["total_mm"] - np.hypot(0.7, 0.2)) < 1e-3
    assert split["total_deg"] < 1e-6
    text, cause, evidence = failure_story(_report(ev), split)
    assert cause is FailureCause.OFF_GOAL
    assert "grasp 0.30 mm" in text and "taught pose 0.40 mm" in text and evidence["insertion_error"] == split


def test_a_symmetric_a_standing_in_its_twin_pose_splits_as_in_the_pose_nearest_its_goal() -> None:
    """A block turned 180 deg about x is the same solid (its symmetry): without it the split would read a
    180 deg 'placement error' and a part 'upside down' in its seat."""
    spec = PartSpec(name="p", solid=None, mesh="p.stl")
    seat = _T((0.0, 0.0, 0.015))
    task = AssemblyTask(name="t", part_a=spec, part_b=spec, T_A_B=seat, v_a=[0.0, 0.0, 1.0])
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    flip[2, 3] = 0.03  # the block's frame at its bottom face: turned over, the frame sits 30 mm up
    a_goal = _T((0.4, 0.0, 0.0))
    T_tcp_part = _T((0.0, 0.0, -0.1))
    ev = _inserted(a_goal @ seat @ np.linalg.inv(T_tcp_part), T_tcp_part, a_goal @ flip)
    plain = insertion_error(_report(ev), task, task, a_goal)
    assert plain is not None and plain["a_place_deg"] > 179.0
    split = insertion_error(_report(ev), task, task, a_goal, [np.eye(4), np.linalg.inv(flip)])
    assert split is not None and max(split.values()) < 1e-6


def test_a_jam_after_a_motion_knocked_its_seat_is_told_as_that_knock() -> None:
    jam = {**_jam(False), "other": "holed_block"}
    # a carry that toppled the block before the peg met it: the topple is the cause, the jam what followed
    carry = _moved("holed_block", 25.0, 31.6, "carry round_peg to assembled", 17.5, "transit")
    text, cause, evidence = failure_story(_report(carry, jam), None)
    assert cause is FailureCause.TOPPLE
    assert text.startswith("holed_block toppled at t = 17.5 s while 'carry round_peg to assembled' (holding t_slider)")
    assert "; then round_peg jammed at 6.0 of 15.0 mm" in text
    assert evidence["knocked"]["by"] == "carry round_peg to assembled"
    # knocked 5 mm without tipping: moved off its goal
    carry = _moved("holed_block", 5.0, 1.0, "carry round_peg to assembled", 17.5, "transit")
    text, cause, _ = failure_story(_report(carry, jam), None)
    assert cause is FailureCause.OFF_GOAL and text.startswith("holed_block was knocked at t = 17.5 s")
    # a nudge within A's goal tolerance, another part's topple, or a topple after the jam change nothing
    for events in (
        (_moved("holed_block", 2.0, 1.0, "carry", 17.5, "transit"), jam),
        (_moved("other_block", 25.0, 40.0, "carry", 17.5, "transit"), jam),
        (jam, _moved("holed_block", 25.0, 40.0, "retreat", 40.0, "approach")),
    ):
        text, cause, _ = failure_story(_report(*events), None)
        assert cause is FailureCause.JAM and text.startswith("round_peg jammed"), events
