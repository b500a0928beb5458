"""Batched path shortening: end points kept, every segment valid, shorter, cost ceiling respected."""

from __future__ import annotations

import numpy as np

from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.shortcut import SegmentChecker, shorten
from asmteach.plugins.planners.motion.toyworld import Box, JointWorld


def length(path: np.ndarray) -> float:
    return float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))


def test_zigzag_in_free_space_becomes_one_segment() -> None:
    path = np.array([[0.0, 0.0], [0.5, 1.0], [1.0, -1.0], [1.5, 1.0], [2.0, 0.0]])
    ok = SegmentChecker(lambda qs: np.ones(len(qs), dtype=bool), 0.01)
    out = shorten(path, ok, np.random.default_rng(0))
    assert np.array_equal(out, path[[0, -1]])
    assert ok.calls > 0


def test_around_a_box_valid_shorter_deterministic() -> None:
    world = JointWorld(-3 * np.ones(2), 3 * np.ones(2), [Box(np.zeros(2), np.array([0.5, 0.5]))])
    path = np.array([[-2.0, 0.0], [-2.0, -1.0], [-1.0, -1.0], [0.0, -1.0], [1.0, -1.0], [2.0, -1.0], [2.0, 0.0]])
    assert np.all(world.valid_batch(densify(path, 0.01)))

    def run(seed: int) -> np.ndarray:
        return shorten(path, SegmentChecker(world.valid_batch, 0.01), np.random.default_rng(seed))

    out = run(1)
    assert np.array_equal(out[0], path[0]) and np.array_equal(out[-1], path[-1])
    assert np.all(world.valid_batch(densify(out, 0.002)))
    assert length(out) < length(path) - 0.5
    assert np.array_equal(out, run(1))


def test_cost_ceiling_keeps_the_detour() -> None:
    """Free space, but a cost hill at the origin: the chord through it is refused, the detour kept."""
    path = np.array([[-2.0, 0.0], [-1.5, 1.5], [0.0, 2.0], [1.5, 1.5], [2.0, 0.0]])

    def hill(qs: np.ndarray) -> np.ndarray:
        return np.exp(-np.sum(np.atleast_2d(qs) ** 2, axis=1))

    ceiling = float(hill(densify(path, 0.04)).max())
    free = SegmentChecker(lambda qs: np.ones(len(qs), dtype=bool), 0.01, cost_batch=hill, ceiling=ceiling)
    out = shorten(path, free, np.random.default_rng(0))
    assert np.array_equal(out[[0, -1]], path[[0, -1]])
    assert hill(densify(out, 0.01)).max() <= ceiling * 1.05
    assert length(out) <= length(path) + 1e-9
    assert np.min(np.linalg.norm(densify(out, 0.01), axis=1)) > 1.0


def test_a_segment_over_the_ceiling_is_refused_before_its_fine_states() -> None:
    """The verdict is every check's; the order only decides what a refused segment costs."""
    calls: list[int] = []

    def free(qs: np.ndarray) -> np.ndarray:
        calls.append(len(qs))
        return np.ones(len(qs), dtype=bool)

    def hill(qs: np.ndarray) -> np.ndarray:
        return np.exp(-np.sum(np.atleast_2d(qs) ** 2, axis=1))

    seg = SegmentChecker(free, 0.01, cost_batch=hill, ceiling=0.5)
    a, b = np.array([-1.0, 0.0]), np.array([1.0, 0.0])  # 199 states between, the hill's top (1.0) at the middle
    assert not seg(a, b)
    assert calls == [25] and seg.cost_calls == 1  # the coarse states only: every 8th
    aside = np.array([0.0, 2.0])
    assert seg(a + aside, b + aside)  # the same segment 2 rad aside: cost <= e^-4 everywhere
    assert calls[1:] == [25, 174] and seg.cost_calls == 2
