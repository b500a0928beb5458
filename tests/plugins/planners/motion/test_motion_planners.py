"""T-RRT and RRTConnect on 2-D and 6-D joint-space toy worlds."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core import registry
from asmteach.core.errors import UserError
from asmteach.core.failures import FailureKind
from asmteach.core.interfaces import MotionPlanner
from asmteach.core.trajectory.batch import inverse_clearance_cost
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.ompl_planners import RRTConnectPlanner
from asmteach.plugins.planners.motion.toyworld import Box, JointWorld
from asmteach.plugins.planners.motion.trrt import TRRTPlanner

PLANNERS = [TRRTPlanner, RRTConnectPlanner]


def assert_valid_path(path: np.ndarray, world: JointWorld, start: np.ndarray, goal: np.ndarray) -> None:
    """Independent re-check without the planning padding: every state at 2 mrad steps is valid; ends exact."""
    assert path is not None and path.ndim == 2 and path.shape[1] == world.dof
    assert np.allclose(path[0], start) and np.allclose(path[-1], goal)
    exact = JointWorld(world.lower, world.upper, world.obstacles, margin=0.0)
    assert np.all(exact.valid_batch(densify(path, 0.002)))


@pytest.mark.parametrize("planner_cls", PLANNERS)
@pytest.mark.parametrize("with_cost", [False, True])
def test_narrow_passage_2d(planner_cls: type[MotionPlanner], with_cost: bool, passage2d) -> None:
    world, start, goal = passage2d
    cost = inverse_clearance_cost(world.clearance) if with_cost else None
    planner = planner_cls({"collision_resolution": 0.01}, seed=3)
    result = planner.plan(
        start, goal, lower=world.lower, upper=world.upper, is_valid=world.is_valid, cost=cost, time_limit=20.0
    )
    assert result.success, result.reason
    assert_valid_path(result.path, world, start, goal)
    # The wall blocks the straight line, so the path detours through the hole at |q1| < 0.15.
    dense = densify(result.path, 0.01)
    crossing = dense[np.argmin(np.abs(dense[:, 0]))]
    assert abs(crossing[1]) < 0.15


@pytest.mark.slow
@pytest.mark.parametrize("planner_cls", PLANNERS)
def test_clutter_6d(planner_cls: type[MotionPlanner], clutter6d) -> None:
    world, start, goal = clutter6d
    planner = planner_cls({"collision_resolution": 0.02}, seed=0)
    result = planner.plan(start, goal, lower=world.lower, upper=world.upper, is_valid=world.is_valid, time_limit=30.0)
    assert result.success, result.reason
    assert_valid_path(result.path, world, start, goal)
    assert result.stats["length"] <= result.stats["raw_length"] + 1e-9


@pytest.mark.parametrize("planner_cls", PLANNERS)
def test_start_goal_in_collision_and_out_of_bounds(planner_cls: type[MotionPlanner], passage2d) -> None:
    world, start, goal = passage2d
    planner = planner_cls(seed=0)
    kw = {"lower": world.lower, "upper": world.upper, "is_valid": world.is_valid}
    in_wall = np.array([0.0, 1.0])
    assert not world.is_valid(in_wall)
    cases = [
        (in_wall, goal, FailureKind.START_INVALID, "start in collision"),
        (start, in_wall, FailureKind.GOAL_INVALID, "goal in collision"),
        (np.array([-4.0, 0.0]), goal, FailureKind.START_OUT_OF_BOUNDS, "start out of joint limits"),
        (start, np.array([0.0, 9.0]), FailureKind.GOAL_OUT_OF_BOUNDS, "goal out of joint limits"),
    ]
    for q0, q1, kind, text in cases:
        result = planner.plan(q0, q1, **kw)
        assert not result.success and result.path is None
        assert result.kind is kind
        assert result.reason.startswith(text)
    with pytest.raises(UserError, match="start must be 2 finite"):
        planner.plan(np.zeros(3), goal, **kw)
    with pytest.raises(UserError, match="lower < upper"):
        planner.plan(start, goal, lower=world.upper, upper=world.lower, is_valid=world.is_valid)


@pytest.mark.parametrize("planner_cls", PLANNERS)
def test_timeout_is_reported(planner_cls: type[MotionPlanner]) -> None:
    # A wall with no hole: no path exists, so only the time limit stops the planner.
    lower, upper = -np.pi * np.ones(2), np.pi * np.ones(2)
    world = JointWorld(lower, upper, [Box(np.zeros(2), np.array([0.1, np.pi]))])
    result = planner_cls(seed=0).plan(
        np.array([-1.0, 0.0]), np.array([1.0, 0.0]), lower=lower, upper=upper, is_valid=world.is_valid, time_limit=0.3
    )
    assert not result.success
    assert result.kind is FailureKind.TIMEOUT
    assert result.reason.startswith("timeout after 0.3 s")


def test_trrt_iteration_limit(passage2d) -> None:
    world, start, goal = passage2d
    result = TRRTPlanner({"max_iterations": 20}, seed=0).plan(
        start, goal, lower=world.lower, upper=world.upper, is_valid=world.is_valid
    )
    assert not result.success and result.kind is FailureKind.ITERATIONS
    assert result.stats["iterations"] == 20


@pytest.mark.parametrize("planner_cls", PLANNERS)
def test_same_seed_same_path(planner_cls: type[MotionPlanner], passage2d) -> None:
    world, start, goal = passage2d
    kw = {"lower": world.lower, "upper": world.upper, "is_valid": world.is_valid, "time_limit": 20.0}
    a = planner_cls(seed=7).plan(start, goal, **kw)
    b = planner_cls(seed=7).plan(start, goal, **kw)
    c = planner_cls(seed=8).plan(start, goal, **kw)
    assert a.success and b.success and c.success
    assert np.array_equal(a.path, b.path)
    assert a.path.shape != c.path.shape or not np.array_equal(a.path, c.path)
    # Successive queries of one planner draw fresh randomness, reproducibly.
    p = planner_cls(seed=7)
    first, second = p.plan(start, goal, **kw), p.plan(start, goal, **kw)
    assert np.array_equal(first.path, a.path) and not np.array_equal(second.path, first.path)


def test_trrt_prefers_cheap_valley() -> None:
    """Cost map with a cheap ring of radius 2: T-RRT follows it, RRTConnect cuts across."""
    lower, upper = -3 * np.ones(2), 3 * np.ones(2)

    def cost(q: np.ndarray) -> float:
        return 1.0 + 20.0 * (np.hypot(q[0], q[1]) - 2.0) ** 2

    def mean_cost(path: np.ndarray) -> float:
        return float(np.mean([cost(q) for q in densify(path, 0.01)]))

    start, goal = np.array([-2.0, 0.0]), np.array([2.0, 0.0])
    kw = {"lower": lower, "upper": upper, "is_valid": lambda q: True, "cost": cost, "time_limit": 10.0}
    for seed in range(3):
        trrt = TRRTPlanner(seed=seed).plan(start, goal, **kw)
        rrtc = RRTConnectPlanner(seed=seed).plan(start, goal, **kw)
        assert trrt.success and rrtc.success
        assert mean_cost(trrt.path) < 0.5 * mean_cost(rrtc.path)
        # Near the valley floor (cost 1): the raw T-RRT paths measure 1.4-1.7; the simplifier may then cut
        # corners up to the path's costliest point (finish_path's ceiling), measured 2.0-3.5 after it.
        assert mean_cost(trrt.path) < 4.0
        # The temperature adapted: uphill steps were accepted and others refused.
        assert trrt.stats["uphill_accepted"] > 0 and trrt.stats["rejected"]["transition"] > 0


def test_registered_entry_points_and_settings() -> None:
    trrt = registry.create("motion_planners", "trrt", {"temperature_rise": 0.2, "range": 0.3}, seed=4)
    assert isinstance(trrt, TRRTPlanner) and trrt.settings.temperature_rise == 0.2 and trrt.seed == 4
    assert isinstance(registry.create("motion_planners", "rrtconnect", {}), RRTConnectPlanner)
    with pytest.raises(UserError):
        registry.create("motion_planners", "trrt", {"temperature_rsie": 0.1})
    with pytest.raises(UserError):
        registry.create("motion_planners", "trrt", {"frontier_ratio": -1})


def test_rrtconnect_shortens_with_batched_checks_when_offered(passage2d) -> None:
    """Given a vectorised validity check, RRTConnect's found path is shortened like T-RRT's (a few batched
    calls, not OMPL's one python call per state): same seed, same path; valid, ends kept, no longer."""
    from asmteach.core.trajectory.batch import batched

    world, start, goal = passage2d
    kw = {"lower": world.lower, "upper": world.upper, "time_limit": 20.0}
    fast = batched(world.is_valid, world.valid_batch)
    a = RRTConnectPlanner({"collision_resolution": 0.01}, seed=4).plan(start, goal, is_valid=fast, **kw)
    b = RRTConnectPlanner({"collision_resolution": 0.01}, seed=4).plan(start, goal, is_valid=fast, **kw)
    plain = RRTConnectPlanner({"collision_resolution": 0.01}, seed=4).plan(start, goal, is_valid=world.is_valid, **kw)
    assert a.success and b.success and plain.success
    assert a.stats["batch_calls"] > 0 and "batch_calls" not in plain.stats
    assert np.array_equal(a.path, b.path)
    assert a.stats["raw_length"] == pytest.approx(plain.stats["raw_length"])  # the same tree; only the shortening
    assert a.stats["length"] <= a.stats["raw_length"] + 1e-9
    assert_valid_path(a.path, world, start, goal)
