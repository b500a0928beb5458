"""The cheap screen of grasps before IK, on a made-in-code bar held over a block (metres)."""

import numpy as np
import pytest
import trimesh

from asmteach.core.geometry import from_rotation
from asmteach.core.interfaces import Obstacle
from asmteach.core.models import Grasp, HandSpec
from asmteach.plugins.planners.regrasp.feasibility import ScreenSettings, screen_slot, world_collider
from asmteach.plugins.planners.regrasp.graph import PoseSlot

HAND = HandSpec(name="test_2f", max_width=0.085, finger_size=[0.010, 0.020, 0.045], pad_size=(0.020, 0.030),
                palm_center=[0.0, 0.0, -0.050], palm_size=[0.040, 0.100, 0.040])
BAR_LENGTH = 0.080
# The bar (part frame: origin at its bottom centre, 80 mm along x) held from above by its two ends, fingers along x.
END_GRASP = Grasp(id=0, p0=[-BAR_LENGTH / 2, 0.0, 0.010], p1=[BAR_LENGTH / 2, 0.0, 0.010],
                  R=np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]).T, width=BAR_LENGTH)
BAR_ON_BLOCK = PoseSlot("assembled", "goal", from_rotation(np.eye(3), [0.0, 0.0, 0.020]))


def block(length: float) -> Obstacle:
    """A 20 mm tall block under the bar, ``length`` along x: at 80 mm its end faces are flush with the bar's."""
    mesh = trimesh.creation.box(extents=[length, 0.060, 0.020])
    return Obstacle("block", mesh, from_rotation(np.eye(3), [0.0, 0.0, 0.010]))


@pytest.mark.parametrize(("length", "free"), [(BAR_LENGTH, False), (BAR_LENGTH - 0.004, True)])
def test_a_hand_closed_flush_with_the_other_part_is_screened_out_where_the_part_is_held(length, free) -> None:
    """Fingers on the bar's ends reach below its bottom (pads 15 mm past the TCP, 10 mm above it): flush with the
    block's end faces they would slide along them on the insertion; 2 mm clear of them they pass."""
    collider = world_collider([block(length)])
    passed, rejected = screen_slot(BAR_ON_BLOCK, [END_GRASP], collider, HAND, ScreenSettings(), on_table=False)
    assert (passed == [END_GRASP]) is free
    if not free:
        assert rejected[0].startswith("collision: hand/finger") and rejected[0].endswith("with block")


def test_the_closed_hand_is_not_checked_for_a_part_resting_on_the_table() -> None:
    """On the table the hand only approaches, open 2 mm a side beyond the width: clear of flush faces."""
    collider = world_collider([block(BAR_LENGTH)])
    passed, _ = screen_slot(BAR_ON_BLOCK, [END_GRASP], collider, HAND, ScreenSettings(), on_table=True)
    assert passed == [END_GRASP]
