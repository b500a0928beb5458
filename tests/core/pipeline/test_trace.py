"""A run's failure reason names the motion that pushed a part in the hand (a jam); its kind decides the cause."""

from __future__ import annotations

from asmteach.core.failures import FailureCause
from asmteach.core.models import RunReport, StageOutcome
from asmteach.core.pipeline.measure import _outside_tolerance_cause, _slip_note, _worst_slip


def _report(*events: dict) -> RunReport:
    return RunReport(
        config={},
        seed=0,
        stages=[
            StageOutcome(
                stage="plan", ok=True, details={"trace": [{"label": "not an execution", "slip_in_hand_mm": 99}]}
            ),
            StageOutcome(stage="execute", ok=True, details={"trace": list(events)}),
        ],
    )


def test_the_worst_push_in_the_hand_is_named_with_the_motion_before_it() -> None:
    worst = _worst_slip(
        _report(
            {
                "label": "release holed_block",
                "part": "holed_block",
                "slip_in_hand_mm": 1.4,
                "after": "place holed_block",
                "after_kind": "approach",
            },
            {
                "label": "release round_peg",
                "part": "round_peg",
                "slip_in_hand_mm": 9.62,
                "after": "insert round_peg at assembled",
                "after_kind": "insertion",
            },
            {"label": "close on round_peg", "part": "round_peg"},
        )
    )
    assert worst is not None and worst["after_kind"] == "insertion"
    assert _slip_note(worst).startswith("; round_peg was pushed 9.6 mm in the hand by 'insert round_peg at assembled'")


def test_no_note_when_parts_stayed_put_in_the_hand() -> None:
    assert _worst_slip(_report({"label": "release round_peg", "part": "round_peg", "slip_in_hand_mm": 0.21})) is None
    assert _worst_slip(RunReport(config={}, seed=0)) is None
    assert _slip_note(None) == ""


def test_a_push_during_an_insertion_is_a_jam_elsewhere_off_goal() -> None:
    insert = {"label": "release round_peg", "slip_in_hand_mm": 7.5, "after": "x", "after_kind": "insertion"}
    place = {
        "label": "release holed_block",
        "slip_in_hand_mm": 7.5,
        "after": "insert-like name",
        "after_kind": "approach",
    }
    assert _outside_tolerance_cause(_worst_slip(_report(insert))) is FailureCause.JAM
    # the label is never read: only the motion's kind decides
    assert _outside_tolerance_cause(_worst_slip(_report(place))) is FailureCause.OFF_GOAL
    assert _outside_tolerance_cause(None) is FailureCause.OFF_GOAL
