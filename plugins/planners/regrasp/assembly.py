"""Moving one part from its start pose to a goal pose, through regrasps if needed.

For a part, a three-layer regrasp graph (start pose / stable placements at
sampled yaws at the start position / goal pose) is searched for keyframes;
arm motions between keyframes come from the configured motion planner;
approaches, lifts and the final insertion are straight Cartesian lines. When
a motion between two keyframes fails, that edge is banned and the graph
searched again, up to ``max_attempts`` sequences: a count, so the same seed
gives the same plan on a busy machine (the wall-clock caps are a safety net,
listed in the stats' ``wall_clock_cuts`` when they cut). The keyframes and
straight lines of a sequence are all checked before the motion planner is
asked for any of its free motions, so a sequence that fails at a line is
dropped in milliseconds.

The middle layer is built lazily: when the start and goal layers already share
a grasp, the cheapest path never regrasps (each regrasp costs
``regrasp_penalty``, more than any difference in transfer motion), so the
intermediate placements are evaluated only when that search fails.

The placements are first tried where the part starts. Near the edge of the
robot's reach a part can often be put down there but not picked up again in
the new way (a lying peg stood upright for its vertical insertion), so when
even the widened search fails, the same placements are tried again further
toward the goal, one position at a time (``relocations``), clear of the
other obstacles; the part is then carried there, regrasped, and carried on.
Last, every layer is screened again with approaches from the side allowed
(``min_down_last``): a headed peg standing on its head shares no top-down
grasp with any rest that leads to its head-up goal.

This module searches and re-searches; the settings are in :mod:`.settings`,
the middle-layer slots in :mod:`.slots`, and turning a keyframe path into
joint paths in :mod:`.realise`, with the single motions (and which edge a
failed one bans) in :mod:`.motions`.

Frames: ``T_world_*`` 4x4 in metres; joint paths in radians.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import networkx as nx
import numpy as np

from asmteach.core.failures import FailureCause
from asmteach.core.interfaces import MotionPlanner, Obstacle, PartModel, Robot
from asmteach.core.models import Grasp
from asmteach.core.robot import PlanningScene
from asmteach.plugins.planners.regrasp.feasibility import (
    ScreenSettings,
    evaluate_slot,
    evaluate_slots,
    screen_slot,
    world_collider,
)
from asmteach.plugins.planners.regrasp.graph import (
    GraspFeasibility,
    KeyframeSearch,
    PoseSlot,
    build_regrasp_graph,
    explain_cut,
    search_keyframes,
)
from asmteach.plugins.planners.regrasp.motions import MotionFailure, cleared_scene
from asmteach.plugins.planners.regrasp.realise import PlaceGoal, Step, realise_keyframes
from asmteach.plugins.planners.regrasp.settings import AssemblySettings
from asmteach.plugins.planners.regrasp.slots import relocated_slots

__all__ = ["TransferResult", "feasible_grasps_at", "plan_transfer"]


@dataclass
class TransferResult:
    """Outcome of moving one part.

    ``keyframes``: the named arm configurations of a plan; ``layers``: on a
    failed search, the counts of every grasp layer (:meth:`GraspFeasibility.counts`:
    grasp variants tried, feasible, rejected by kind, of those with the table).
    """

    success: bool
    steps: list[Step] = field(default_factory=list)
    search: KeyframeSearch | None = None
    graph: nx.Graph | None = None
    reason: str | None = None
    stats: dict[str, Any] = field(default_factory=dict)
    q_end: dict[str, np.ndarray] = field(default_factory=dict)
    keyframes: list[dict[str, Any]] = field(default_factory=list)
    layers: list[dict[str, Any]] = field(default_factory=list)
    scene: PlanningScene | None = field(default=None, repr=False)
    """The planning scene the transfer ends (or failed) with; the next part's planning starts from it."""
    cause: FailureCause | None = None
    """Why it failed (None on success): see :func:`_search_cause`; ``motion`` when ``max_attempts`` keyframe
    sequences each had a motion fail."""


def _screen_settings(settings: AssemblySettings) -> ScreenSettings:
    return ScreenSettings(
        max_candidates=settings.max_candidates, min_down=settings.min_down, pregrasp_distance=settings.pregrasp_distance
    )


