"""The look-again stage's rules: a part not found again at its goal, and a part seen turned where it was placed."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.models import Detection, TablePlane
from asmteach.core.pipeline.plan import placed_or_seen, went_on_guessing
from asmteach.core.pose_error import pose_error
from asmteach.core.symmetry import part_symmetries


def _det(**details: object) -> Detection:
    return Detection(part="a", found=True, details=details)


def test_only_an_unsettled_ambiguity_is_a_guess() -> None:
    rivals = [{"T_world_part": None}, {"T_world_part": None}]
    assert went_on_guessing(_det(ambiguous=rivals, provisional=True))
    assert not went_on_guessing(_det(ambiguous=rivals, resolved_by_view={"winner": 1}))  # a look settled it
    assert not went_on_guessing(_det())


# ---- the look at the goal against where the robot put A (placed_or_seen)

EYE_1 = np.array([-0.05, 0.0, 0.70])  # the robot's side of the table, as the scene Kinect
EYE_2 = np.array([0.98, 0.0, 0.53])  # across the table, 45 deg down


@pytest.mark.parametrize("truth", ["placed", "seen"])
def test_a_turn_seen_at_the_goal_must_beat_where_the_part_was_placed(
    d_peg_part, d_peg_poses, table_kinect_view, truth: str
) -> None:
    # placed with the flat towards camera 2; seen turned 20 deg, the flat down, out of camera 1's sight
    part, d_peg_mesh = d_peg_part, d_peg_part.mesh
    placed, seen = d_peg_poses
    T_true = placed if truth == "placed" else seen
    views = [table_kinect_view(d_peg_mesh, T_true, EYE_1, 1), table_kinect_view(d_peg_mesh, T_true, EYE_2, 2)]
    det = Detection(part="d_peg", found=True, rough=seen, details={})
    details: dict = {}
    syms = part_symmetries(d_peg_mesh, part.center_of_mass)
    T = placed_or_seen(det, part, seen, placed, views, TablePlane(), syms, None, details)
    assert pose_error(T, T_true, (), syms).within(2.0, 3.0)
    assert details["placed_vs_seen"]["settled"]
    # one view cannot tell them apart (the flat out of its sight): the placed pose stands, whatever is true
    details = {}
    T = placed_or_seen(det, part, seen, placed, views[:1], TablePlane(), syms, None, details)
    np.testing.assert_allclose(T, placed)
    assert details["placed_vs_seen"]["kept"] == "placed" and not details["placed_vs_seen"]["settled"]


def test_a_wrist_look_settles_what_the_fixed_views_leave(d_peg_part, d_peg_poses) -> None:
    part = d_peg_part
    placed, seen = d_peg_poses
    asked: list[Detection] = []

    def closer(d: Detection) -> Detection:
        asked.append(d)
        return d.model_copy(update={"found": True, "reason": None, "rough": seen})

    det = Detection(part="d_peg", found=True, rough=seen, details={})
    details: dict = {}
    T = placed_or_seen(det, part, seen, placed, [], TablePlane(), None, closer, details)
    np.testing.assert_allclose(T, seen)
    rivals = [np.asarray(r["T_world_part"]) for r in asked[0].details["ambiguous"]]
    np.testing.assert_allclose(rivals, [seen, placed])
    assert asked[0].details["ambiguous_kind"] == "placed_vs_seen" and not asked[0].found
