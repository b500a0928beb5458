"""BiTRRT specifics: batched checks, direct connection, clearance against RRTConnect, the cost map helper."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.failures import FailureKind
from asmteach.core.trajectory.batch import batched, inverse_clearance_cost
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.ompl_planners import RRTConnectPlanner
from asmteach.plugins.planners.motion.toyworld import Box, JointWorld, narrow_passage
from asmteach.plugins.planners.motion.trrt import TRRTPlanner


def vectorised(world: JointWorld) -> dict:
    """Validity and inverse-clearance cost with vectorised twins, as a robot's batch checker provides."""
    clearance = batched(world.clearance, world.clearance_batch)
    return {
        "lower": world.lower,
        "upper": world.upper,
        "is_valid": batched(world.is_valid, world.valid_batch),
        "cost": inverse_clearance_cost(clearance),
    }


def exact_check(path: np.ndarray, world: JointWorld, start: np.ndarray, goal: np.ndarray) -> None:
    """Ends exact and every state at 2 mrad steps valid without the planning margin."""
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    exact = JointWorld(world.lower, world.upper, world.obstacles, margin=0.0)
    assert np.all(exact.valid_batch(densify(path, 0.002)))


def test_batched_and_plain_checks_grow_the_same_trees(passage2d) -> None:
    """Whole-edge batch checks decide exactly what OMPL's per-state motion checks decide."""
    world, start, goal = passage2d
    kw = vectorised(world)
    plain = {**kw, "is_valid": world.is_valid, "cost": inverse_clearance_cost(world.clearance)}
    a = TRRTPlanner({"collision_resolution": 0.01}, seed=5).plan(start, goal, **kw, time_limit=20.0)
    b = TRRTPlanner({"collision_resolution": 0.01}, seed=5).plan(start, goal, **plain, time_limit=20.0)
    assert a.success and b.success
    for key in ("iterations", "start_nodes", "goal_nodes", "uphill_accepted", "raw_waypoints"):
        assert a.stats[key] == b.stats[key], key
    assert a.stats["raw_length"] == pytest.approx(b.stats["raw_length"])
    assert a.stats["batch_calls"] > 0 and b.stats["batch_calls"] == 0
    exact_check(a.path, world, start, goal)


def test_batched_same_seed_same_path(passage2d) -> None:
    world, start, goal = passage2d
    kw = {**vectorised(world), "time_limit": 20.0}
    a = TRRTPlanner(seed=11).plan(start, goal, **kw)
    b = TRRTPlanner(seed=11).plan(start, goal, **kw)
    c = TRRTPlanner(seed=12).plan(start, goal, **kw)
    assert a.success and b.success and c.success
    assert np.array_equal(a.path, b.path)
    assert a.path.shape != c.path.shape or not np.array_equal(a.path, c.path)


@pytest.mark.parametrize(("dof", "gap"), [(3, 0.6), (4, 1.0)])
def test_narrow_passage_nd(dof: int, gap: float) -> None:
    """A wall with a square hole in 3-D and 4-D; the path must go through the hole and stay valid."""
    world = narrow_passage(dof, gap=gap)
    world.margin = 0.01
    start = np.r_[-1.5, -2.0 * np.ones(dof - 1)]
    goal = np.r_[1.5, 2.0 * np.ones(dof - 1)]
    result = TRRTPlanner({"collision_resolution": 0.01}, seed=2).plan(start, goal, **vectorised(world), time_limit=30.0)
    assert result.success, result.reason
    assert not result.stats["direct"]
    exact_check(result.path, world, start, goal)
    dense = densify(result.path, 0.005)
    crossing = dense[np.argmin(np.abs(dense[:, 0]))]
    assert np.all(np.abs(crossing[1:]) < gap / 2)


