"""Toy joint-space problems shared by the motion planner tests (made in code)."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.plugins.planners.motion import toyworld
from asmteach.plugins.planners.motion.toyworld import JointWorld, narrow_passage


@pytest.fixture
def passage2d() -> tuple[JointWorld, np.ndarray, np.ndarray]:
    """A 2-D wall with a 0.3 rad hole; the straight line start -> goal hits the wall.

    Planning pads obstacles by 0.01 rad: a motion checked every 0.01 rad can clip
    a corner by up to half a step, and the tests re-check unpadded at 2 mrad.
    """
    world = narrow_passage(2, gap=0.3)
    world.margin = 0.01
    return world, np.array([-1.5, -2.0]), np.array([1.5, -2.0])


@pytest.fixture
def clutter6d() -> tuple[JointWorld, np.ndarray, np.ndarray]:
    """A 6-D wall with a wide hole plus a ball and a box, padded 0.02 rad; the straight line is blocked."""
    return toyworld.clutter6d(margin=0.02)
