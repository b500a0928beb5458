"""The PyBullet hold check: good grasps hold with friction only; a slippery heavy part falls; a thin plate holds."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.models import Grasp, Primitive
from asmteach.plugins.planners.grasps.hold_check import HoldSimulator
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner


@pytest.mark.slow
def test_block_holds_and_slippery_heavy_block_drops(block, hand) -> None:
    grasps = AntipodalGraspPlanner({"cache": False}).plan(block, hand)
    picks = [grasps[0], grasps[len(grasps) // 2], grasps[-1]]
    with HoldSimulator(hand, block, friction=0.5) as sim:
        results = [sim.check(g) for g in picks]
    assert all(r.held for r in results), results
    assert all(r.lift == pytest.approx(0.10, abs=0.01) for r in results)
    assert all(r.drift < 0.003 for r in results)
    # 2 kg of part, friction 0.02: 2 x 0.02 x 40 N = 1.6 N of grip against 19.6 N of weight
    block.mass, saved = 2.0, block.mass
    try:
        with HoldSimulator(hand, block, friction=0.02) as sim:
            r = sim.check(grasps[0])
    finally:
        block.mass = saved
    assert not r.held and r.reason == "dropped" and r.lift < 0.05


@pytest.mark.slow
def test_pinched_thin_plate_holds(make_box, hand) -> None:
    # A 2.5 mm plate with an 8 mm hole (64 overlapping convex pieces), pinched across its thickness from an
    # edge: the pads must stop on its faces. Closing 0.42 mm per step, or built as one multibody link per
    # piece, the jaws went through thin plates ("fingers closed through the part").
    t = 0.0025
    holes = [Primitive(shape="cylinder", radius=0.004, height=4 * t, pose={"xyz": [-0.015, 0.0, t / 2]})]
    plate = make_box([0.060, 0.050, t], name="plate", subtract=holes)
    # jaw axis along the plate's normal (part z), approach from its +x edge (TCP z along part -x)
    R = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    picks = [(0.0, -0.01), (0.0, 0.01), (0.01, 0.0), (0.02, 0.0)]
    with HoldSimulator(hand, plate, friction=0.5) as sim:
        results = [sim.check(Grasp(id=0, p0=[x, y, 0.0], p1=[x, y, t], R=R, width=t)) for x, y in picks]
    assert all(r.held for r in results), results
    assert all(r.drift < 0.001 for r in results), results