def test_keeps_more_clearance_than_rrtconnect(clutter6d) -> None:
    """On the 6-D clutter problem T-RRT's paths are on average clearly farther from obstacles."""
    world, start, goal = clutter6d
    kw = {**vectorised(world), "time_limit": 20.0}
    mean_cost = {"trrt": [], "rrtconnect": []}
    min_clear = {"trrt": [], "rrtconnect": []}
    for seed in range(5):
        for name, cls in (("trrt", TRRTPlanner), ("rrtconnect", RRTConnectPlanner)):
            res = cls({"collision_resolution": 0.02}, seed=seed).plan(start, goal, **kw)
            assert res.success, (name, seed, res.reason)
            clearance = world.clearance_batch(densify(res.path, 0.01))
            mean_cost[name].append(float(np.mean(1.0 / np.maximum(clearance, 1e-3))))
            min_clear[name].append(float(clearance.min()))
    # Measured: mean cost ~1.3 vs ~2.0, minimum clearance ~0.4 vs ~0.05 rad; the bounds leave ample slack.
    assert np.mean(mean_cost["trrt"]) < 0.85 * np.mean(mean_cost["rrtconnect"])
    assert np.mean(min_clear["trrt"]) > np.mean(min_clear["rrtconnect"]) + 0.05


def test_direct_connection() -> None:
    lower, upper = -np.pi * np.ones(3), np.pi * np.ones(3)
    start, goal = np.array([-2.0, 0.0, 0.5]), np.array([2.0, 0.5, -0.5])
    free = {"lower": lower, "upper": upper, "is_valid": lambda q: True}
    res = TRRTPlanner(seed=0).plan(start, goal, **free)
    assert res.success and res.stats["direct"] and res.stats["iterations"] == 0
    assert np.array_equal(res.path, np.stack([start, goal]))
    # Switched off, the trees are grown even though the line is free.
    res = TRRTPlanner({"direct_first": False}, seed=0).plan(start, goal, **free)
    assert res.success and not res.stats["direct"] and res.stats["iterations"] >= 1
    # A line that climbs above both end points' cost is not taken directly: T-RRT goes round the hill.
    hill = lambda q: float(np.exp(-np.sum(q[:2] ** 2)))  # noqa: E731 - a one-line cost map
    res = TRRTPlanner(seed=0).plan(start, goal, **free, cost=hill, time_limit=10.0)
    assert res.success and not res.stats["direct"]
    assert max(hill(q) for q in densify(res.path, 0.01)) < hill(np.zeros(3)) - 0.1


def test_failure_reports_how_close_the_trees_came() -> None:
    lower, upper = -np.pi * np.ones(2), np.pi * np.ones(2)
    world = JointWorld(lower, upper, [Box(np.zeros(2), np.array([0.1, np.pi]))])
    res = TRRTPlanner(seed=0).plan(np.array([-1.0, 0.0]), np.array([1.0, 0.0]), **vectorised(world), time_limit=0.3)
    assert not res.success and res.kind is FailureKind.TIMEOUT
    # The closed wall is 0.2 rad thick, so the two trees stay at least that far apart.
    assert res.stats["tree_gap"] >= 0.2 - 1e-9


def test_direct_check_batched_agrees_with_every_state_and_stops_at_the_coarse_ones() -> None:
    """The straight-motion test, batched (every 8th state first, validity then cost): the verdict of checking
    every state at the resolution, on lines that are free, blocked, or climb the cost map between free ends."""
    from asmteach.plugins.planners.motion.space import JointSpace
    from asmteach.plugins.planners.motion.tree import Checks

    world = JointWorld(-np.pi * np.ones(2), np.pi * np.ones(2), [Box(np.array([0.0, 1.5]), np.array([0.3, 0.3]))])
    checks = vectorised(world)
    sizes: list[int] = []
    valid = batched(world.is_valid, lambda qs: (sizes.append(len(qs)), world.valid_batch(qs))[1])
    space = JointSpace(world.lower, world.upper, valid, resolution=0.01)
    rng = np.random.default_rng(3)
    verdicts = set()
    for _ in range(60):
        a, b = rng.uniform(-2.5, 2.5, (2, 2))
        if not (world.is_valid(a) and world.is_valid(b)):
            continue
        cost = checks["cost"]
        ceiling = max(cost(a), cost(b))
        line = densify(np.stack([a, b]), 0.01)[1:-1]
        expected = bool(np.all(world.valid_batch(line)) and np.max(cost.batch(line), initial=0.0) <= ceiling)
        sizes.clear()
        got = TRRTPlanner._direct_ok(Checks(space, valid, cost), a, b, ceiling)
        assert got == expected
        verdicts.add((got, bool(np.all(world.valid_batch(line)))))
        if not np.all(world.valid_batch(line[::8])):
            assert sizes == [len(line[::8])]  # blocked at a coarse state: one small call
    assert verdicts == {(True, True), (False, True), (False, False)}  # free, over the ceiling, blocked
