"""The regrasp planner's cheap screen of grasps at a slot: at a goal slot the hand is also checked closed.

Fixture made in code: a 20 mm wide bar held across its width by a test hand (fingers 10 mm thick), and a
thin plate beside it that the fingers meet only when closed on the bar (with the jaw pre-shaped 2 mm wider
a side for the approach, they clear it).
"""

import numpy as np
import trimesh

from asmteach.core.interfaces import Obstacle
from asmteach.core.models import Grasp, HandSpec
from asmteach.plugins.planners.regrasp.feasibility import ScreenSettings, screen_slot, world_collider
from asmteach.plugins.planners.regrasp.graph import PoseSlot, Rejected

HAND = HandSpec(
    name="test_2f",
    max_width=0.085,
    finger_size=[0.010, 0.020, 0.045],
    pad_size=(0.020, 0.030),
    palm_center=[0.0, 0.0, -0.050],
    palm_size=[0.040, 0.100, 0.040],
)
# Across the part's y (20 mm) at its origin, approaching straight down (TCP z = world -z, x = world x).
GRASP = Grasp(id=0, p0=[0.0, -0.01, 0.0], p1=[0.0, 0.01, 0.0], R=np.diag([1.0, -1.0, -1.0]), width=0.02)


def _plate(y0: float, y1: float) -> Obstacle:
    """A plate spanning world y in [y0, y1] (metres), 10 mm thick just below the TCP, where the fingers reach."""
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.5 * (y0 + y1), -0.005]
    return Obstacle("plate", trimesh.creation.box(extents=[0.05, y1 - y0, 0.01]), T)


def test_a_goal_slot_checks_the_hand_closed_on_the_part() -> None:
    # closed, the finger at world +y (finger0: the TCP y is world -y) spans y in [10, 20] mm;
    # pre-shaped for the approach, [12, 22] mm
    world = world_collider([_plate(0.0105, 0.0115)])
    settings = ScreenSettings(finger_clearance=0.002)
    at_goal = screen_slot(PoseSlot("assembled", "goal", np.eye(4)), [GRASP], world, HAND, settings, on_table=False)
    passed, rejected = at_goal
    assert passed == [] and rejected[0].kind is Rejected.HAND_COLLISION
    assert rejected[0].detail == "hand/finger0 closed with plate"
    # the same pose as a middle slot: the part is picked up there, the jaw opened around it
    passed, rejected = screen_slot(PoseSlot("p", "middle", np.eye(4)), [GRASP], world, HAND, settings, on_table=False)
    assert passed == [GRASP] and rejected == {}
    # clear of both: no rejection at the goal either
    far = world_collider([_plate(0.030, 0.031)])
    assert screen_slot(PoseSlot("assembled", "goal", np.eye(4)), [GRASP], far, HAND, settings, False)[0] == [GRASP]
