"""Transition-based RRT (Jaillet, Cortes, Simeon 2008) on OMPL 2's state space.

T-RRT grows one tree from the start like RRT, but filters every new node by
the cost map: a step downhill is always accepted, a step uphill with
probability ``exp(-(dc / d) / (K T))`` (slope ``dc/d`` over the step length,
``K`` the mean cost of start and goal). The temperature ``T`` adapts: it is
divided by ``alpha`` after each accepted uphill step (be stricter) and
multiplied by ``alpha`` after ``max_fail`` consecutive rejections (relax), so the
tree follows valleys of the cost map and climbs only where it must. Minimum
expansion control keeps the tree exploring: a node whose random target lies
within one step of the tree is a refinement node, and refinement nodes are
refused while they exceed ``frontier_ratio`` times the frontier (expansion) nodes.

OMPL 2.0.1's python bindings have no TRRT (and ompl 1.7's corrupts memory), so
the loop is written here; OMPL provides the bounded state space, the uniform
state sampler (seeded through ``ompl.util.RNG``), state validity and discrete
motion validation (``si.checkMotion``), and the final ``og.PathSimplifier``.
Nearest neighbours are a vectorised numpy scan (OMPL's ``NearestNeighbors`` is
not bound in python).

Cost map: ``cost(q)``, higher is worse, supplied by the caller. The assembly
planner passes inverse clearance, ``1 / max(clearance(q), floor)`` with the
robot's clearance to the world in metres (see :func:`inverse_clearance_cost`),
so paths keep away from obstacles. Without a cost the planner is a goal-biased
RRT with expansion control.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np
from pydantic import Field

from asmteach.core.interfaces import MotionPlanner, MotionResult
from asmteach.plugins.planners.motion.query import (
    FailureKind,
    MotionSettings,
    check_query,
    default_range,
    failure,
    finish_path,
)
from asmteach.plugins.planners.motion.space import seed_ompl

__all__ = ["TRRTPlanner", "TRRTSettings", "inverse_clearance_cost"]


class TRRTSettings(MotionSettings):
    """T-RRT parameters (names after Jaillet et al. 2008; radians, seconds)."""

    goal_bias: float = Field(
        0.05, ge=0, le=1, description="Probability of sampling the goal instead of a random state."
    )
    init_temperature: float = Field(
        1.0, gt=0, description="Initial temperature T of the transition test (dimensionless; cost slope / K)."
    )
    temperature_factor: float = Field(
        2.0, gt=1, description="alpha: T /= alpha after an accepted uphill step, T *= alpha after max_fail rejections."
    )
    max_fail: int = Field(10, ge=1, description="Consecutive rejected uphill steps before the temperature rises.")
    cost_threshold: float = Field(
        math.inf, gt=0, description="c_max: states costlier than this are never added (inf: no limit)."
    )
    frontier_ratio: float = Field(
        0.1, ge=0, description="rho: refinement nodes allowed per frontier node (minimum expansion control)."
    )
    frontier_threshold: float | None = Field(
        None,
        gt=0,
        description="A random target farther than this (radians) from its nearest node makes a frontier node; "
        "None: the step size (range).",
    )
    max_iterations: int = Field(200_000, ge=1, description="Upper bound on tree-growing iterations per query.")


def inverse_clearance_cost(
    clearance: Callable[[np.ndarray], float], floor: float = 1e-3
) -> Callable[[np.ndarray], float]:
    """The cost map the assembly planner uses: ``1 / max(clearance(q), floor)``.

    ``clearance(q)`` is the distance in metres from the robot (and held part) to
    the world at ``q``; ``floor`` (metres) bounds the cost where it touches.
    """

    def cost(q: np.ndarray) -> float:
        return 1.0 / max(float(clearance(q)), floor)

    return cost


def _zero_cost(q: np.ndarray) -> float:
    return 0.0


class TRRTPlanner(MotionPlanner):
    """Transition-based RRT with adaptive temperature and frontier control (see module doc).

    Queries are reproducible: the ``k``-th call of a planner built with seed ``s``
    draws from ``self.rng(k)`` and seeds OMPL's RNG from it.
    """

    Settings = TRRTSettings
    settings: TRRTSettings

    def __init__(self, settings: TRRTSettings | dict | None = None, *, seed: int = 0) -> None:
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
        cost_fn = cost if cost is not None else _zero_cost
        step = default_range(space, cfg, fraction=0.05)
        frontier_threshold = cfg.frontier_threshold if cfg.frontier_threshold is not None else step

        seed_ompl(int(rng.integers(2**31 - 1)))
        draw = space.sampler()

        cap = 1024
        nodes = np.empty((cap, space.dof))
        parents = np.empty(cap, dtype=np.int64)
        costs = np.empty(cap)
        nodes[0], parents[0], costs[0] = q_start, -1, float(cost_fn(q_start))
        n = 1
        c_goal = float(cost_fn(q_goal))
        # K normalises cost slopes so the temperature is dimensionless (paper: mean cost of the end points).
        k_norm = max(0.5 * (costs[0] + c_goal), 1e-12)
        temperature = cfg.init_temperature
        n_fail = n_frontier = n_refine = 0
        counts = {"collision": 0, "transition": 0, "refinement": 0, "motion": 0, "uphill_accepted": 0}
        goal_index = -1

        def transition_test(c_from: float, c_to: float, dist: float) -> bool:
            # Jaillet et al. 2008, Alg. 2: downhill always; uphill by a Metropolis test on the slope.
            nonlocal temperature, n_fail
            if c_to > cfg.cost_threshold:
                return False
            if c_to <= c_from:
                return True
            slope = (c_to - c_from) / max(dist, 1e-12)
            if rng.random() < math.exp(-slope / (k_norm * temperature)):
                temperature /= cfg.temperature_factor
                n_fail = 0
                counts["uphill_accepted"] += 1
                return True
            if n_fail > cfg.max_fail:
                temperature *= cfg.temperature_factor
                n_fail = 0
            else:
                n_fail += 1
            return False

        iteration = 0
        timed_out = False
        for iteration in range(1, cfg.max_iterations + 1):  # noqa: B007 - reported in stats
            if time.perf_counter() - t0 > time_limit:
                timed_out = True
                break
            to_goal = rng.random() < cfg.goal_bias
            q_rand = q_goal if to_goal else draw()
            d2 = np.einsum("ij,ij->i", nodes[:n] - q_rand, nodes[:n] - q_rand)
            i_near = int(np.argmin(d2))
            d_rand = math.sqrt(float(d2[i_near]))
            if d_rand < 1e-12:
                continue
            q_near = nodes[i_near]
            q_new = q_near + (q_rand - q_near) * (step / d_rand) if d_rand > step else q_rand.copy()
            d_new = min(d_rand, step)
            # Minimum expansion control; a goal sample is exempt so the tree can always finish.
            frontier = d_rand > frontier_threshold
            if not frontier and not to_goal and n_refine > cfg.frontier_ratio * max(n_frontier, 1):
                counts["refinement"] += 1
                continue
            if not space.is_valid(q_new):
                counts["collision"] += 1
                continue
            c_new = float(cost_fn(q_new))
            if not transition_test(float(costs[i_near]), c_new, d_new):
                counts["transition"] += 1
                continue
            if not space.check_motion(q_near, q_new):
                counts["motion"] += 1
                continue
            if n == cap:
                cap *= 2
                nodes = np.resize(nodes, (cap, space.dof))
                parents = np.resize(parents, cap)
                costs = np.resize(costs, cap)
            nodes[n], parents[n], costs[n] = q_new, i_near, c_new
            n += 1
            if frontier:
                n_frontier += 1
            else:
                n_refine += 1
            if np.array_equal(q_new, q_goal):
                goal_index = n - 1
                break
            if np.linalg.norm(q_goal - q_new) <= step and space.check_motion(q_new, q_goal):
                nodes[n], parents[n], costs[n] = q_goal, n - 1, c_goal
                goal_index = n
                n += 1
                break

        stats = {
            "planner": "trrt",
            "iterations": iteration,
            "nodes": n,
            "frontier_nodes": n_frontier,
            "refinement_nodes": n_refine,
            "temperature": temperature,
            "rejected": counts,
            "range": step,
        }
        if goal_index < 0:
            stats["validity_checks"] = space.n_checks
            stats["time"] = time.perf_counter() - t0
            stats["closest_to_goal"] = float(np.min(np.linalg.norm(nodes[:n] - q_goal, axis=1)))
            if timed_out:
                return failure(FailureKind.TIMEOUT, f"after {time_limit} s ({n} nodes)", **stats)
            return failure(FailureKind.ITERATIONS, f"of {cfg.max_iterations} reached ({n} nodes)", **stats)

        chain = [goal_index]
        while parents[chain[-1]] >= 0:
            chain.append(int(parents[chain[-1]]))
        raw = nodes[np.array(chain[::-1])].copy()
        path = finish_path(space, raw, cfg, cost)
        stats.update(
            raw_waypoints=len(raw),
            raw_length=float(np.sum(np.linalg.norm(np.diff(raw, axis=0), axis=1))),
            length=float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            validity_checks=space.n_checks,
            time=time.perf_counter() - t0,
        )
        return MotionResult(success=True, path=path, reason=None, stats=stats)