def feasible_grasps_at(
    robot: Robot,
    scene: PlanningScene,
    part: PartModel,
    grasps: Sequence[Grasp],
    T_world_part: np.ndarray,
    world: Sequence[Obstacle],
    settings: AssemblySettings,
    on_table: bool = False,
) -> set[int]:
    """Ids of ``part``'s grasps (not variants) some arm can take with the part at ``T_world_part`` (metres).

    The same test as a layer of the regrasp graph: screen, IK of the best
    ``settings.max_candidates``, collision of the arm with ``world`` (table
    named ``"table"`` and other obstacles, not this part), the pre-grasp pose
    reachable; checked in ``scene`` with the obstacles of ``world`` and the
    hands empty (the arms stay where ``scene`` has them), IK seeded there.
    """
    scene = cleared_scene(scene, world)
    slot = PoseSlot("probe", "goal", np.asarray(T_world_part, float))
    screen = _screen_settings(settings)
    screened = screen_slot(slot, grasps, world_collider(world), robot.hand, screen, on_table)
    seeds = {arm: np.array(q, dtype=float) for arm, q in scene.configuration.items()}
    return _grasp_ids([evaluate_slot(robot, scene, slot, screened, list(robot.arms), settings=screen, seeds=seeds)])


def _grasp_dict(grasps: Sequence[Grasp]) -> dict[int, Grasp]:
    return {g.id: g for g in grasps}


