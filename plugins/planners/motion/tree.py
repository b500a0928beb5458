"""The trees T-RRT grows and the checks it grows them with (joint space, radians).

:class:`Tree` holds nodes with parent indices and cached costs; :class:`Checks`
answers state and motion validity and costs, batched when the callables offer
``batch`` (:mod:`asmteach.core.trajectory.batch`), and counts the calls.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable

import numpy as np

from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.space import JointSpace

__all__ = ["Checks", "Grow", "Tree"]


class Grow(enum.Enum):
    """What one extension step did."""

    TRAPPED = 0
    ADVANCED = 1
    REACHED = 2


class Tree:
    """Nodes ``(n, dof)`` radians with parent indices and cached costs; the root is node 0."""

    def __init__(self, root: np.ndarray, cost: float, is_start: bool) -> None:
        self.is_start = is_start
        self.nodes = np.empty((256, root.size))
        self.parents = np.empty(256, dtype=np.int64)
        self.costs = np.empty(256)
        self.n = 0
        self.add(root, -1, cost)

    def add(self, q: np.ndarray, parent: int, cost: float) -> int:
        if self.n == len(self.nodes):
            grow = len(self.nodes)
            self.nodes = np.concatenate([self.nodes, np.empty_like(self.nodes)])
            self.parents = np.concatenate([self.parents, np.empty(grow, dtype=np.int64)])
            self.costs = np.concatenate([self.costs, np.empty(grow)])
        self.nodes[self.n], self.parents[self.n], self.costs[self.n] = q, parent, cost
        self.n += 1
        return self.n - 1

    def nearest(self, q: np.ndarray) -> tuple[int, float]:
        diff = self.nodes[: self.n] - q
        d2 = np.einsum("ij,ij->i", diff, diff)
        i = int(np.argmin(d2))
        return i, math.sqrt(float(d2[i]))

    def chain(self, i: int) -> np.ndarray:
        """Nodes from the root to node ``i``."""
        idx = [i]
        while self.parents[idx[-1]] >= 0:
            idx.append(int(self.parents[idx[-1]]))
        return self.nodes[np.array(idx[::-1])].copy()


class Checks:
    """State and motion validity and costs, batched when the callables offer ``batch``; counts the calls."""

    def __init__(
        self,
        space: JointSpace,
        is_valid: Callable[[np.ndarray], bool],
        cost: Callable[[np.ndarray], float] | None,
    ) -> None:
        self.space = space
        self.is_valid = is_valid
        self.valid_batch = getattr(is_valid, "batch", None)
        self.cost_fn = cost
        self.cost_batch = getattr(cost, "batch", None) if cost is not None else None
        self.batch_calls = 0
        self.batch_states = 0
        self.cost_evals = 0

    def state(self, q: np.ndarray) -> bool:
        """Validity of one configuration within bounds (the user's check, called directly)."""
        if not self.space.in_bounds(q):
            return False
        self.batch_states += 1
        return bool(self.is_valid(q))

    def motion(self, qa: np.ndarray, qb: np.ndarray) -> bool:
        """The straight segment ``qa -> qb`` (end points assumed valid) at the space's resolution."""
        if self.valid_batch is None:
            return self.space.check_motion(qa, qb)
        return self.states(densify(np.stack([qa, qb]), self.space.resolution)[1:-1])

    def states(self, qs: np.ndarray) -> bool:
        """Every one of ``qs`` ``(n, dof)`` valid, in one batched call (``valid_batch`` must exist)."""
        if len(qs) == 0:
            return True
        assert self.valid_batch is not None
        self.batch_calls += 1
        self.batch_states += len(qs)
        return bool(np.all(np.asarray(self.valid_batch(qs), dtype=bool)))

    def cost(self, q: np.ndarray) -> float:
        if self.cost_fn is None:
            return 0.0
        self.cost_evals += 1
        return float(self.cost_fn(q))

    def costs(self, qs: np.ndarray) -> np.ndarray:
        if self.cost_fn is None:
            return np.zeros(len(qs))
        self.cost_evals += len(qs)
        if self.cost_batch is not None:
            return np.asarray(self.cost_batch(qs), dtype=float).reshape(-1)
        return np.array([float(self.cost_fn(q)) for q in qs])
