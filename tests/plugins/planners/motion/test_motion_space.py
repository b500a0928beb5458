from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.errors import UserError
from asmteach.plugins.planners.motion.space import JointSpace, seed_ompl

LOWER, UPPER = np.array([-1.0, -2.0, -0.5]), np.array([1.0, 2.0, 0.5])


def outside_ball(q: np.ndarray) -> bool:
    return bool(np.linalg.norm(q[:2]) > 0.3)


def test_conversion_round_trip_and_checks() -> None:
    space = JointSpace(LOWER, UPPER, outside_ball, resolution=0.01)
    q = np.array([0.25, -1.5, 0.125])
    assert np.array_equal(space.to_numpy(space.to_state(q)), q)
    path = np.array([[-0.9, 0.0, 0.0], [-0.9, 1.0, 0.0], [0.9, 1.0, 0.1]])
    assert np.array_equal(space.from_path(space.to_path(path)), path)
    assert space.is_valid(np.array([0.5, 0.5, 0.0])) and not space.is_valid(np.zeros(3))
    assert not space.is_valid(np.array([1.5, 0.0, 0.0]))  # out of bounds
    # The straight segment through the ball is refused; the detour is accepted.
    assert not space.check_motion(np.array([-0.9, 0.0, 0.0]), np.array([0.9, 0.0, 0.0]))
    assert space.check_path(path)
    with pytest.raises(UserError, match="lower < upper"):
        JointSpace(UPPER, LOWER, outside_ball)


def test_sampler_in_bounds_and_seeded() -> None:
    space = JointSpace(LOWER, UPPER, outside_ball)
    seed_ompl(11)
    draw = space.sampler()
    a = np.array([draw() for _ in range(200)])
    assert np.all(a >= LOWER) and np.all(a <= UPPER)
    other = JointSpace(LOWER, UPPER, outside_ball)
    seed_ompl(11)  # after building the space: its setup draws from OMPL's seed sequence too
    draw = other.sampler()
    assert np.array_equal(a, np.array([draw() for _ in range(200)]))


def test_cost_ceiling_guides_simplifier() -> None:
    """A detour around a costly disc survives simplification only under the cost ceiling."""
    space = JointSpace(LOWER, UPPER, lambda q: True, resolution=0.01)

    def cost(q: np.ndarray) -> float:
        return 10.0 if np.linalg.norm(q[:2]) < 0.5 else 1.0

    detour = np.array([[-0.9, 0.0, 0.0], [-0.9, 1.0, 0.0], [0.9, 1.0, 0.0], [0.9, 0.0, 0.0]])
    seed_ompl(1)
    free = space.simplify(detour)
    assert len(free) == 2  # cost-blind: straight through the disc
    seed_ompl(1)
    bounded = space.simplify(detour, cost=cost, ceiling=1.0)
    assert max(cost(q) for q in np.linspace(bounded[:-1], bounded[1:], 50).reshape(-1, 3)) == 1.0
    assert np.allclose(bounded[0], detour[0]) and np.allclose(bounded[-1], detour[-1])
    assert space.is_valid(np.zeros(3))  # the ceiling is lifted after the call