def plan_transfer(
    robot: Robot,
    scene: PlanningScene,
    planner: MotionPlanner,
    part: PartModel,
    grasps: Sequence[Grasp],
    *,
    T_start: np.ndarray,
    goal: PlaceGoal,
    middle_slots: Callable[[bool], Sequence[PoseSlot]],
    world: Sequence[Obstacle],
    q_now: dict[str, np.ndarray],
    settings: AssemblySettings,
    progress: Callable[[str], None] | None = None,
) -> TransferResult:
    """Move ``part`` from ``T_start`` to ``goal``; the arms end at home.

    ``world`` holds the table (named ``"table"``) and the other obstacles,
    not this part. ``middle_slots(every)`` gives placements at the part's
    start position and is called only if intermediate placements are
    needed: first the chosen few, then, if the search still fails, every
    placement (``every=True``), which is then moved toward the goal
    (``settings.relocations``) while no path exists.
    Paths are untimed; see
    :func:`asmteach.plugins.planners.regrasp.plan_io.to_plan`.
    Collisions are checked in scenes made from ``scene`` (the arms where it
    has them); the result's :attr:`TransferResult.scene` is the one the
    transfer ends with, and ``robot`` is never changed.
    """
    t0 = time.perf_counter()
    by_id = _grasp_dict(grasps)
    arms = list(robot.arms)
    screen = _screen_settings(settings)
    seeds = {k: np.asarray(v, float).copy() for k, v in q_now.items()}
    collider = world_collider(world)

    def evaluate(slot: PoseSlot, on_table: bool = True, **kwargs: Any) -> GraspFeasibility:
        screened = screen_slot(slot, grasps, collider, robot.hand, screen, on_table)
        return evaluate_slot(robot, scene, slot, screened, arms, settings=screen, seeds=seeds, **kwargs)

    start_slot = PoseSlot("start", "start", np.asarray(T_start, float))

    def start_and_goal() -> list[GraspFeasibility]:
        """The start layer, then one goal layer per goal slot (a symmetric part's equivalent poses)."""
        nonlocal scene
        scene = cleared_scene(scene, world)
        start = evaluate(start_slot)
        return [start] + [evaluate(slot, goal.on_table, prefer=_grasp_ids([start])) for slot in goal.slots]

    n_end = 1 + len(goal.slots)  # layers[:n_end]: the start and the goal layers; the middle ones follow

    def graph(layers: list[GraspFeasibility]) -> nx.Graph:
        return build_regrasp_graph(
            layers, regrasp_penalty=settings.regrasp_penalty, motion_weight=settings.motion_weight
        )

    layers = start_and_goal()
    stats: dict[str, Any] = {"feasible": _feasible(layers, n_end)}
    G = graph(layers)
    middle_done = widened = sideways = False
    slots: list[PoseSlot] = []
    moved_slots: list[PoseSlot] = []
    relocations = list(settings.relocations)
    start_xy = np.asarray(T_start, float)[:2, 3]
    goal_xy = np.asarray(goal.slot.T_world_part, float)[:2, 3]

    def middle_layers(slots: list[PoseSlot], prefer: set[int]) -> list[GraspFeasibility]:
        screens = [screen_slot(slot, grasps, collider, robot.hand, screen) for slot in slots]
        total = Counter(g.id for passed, _ in screens for g in passed)
        nonlocal scene
        scene = cleared_scene(scene, world)  # a failed realisation may have left other obstacles or a held part
        shared = [
            {gid: n - (gid in {g.id for g in passed}) for gid, n in total.items()} for passed, _ in screens
        ]  # per slot: the other slots passing each grasp
        return evaluate_slots(
            robot, scene, slots, screens, arms, settings=screen, prefer=prefer, shared=shared, seeds=seeds
        )

    banned: list[tuple[Any, Any]] = []
    last_reason: str | None = None
    stats["graph_seconds"] = time.perf_counter() - t0
    stats["search_seconds"] = 0.0
    stats["motion_seconds"] = 0.0
    # Every wall-clock limit that changed the outcome (a motion query cut at motion_time_limit, the part's
    # time_budget): with none, the plan is a function of the seed alone; with some, of the machine's load too.
    stats["wall_clock_cuts"] = []
    attempts = 0
    while True:
        ts = time.perf_counter()
        search = search_keyframes(G, banned_edges=banned)
        stats["search_seconds"] += time.perf_counter() - ts
        if not search.success and not middle_done and settings.max_placements > 0:
            tg = time.perf_counter()
            slots = list(middle_slots(False))
            layers += middle_layers(slots, _grasp_ids(layers))
            stats["feasible"]["middle"] = sum(len(f.solutions) for f in layers[n_end:])
            G = graph(layers)
            middle_done = True
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                progress(f"{part.name}: no direct grasp; {len(layers) - n_end} intermediate placements added")
            continue
        if not search.success and not widened and settings.max_placements > 0:
            # Turning a part over takes grasps that two placements share, and there are few: only grasps
            # solved by IK make nodes, the cap per slot can leave them out, and so can the choice of one
            # of a symmetric part's equal placements. Once: every placement, more grasps solved per slot.
            tg = time.perf_counter()
            widened = middle_done = True
            screen = replace(screen, max_candidates=max(settings.max_candidates_wide, screen.max_candidates))
            slots = list(middle_slots(True))
            layers = start_and_goal()
            layers += middle_layers(slots, _grasp_ids(layers))
            stats["feasible"] = {**_feasible(layers, n_end), "widened": True}
            G = graph(layers)
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                progress(
                    f"{part.name}: no keyframe path; all {len(slots)} placement slots, "
                    f"{screen.max_candidates} grasps solved per slot"
                )
            continue
        if not search.success and widened and relocations and settings.max_placements > 0:
            # Where the part starts, the arm may reach it in one way and not in the other (at the edge of
            # its reach): the same placements, further toward the goal and clear of the other obstacles.
            tg = time.perf_counter()
            fraction = relocations.pop(0)
            moved = relocated_slots(
                slots,
                start_xy,
                start_xy + fraction * (goal_xy - start_xy),
                part,
                collider,
                settings.relocation_clearance,
            )
            stats.setdefault("relocations", []).append(fraction)
            if moved:
                moved_slots += moved
                layers += middle_layers(moved, _grasp_ids(layers))
                stats["feasible"]["middle"] = sum(len(f.solutions) for f in layers[n_end:])
                G = graph(layers)
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                where = f"{fraction:g} of the way to the goal"
                progress(
                    f"{part.name}: no keyframe path; {len(moved)} placement slots added {where}"
                    if moved
                    else f"{part.name}: placements {where} would come too near an obstacle; skipped"
                )
            continue
        if not search.success and widened and not sideways and settings.min_down_last < screen.min_down:
            # Approaches from above are the cell's first choice (the fingers come down clear of the table),
            # but a part can rest only in ways that share no such grasp with its goal: then from the side too.
            tg = time.perf_counter()
            sideways = True
            screen = replace(screen, min_down=settings.min_down_last)
            layers = start_and_goal()
            layers += middle_layers(slots + moved_slots, _grasp_ids(layers))
            stats["feasible"] = {**_feasible(layers, n_end), "widened": True, "sideways": True}
            G = graph(layers)
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                progress(f"{part.name}: no keyframe path; grasps approaching from the side allowed")
            continue
        stats["graph_nodes"] = G.number_of_nodes() - 2
        stats["graph_edges"] = G.number_of_edges()
        if not search.success:
            reason = search.reason or "no keyframe path"
            if search.cut == "start":
                reason += f": {layers[0].summary()}"
            elif search.cut == "goal":
                reason += ": " + "; ".join(f.summary() for f in layers[1:n_end])
            elif search.cut == "between" and (why := explain_cut(G, layers)):
                reason += f"; {why}"
            if last_reason is not None:
                reason += f"; last motion failure: {last_reason}"
            stats.update(cut=search.cut, components=search.components)
            return TransferResult(
                False,
                search=search,
                graph=G,
                reason=f"{reason}; {_time_spent(stats, t0)}",
                stats=_rounded(stats),
                layers=[f.counts() for f in layers],
                scene=scene,
                cause=_search_cause(search, layers, n_end),
            )
        attempts += 1
        tm = time.perf_counter()
        try:
            steps, q_end, keyframes, min_clear, scene = realise_keyframes(
                robot, scene, planner, part, by_id, G, search, goal, world, q_now, settings
            )
        except MotionFailure as fail:
            stats["motion_seconds"] += time.perf_counter() - tm
            if fail.scene is not None:
                scene = fail.scene
            banned.append(fail.edge)
            if fail.node is not None and fail.node in G:
                banned += list(G.edges(fail.node))
            last_reason = fail.reason
            if fail.timed_out:
                stats["wall_clock_cuts"].append(fail.reason)
            if progress:
                progress(f"{part.name}: {fail.reason}; searching again")
            if attempts >= settings.max_attempts:
                return TransferResult(
                    False,
                    search=search,
                    graph=G,
                    stats=_rounded(stats),
                    reason=f"{attempts} keyframe sequences tried (max_attempts); last failure: {last_reason}; "
                    f"{_time_spent(stats, t0)}",
                    scene=scene,
                    cause=FailureCause.MOTION,
                )
            if time.perf_counter() - t0 > settings.time_budget:
                stats["wall_clock_cuts"].append(f"time budget of {settings.time_budget:.0f} s")
                return TransferResult(
                    False,
                    search=search,
                    graph=G,
                    stats=_rounded(stats),
                    reason=f"time budget of {settings.time_budget:.0f} s (wall clock) spent after {attempts} "
                    f"keyframe sequences; last failure: {last_reason}; {_time_spent(stats, t0)}",
                    scene=scene,
                    cause=FailureCause.REGRASP_GRAPH,  # the search's budget spent, as a cut graph
                )
            continue
        stats["motion_seconds"] += time.perf_counter() - tm
        stats.update(
            regrasps=search.regrasps, attempts=attempts, seconds=time.perf_counter() - t0, min_clearance_m=min_clear
        )
        return TransferResult(
            True,
            steps=steps,
            search=search,
            graph=G,
            stats=_rounded(stats),
            q_end=q_end,
            keyframes=keyframes,
            scene=scene,
        )


