"""The PyBullet hold check: good grasps hold with friction only; a slippery heavy part falls."""

from __future__ import annotations

import pytest

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
