"""Transition-based RRT on OMPL 2's state space, bidirectional (BiTRRT).

T-RRT (Jaillet, Cortes, Simeon 2008) grows RRT trees but filters every new
node by a cost map: a step downhill is always accepted, a step uphill by
``dc > 0`` with probability ``exp(-dc / (K T))`` (``K`` the mean cost of start
and goal, so the temperature ``T`` is dimensionless). The temperature adapts
so that the trees follow the valleys of the cost map and climb only where they
must. Minimum expansion control keeps the trees exploring: a node whose random
target lies within ``frontier_threshold`` of the tree refines it, and refinement
nodes are refused while they exceed ``frontier_ratio`` times the frontier nodes.

This is the bidirectional variant (BiTRRT, Devaurs, Simeon, Cortes 2013): one
tree from the start and one from the goal, swapped every iteration; each
iteration extends one tree one step towards a uniform sample, then greedily
extends the other tree towards the new node, every step of that connection
subject to the transition test too (in each tree's growth direction). The
temperature self-tunes as in that paper: an accepted uphill step divides ``T``
by ``2 ** (dc / (0.1 * cost range))`` (cost range: worst minus best node cost
so far), a rejected one multiplies it by ``exp(temperature_rise)``; so ``T``
cools after climbs and warms slowly while the trees are stuck. One deviation:
a single cooling step is capped at ``2 ** max_cooling`` (halving by default).
Early on the cost range seen is small, and with a steep cost such as inverse
clearance one accepted climb would otherwise divide ``T`` by thousands and
freeze both trees in their start basins (on the 6-D benchmark, 10 seeds:
90th percentile planning time 3.3 s uncapped, 0.06 s capped).

Before growing trees the planner tries the straight motion start -> goal: it is
taken when it is collision-free and, with a cost map, never costlier than the
costlier end point (it keeps at least the clearance the end points have).

OMPL 2.0.1's python bindings have no TRRT (and ompl 1.7's corrupts memory), so
the loop is written here; OMPL provides the bounded state space, the uniform
state sampler (seeded through ``ompl.util.RNG``), state validity and discrete
motion validation (``si.checkMotion``), and the final ``og.PathSimplifier``.
When ``is_valid`` (or ``cost``) has a vectorised twin ``fn.batch(qs)`` (see
:mod:`.batch`), every tree edge is checked in one call at the motion
resolution instead of one call per state, which is what makes planning on a
real robot's collision checker fast. Nearest neighbours are a vectorised numpy
scan (OMPL's ``NearestNeighbors`` is not bound in python).

Cost map: ``cost(q)``, higher is worse, supplied by the caller and evaluated
once per tree node (cached with the node). :func:`inverse_clearance_cost` is
the one meant for the assembly planner: inverse clearance between a floor and a
cap, so that paths keep away from obstacles where it matters and the open
space is flat (free exploration). Without a cost the planner is a plain
bidirectional RRT with expansion control.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pydantic import Field
from scipy.spatial import cKDTree

from asmteach.core.failures import FailureKind
from asmteach.core.interfaces import MotionPlanner, MotionResult
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.motion.query import (
    MotionSettings,
    check_query,
    default_range,
    failure,
    finish_path,
    shorten_batched,
)
from asmteach.plugins.planners.motion.space import JointSpace, seed_ompl
from asmteach.plugins.planners.motion.tree import Checks, Grow, Tree

__all__ = ["TRRTPlanner", "TRRTSettings"]


class TRRTSettings(MotionSettings):
    """BiTRRT parameters (names after Jaillet et al. 2008 and Devaurs et al. 2013; radians, seconds)."""

    init_temperature: float = Field(
        1.0, gt=0, description="Initial temperature T of the transition test (dimensionless: cost rise / K)."
    )
    temperature_rise: float = Field(
        0.1, gt=0, description="T *= exp(temperature_rise) after each rejected uphill step (Devaurs et al. 2013)."
    )
    max_cooling: float = Field(
        1.0,
        gt=0,
        description="Cap on the exponent of one cooling step (T /= 2 ** min(dc / (0.1 range), max_cooling)).",
    )
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
    direct_first: bool = Field(
        True, description="Try the straight motion start -> goal first (taken if valid and not costlier than its ends)."
    )
    max_iterations: int = Field(200_000, ge=1, description="Upper bound on tree-growing iterations per query.")


class _Transition:
    """The transition test with self-tuning temperature (Jaillet et al. 2008, Devaurs et al. 2013)."""

    def __init__(self, cfg: TRRTSettings, k_norm: float, costs: tuple[float, float], rng: np.random.Generator) -> None:
        self.cfg = cfg
        self.k = k_norm
        self.rng = rng
        self.temperature = cfg.init_temperature
        self.best, self.worst = min(costs), max(costs)
        self.accepted_uphill = 0
        self.rejected = 0

    def seen(self, c: float) -> None:
        self.best, self.worst = min(self.best, c), max(self.worst, c)

    def __call__(self, c_from: float, c_to: float) -> bool:
        if c_to > self.cfg.cost_threshold:
            self.rejected += 1
            return False
        dc = c_to - c_from
        if dc <= 0.0:
            return True
        if self.rng.random() < math.exp(-dc / (self.k * self.temperature)):
            cost_range = max(self.worst, c_to) - self.best
            if cost_range > 1e-12:
                # Cool down in proportion to the climb relative to the costs seen so far, but at most by half:
                # early on the range seen is small and one climb would otherwise freeze the trees.
                self.temperature /= 2.0 ** min(dc / (0.1 * cost_range), self.cfg.max_cooling)
            self.accepted_uphill += 1
            return True
        self.temperature *= math.exp(self.cfg.temperature_rise)
        self.rejected += 1
        return False


class TRRTPlanner(MotionPlanner):
    """Bidirectional Transition-based RRT with self-tuning temperature and frontier control (see module doc).

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
        """Plan from ``start`` to ``goal`` (radians) within ``[lower, upper]``; see :class:`MotionPlanner`.

        ``is_valid`` and ``cost`` may carry a vectorised ``batch(qs)`` (see :mod:`.batch`).
        """
        t0 = time.perf_counter()
        cfg = self.settings
        rng = self.rng(self._calls)
        self._calls += 1
        space, q_start, q_goal, failed = check_query(start, goal, lower, upper, is_valid, cfg)
        if failed is not None:
            return failed
        checks = Checks(space, is_valid, cost)
        step = default_range(space, cfg, fraction=0.05)
        frontier_threshold = cfg.frontier_threshold if cfg.frontier_threshold is not None else step
        c_start, c_goal = checks.cost(q_start), checks.cost(q_goal)
        stats: dict[str, Any] = {"planner": "trrt", "range": step, "direct": False}

        if cfg.direct_first and self._direct_ok(checks, q_start, q_goal, max(c_start, c_goal)):
            stats.update(direct=True, iterations=0, nodes=2)
            return self._finish(space, checks, np.stack([q_start, q_goal]), cost, stats, t0, rng)

        seed_ompl(int(rng.integers(2**31 - 1)))
        draw = space.sampler()
        trees = (Tree(q_start, c_start, True), Tree(q_goal, c_goal, False))
        # K normalises cost rises so the temperature is dimensionless (Jaillet et al.: mean cost of the end points).
        k_norm = max(0.5 * (abs(c_start) + abs(c_goal)), 1e-12)
        transition = _Transition(cfg, k_norm, (c_start, c_goal), rng)
        counts = {"collision": 0, "transition": 0, "refinement": 0, "motion": 0}
        frontier = {"frontier": 0, "refinement": 0}

        def extend(tree: Tree, i_near: int, target: np.ndarray, d: float, explore: bool) -> tuple[Grow, int]:
            """One step of at most ``step`` from node ``i_near`` towards ``target`` (``d`` away)."""
            if d < 1e-12:
                return Grow.REACHED, i_near
            q_near = tree.nodes[i_near]
            reach = d <= step
            q_new = target.copy() if reach else q_near + (target - q_near) * (step / d)
            is_frontier = d > frontier_threshold
            refine_quota = cfg.frontier_ratio * max(frontier["frontier"], 1)
            if explore and not is_frontier and frontier["refinement"] > refine_quota:
                counts["refinement"] += 1
                return Grow.TRAPPED, i_near
            if not checks.state(q_new):
                counts["collision"] += 1
                return Grow.TRAPPED, i_near
            c_new = checks.cost(q_new)
            if not transition(float(tree.costs[i_near]), c_new):
                counts["transition"] += 1
                return Grow.TRAPPED, i_near
            # The goal tree's edges are travelled backwards; the discrete check is symmetric, so the order is moot.
            if not checks.motion(q_near, q_new):
                counts["motion"] += 1
                return Grow.TRAPPED, i_near
            i_new = tree.add(q_new, i_near, c_new)
            transition.seen(c_new)
            if explore:
                frontier["frontier" if is_frontier else "refinement"] += 1
            return (Grow.REACHED if reach else Grow.ADVANCED), i_new

        def connect(tree: Tree, target: np.ndarray) -> tuple[Grow, int]:
            """Greedy steps of ``tree`` towards ``target``, each one subject to the transition test."""
            i, d = tree.nearest(target)
            while True:
                grow, i = extend(tree, i, target, d, explore=False)
                if grow is not Grow.ADVANCED:
                    return grow, i
                d = float(np.linalg.norm(target - tree.nodes[i]))

        iteration = 0
        timed_out = False
        joint: tuple[Tree, int, Tree, int] | None = None
        for iteration in range(1, cfg.max_iterations + 1):
            if time.perf_counter() - t0 > time_limit:
                timed_out = True
                break
            grow_tree, other = trees[iteration % 2 == 0], trees[iteration % 2 == 1]
            q_rand = draw()
            i_near, d = grow_tree.nearest(q_rand)
            grow, i_new = extend(grow_tree, i_near, q_rand, d, explore=True)
            if grow is Grow.TRAPPED or i_new == i_near:
                continue
            reached, j = connect(other, grow_tree.nodes[i_new])
            if reached is Grow.REACHED:
                joint = (grow_tree, i_new, other, j)
                break

        stats.update(
            iterations=iteration,
            nodes=trees[0].n + trees[1].n,
            start_nodes=trees[0].n,
            goal_nodes=trees[1].n,
            frontier_nodes=frontier["frontier"],
            refinement_nodes=frontier["refinement"],
            temperature=transition.temperature,
            uphill_accepted=transition.accepted_uphill,
            rejected=counts,
        )
        if joint is None:
            stats.update(self._check_stats(space, checks), time=time.perf_counter() - t0)
            # How close the trees came (radians): tells "almost connected" from "stuck near the start".
            gap, _ = cKDTree(trees[1].nodes[: trees[1].n]).query(trees[0].nodes[: trees[0].n])
            stats["tree_gap"] = float(np.min(gap))
            if timed_out:
                return failure(FailureKind.TIMEOUT, f"after {time_limit} s ({stats['nodes']} nodes)", **stats)
            return failure(FailureKind.ITERATIONS, f"of {cfg.max_iterations} reached ({stats['nodes']} nodes)", **stats)

        tree_a, i, tree_b, j = joint
        # Both chains end at the connection node; the start tree's chain runs forwards, the goal tree's backwards.
        head, tail = (tree_a.chain(i), tree_b.chain(j)) if tree_a.is_start else (tree_b.chain(j), tree_a.chain(i))
        raw = np.vstack([head, tail[::-1][1:]])
        return self._finish(space, checks, raw, cost, stats, t0, rng)

    @staticmethod
    def _direct_ok(checks: Checks, q_start: np.ndarray, q_goal: np.ndarray, ceiling: float) -> bool:
        """The straight motion is valid and, with a cost, nowhere costlier than ``ceiling`` (checked at resolution).

        With batched checks, every 8th state first, validity then cost, then the others: most straight
        motions fail, and most of those on a few of the states.
        """
        ceiling *= 1 + 1e-9

        def below(states: np.ndarray) -> bool:
            return checks.cost_fn is None or len(states) == 0 or bool(np.max(checks.costs(states)) <= ceiling)

        line = densify(np.stack([q_start, q_goal]), checks.space.resolution)[1:-1]  # strictly between
        if checks.valid_batch is None:
            return checks.motion(q_start, q_goal) and below(line)
        first = np.zeros(len(line), dtype=bool)
        first[::8] = True
        return checks.states(line[first]) and below(line[first]) and checks.states(line[~first]) and below(line[~first])

    @staticmethod
    def _check_stats(space: JointSpace, checks: Checks) -> dict[str, int]:
        return {
            "validity_checks": space.n_checks + checks.batch_states,
            "batch_calls": checks.batch_calls,
            "cost_evaluations": checks.cost_evals,
        }

    def _finish(
        self,
        space: JointSpace,
        checks: Checks,
        raw: np.ndarray,
        cost: Callable[[np.ndarray], float] | None,
        stats: dict[str, Any],
        t0: float,
        rng: np.random.Generator,
    ) -> MotionResult:
        stats["planning_time"] = time.perf_counter() - t0
        cfg = self.settings
        if cfg.simplify and checks.valid_batch is not None:
            # Batched checks available: shorten with a few batched calls instead of OMPL's per-state simplifier.
            path, segment_ok = shorten_batched(
                space,
                raw,
                cfg,
                rng,
                valid_batch=checks.valid_batch,
                cost_batch=checks.costs if cost is not None else None,
            )
            checks.batch_calls += segment_ok.calls
            checks.batch_states += segment_ok.states
        else:
            path = finish_path(space, raw, cfg, cost)
        stats.update(
            raw_waypoints=len(raw),
            raw_length=float(np.sum(np.linalg.norm(np.diff(raw, axis=0), axis=1))),
            length=float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))),
            time=time.perf_counter() - t0,
            **self._check_stats(space, checks),
        )
        return MotionResult(success=True, path=path, reason=None, stats=stats)