def _search_cause(search: KeyframeSearch, layers: Sequence[GraspFeasibility], n_end: int = 2) -> FailureCause:
    """Why a keyframe search failed, from where it is cut (:attr:`KeyframeSearch.cut`) and the layers' solutions
    (``layers[0]`` the start, ``layers[1:n_end]`` the goal slots).

    Cut at the start or the goal with no feasible grasp in that layer (at any goal slot): ``no_grasp``. Cut
    there although it had feasible grasps: every one of them was banned after its motion failed, so
    ``motion``. Cut between the layers (no grasp connects them, banned edges included): ``regrasp_graph``.
    """
    if search.cut in ("start", "goal"):
        cut = layers[:1] if search.cut == "start" else layers[1:n_end]
        return FailureCause.NO_GRASP if not any(f.solutions for f in cut) else FailureCause.MOTION
    return FailureCause.REGRASP_GRAPH


def _feasible(layers: Sequence[GraspFeasibility], n_end: int) -> dict[str, int]:
    """Feasible grasp variants of the start, the goal slots together and the middle layers (after ``n_end``)."""
    out = {"start": len(layers[0].solutions), "goal": sum(len(f.solutions) for f in layers[1:n_end])}
    if n_end > 2:
        out["goal_slots"] = n_end - 1
    if len(layers) > n_end:
        out["middle"] = sum(len(f.solutions) for f in layers[n_end:])
    return out


def _grasp_ids(layers: Sequence[GraspFeasibility]) -> set[int]:
    """Grasp ids (not variants) with a solution in any of ``layers``: tried first at the next slots."""
    return {vid // 2 for f in layers for vid, _ in f.solutions}


def _rounded(stats: dict[str, Any]) -> dict[str, Any]:
    return {k: round(v, 4) if isinstance(v, float) else v for k, v in stats.items()}


def _time_spent(stats: dict[str, Any], t0: float) -> str:
    """Where the part's planning time went (seconds, wall clock): building the graph, searching it, motions."""
    return (
        f"{time.perf_counter() - t0:.1f} s spent: {stats['graph_seconds']:.1f} s on the grasp layers, "
        f"{stats['search_seconds']:.1f} s searching, {stats['motion_seconds']:.1f} s on motions"
    )
