"""Per-configuration callables with an optional vectorised twin (``fn.batch(qs)``).

The :class:`~asmteach.core.interfaces.MotionPlanner` contract passes
``is_valid(q) -> bool`` and ``cost(q) -> float`` for one ``(dof,)``
configuration. Robot collision checkers are far cheaper per configuration in
batches (the Nextage's checker: ~1.2 ms for one configuration, ~45 us each in a
batch), so a caller may hand a :class:`Batched` callable instead: it still
answers one configuration (OMPL's validity checker and RRTConnect use that) and
also ``batch(qs)`` for ``(n, dof)`` configurations, which T-RRT uses to check a
whole motion segment in one call. Any plain callable works too:
:func:`batch_of` falls back to a python loop. :func:`inverse_clearance_cost`
turns a (batched) clearance into the cost map a cost-aware planner climbs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["Batched", "batch_of", "batched", "inverse_clearance_cost"]


@dataclass(frozen=True)
class Batched:
    """``one(q)`` for a ``(dof,)`` configuration and ``many(qs) -> (n,)`` for ``(n, dof)``; both must agree."""

    one: Callable[[np.ndarray], Any]
    many: Callable[[np.ndarray], np.ndarray]

    def __call__(self, q: np.ndarray) -> Any:
        return self.one(q)

    def batch(self, qs: np.ndarray) -> np.ndarray:
        """``(n,)`` results for ``(n, dof)`` configurations (radians)."""
        return np.asarray(self.many(np.atleast_2d(np.asarray(qs, dtype=float)))).reshape(-1)


def batched(one: Callable[[np.ndarray], Any], many: Callable[[np.ndarray], np.ndarray]) -> Batched:
    """A callable answering one configuration with ``one`` and ``fn.batch(qs)`` with ``many``.

    For validity, ``one`` must return a python ``bool`` (OMPL's validity checker
    needs one) and ``many`` a ``(n,)`` bool array; for a cost, floats.
    """
    return Batched(one, many)


def batch_of(fn: Callable[[np.ndarray], Any]) -> Callable[[np.ndarray], np.ndarray]:
    """The vectorised form of ``fn``: its own ``batch`` when it has one, else a loop over rows."""
    vec = getattr(fn, "batch", None)
    if callable(vec):
        return vec

    def loop(qs: np.ndarray) -> np.ndarray:
        return np.array([fn(q) for q in np.atleast_2d(qs)])

    return loop


def inverse_clearance_cost(
    clearance: Callable[[np.ndarray], float], floor: float = 1e-3, cap: float = math.inf
) -> Callable[[np.ndarray], float]:
    """Cost map ``1 / min(max(clearance(q), floor), cap)`` (1 / metres for a robot, 1 / radians in toy worlds).

    ``clearance(q)`` is the distance from the robot (and held part) to the
    world at ``q``. ``floor`` bounds the cost where it touches; ``cap`` is the
    clearance beyond which the planner does not care (the cost is flat there, so
    open space is explored freely and the transition test only bites near
    obstacles). When ``clearance`` has a vectorised twin ``clearance.batch(qs)``
    the cost gets one too.
    """
    lo, hi = float(floor), float(cap)
    if not 0 < lo < hi:
        raise ValueError(f"inverse_clearance_cost needs 0 < floor < cap (got floor={floor}, cap={cap})")

    def one(q: np.ndarray) -> float:
        return 1.0 / min(max(float(clearance(q)), lo), hi)

    many = getattr(clearance, "batch", None)
    if callable(many):
        return Batched(one, lambda qs: 1.0 / np.clip(np.asarray(many(qs), dtype=float), lo, hi))
    return one
