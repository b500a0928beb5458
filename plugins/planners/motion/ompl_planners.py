"""OMPL's own geometric planners behind the :class:`MotionPlanner` interface.

:class:`RRTConnectPlanner` runs ``og.RRTConnect`` (bidirectional RRT, Kuffner and
LaValle 2000) on the same :class:`~asmteach.plugins.planners.motion.space.JointSpace`
as T-RRT, so the two are swap-ins: same query, same validity and motion checks,
same simplifier (the batched shortener when ``is_valid`` has a batch, else
OMPL's; OMPL's checks one state per python call and took 78 % of a
peg-in-hole assembly plan). RRTConnect ignores the cost map (it only looks for
a feasible path); the cost, when given, only keeps the simplifier from
shortcutting through states costlier than the costliest point of the found
path. Its own tree search checks one state per call (OMPL's motion validator).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
from ompl import base as ob
from ompl import geometric as og

from asmteach.core.failures import FailureKind
from asmteach.core.interfaces import MotionPlanner, MotionResult
from asmteach.core.trajectory.batch import batch_of
from asmteach.plugins.planners.motion.query import (
    MotionSettings,
    check_query,
    default_range,
    failure,
    finish_path,
    shorten_batched,
)
from asmteach.plugins.planners.motion.space import quiet_ompl, seed_ompl

__all__ = ["RRTConnectPlanner", "RRTConnectSettings"]


class RRTConnectSettings(MotionSettings):
    """RRTConnect parameters: the shared ones (range = OMPL's ``setRange``, radians)."""


class RRTConnectPlanner(MotionPlanner):
    """OMPL's ``og.RRTConnect``; reproducible per query like :class:`TRRTPlanner`
    (the ``k``-th call seeds OMPL's RNG from ``self.rng(k)``), as long as it
    finishes before its time limit."""

    Settings = RRTConnectSettings
    settings: RRTConnectSettings

    def __init__(self, settings: RRTConnectSettings | dict | None = None, *, seed: int = 0) -> None:
        super().__init__(settings, seed=seed)
        self._calls = 0

    def plan(
        self,
        start: np.ndarray,
        goal: np.ndarray,
        *,
        lower: np.ndarray,
        upper: np.ndarray,
        is_valid: Callable[[np.ndarray], bool],
        cost: Callable[[np.ndarray], float] | None = None,
        time_limit: float = 5.0,
    ) -> MotionResult:
        """Plan from ``start`` to ``goal`` (radians) within ``[lower, upper]``; see :class:`MotionPlanner`."""
        t0 = time.perf_counter()
        cfg = self.settings
        rng = self.rng(self._calls)
        self._calls += 1
        space, q_start, q_goal, failed = check_query(start, goal, lower, upper, is_valid, cfg)
        if failed is not None:
            return failed
        seed_ompl(int(rng.integers(2**31 - 1)))
        problem = ob.ProblemDefinition(space.si)
        problem.setStartAndGoalStates(space.to_state(q_start), space.to_state(q_goal))
        planner = og.RRTConnect(space.si)
        planner.setRange(default_range(space, cfg))
        planner.setProblemDefinition(problem)
        remaining = max(time_limit - (time.perf_counter() - t0), 1e-3)
        with quiet_ompl():
            planner.setup()
            planner.solve(ob.timedPlannerTerminationCondition(remaining))
        stats: dict = {"planner": "rrtconnect", "range": default_range(space, cfg)}
        if not problem.hasExactSolution():
            stats.update(validity_checks=space.n_checks, time=time.perf_counter() - t0)
            return failure(FailureKind.TIMEOUT, f"after {time_limit} s", **stats)
        raw = space.from_path(problem.getSolutionPath())
        valid_batch = getattr(is_valid, "batch", None)
        if cfg.simplify and valid_batch is not None:
            path, segment_ok = shorten_batched(
                space, raw, cfg, rng, valid_batch=valid_batch, cost_batch=None if cost is None else batch_of(cost)
            )
            stats.update(batch_calls=segment_ok.calls, batch_states=segment_ok.states)
        else:
            path = finish_path(space, raw, cfg, cost)
        stats.update(
            raw_waypoints=len(raw),
            raw_length=float(np.sum(np.linalg.norm(np.diff(raw, axis=0), axis=1))),
            length=float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            validity_checks=space.n_checks,
            time=time.perf_counter() - t0,
        )
        return MotionResult(success=True, path=path, reason=None, stats=stats)
