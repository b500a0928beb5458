"""The look-again stage's rule for a part not found again at its goal."""

from __future__ import annotations

from asmteach.core.models import Detection
from asmteach.core.pipeline.plan import went_on_guessing


def _det(**details: object) -> Detection:
    return Detection(part="a", found=True, details=details)


def test_only_an_unsettled_ambiguity_is_a_guess() -> None:
    rivals = [{"T_world_part": None}, {"T_world_part": None}]
    assert went_on_guessing(_det(ambiguous=rivals, provisional=True))
    assert not went_on_guessing(_det(ambiguous=rivals, resolved_by_view={"winner": 1}))  # a look settled it
    assert not went_on_guessing(_det())
