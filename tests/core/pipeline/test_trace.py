"""The failure reason of a run names the motion that pushed a part in the hand (a jam)."""

from __future__ import annotations

from asmteach.core.models import RunReport, StageOutcome
from asmteach.core.pipeline.measure import _worst_slip


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
    note = _worst_slip(
        _report(
            {
                "label": "release holed_block",
                "part": "holed_block",
                "slip_in_hand_mm": 1.4,
                "after": "place holed_block",
            },
            {
                "label": "release round_peg",
                "part": "round_peg",
                "slip_in_hand_mm": 9.62,
                "after": "insert round_peg at assembled",
            },
            {"label": "close on round_peg", "part": "round_peg"},
        )
    )
    assert note.startswith("; round_peg was pushed 9.6 mm in the hand by 'insert round_peg at assembled'")


def test_no_note_when_parts_stayed_put_in_the_hand() -> None:
    assert _worst_slip(_report({"label": "release round_peg", "part": "round_peg", "slip_in_hand_mm": 0.21})) == ""
    assert _worst_slip(RunReport(config={}, seed=0)) == ""
