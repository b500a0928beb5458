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

Frames: ``T_world_*`` 4x4 in metres; joint paths in radians.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Annotated, Any, Literal

import networkx as nx
import numpy as np
from pydantic import Field

from asmteach.core.failures import FailureKind
from asmteach.core.geometry import compose, from_rotation, rot_z
from asmteach.core.hand_geometry import MeshCollider
from asmteach.core.interfaces import MotionPlanner, Obstacle, PartModel, Robot
from asmteach.core.models import Grasp, GripperEvent, Placement, StrictModel
from asmteach.core.trajectory.batch import batched, inverse_clearance_cost
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.regrasp.feasibility import (
    ScreenSettings,
    approach_offset,
    evaluate_slot,
    evaluate_slots,
    screen_slot,
    variant_tcp,
    world_collider,
)
from asmteach.plugins.planners.regrasp.graph import (
    GOAL,
    START,
    GraspFeasibility,
    KeyframeSearch,
    PoseSlot,
    build_regrasp_graph,
    search_keyframes,
)

__all__ = [
    "AssemblySettings",
    "PlaceGoal",
    "Step",
    "TransferResult",
    "cartesian_path",
    "feasible_grasps_at",
    "placement_slots",
    "plan_transfer",
    "relocated_slots",
]


class AssemblySettings(StrictModel):
    """How keyframes and motions are chosen. Distances in metres, angles in radians, times in seconds."""

    retract: float = Field(
        0.05, gt=0.0, le=0.5, description="pre-assembly retraction of B along -v_a, metres; more where B is still in A")
    vertical_snap_deg: float = Field(
        2.0, ge=0.0, le=10.0,
        description="a taught v_a this close to straight down at A's goal is made straight down, degrees (0: off)")
    goal_xy: tuple[float, float] = Field((0.40, 0.0), description="where A is assembled on the table (world x, y)")
    goal_yaw: float = Field(0.0, description="yaw of A's goal placement about the table normal")
    min_goal_grasps: int = Field(
        3, ge=0, le=100,
        description="A's goal placement is the one making B's insertion most nearly vertical among those where at "
        "least this many grasps of B are feasible (IK, collision) when assembled; if none, the one with the most "
        "(0: always the most vertical, unchecked)")
    placement_yaws: int = Field(4, ge=1, le=24, description="evenly sampled yaws per stable placement")
    max_placements: int = Field(4, ge=0, le=32, description="most probable placements used as middle layers")
    max_candidates: int = Field(40, ge=1, le=500, description="grasps solved by IK per slot after screening")
    max_candidates_wide: int = Field(
        80, ge=1, le=1000,
        description="when no keyframe path exists, the search is tried once more with every placement (symmetric "
        "duplicates too) and this many grasps solved per slot")
    relocations: tuple[Annotated[float, Field(gt=0.0, le=1.0)], ...] = Field(
        (0.5, 0.25, 0.75),
        description="when even the widened search finds no keyframe path, every placement is tried again at "
        "these fractions (dimensionless; 0 = start, 1 = goal) of the way from the part's start to its goal on "
        "the table, one position at a time in this order, until a path exists (empty: never)")
    relocation_clearance: float = Field(
        0.03, ge=0.0, le=0.3,
        description="metres: a relocated placement keeps at least this distance between the part and every "
        "obstacle other than the table (room for the fingers); positions closer are skipped")
    min_down: float = Field(0.3, ge=-1.0, le=1.0, description="cosine: approach to a part on the table from above")
    pregrasp_distance: float = Field(0.06, gt=0.0, description="approach stand-off along the TCP -z")
    lift: float = Field(0.08, gt=0.0, description="lift above the table after grasping / before placing")
    release_gap: float = Field(
        0.001, ge=0.0, le=0.01,
        description="a part placed on the table is let go this far above it (pressing it down makes it shift)")
    cartesian_step: float = Field(0.004, gt=0.0, description="TCP step of straight-line motions")
    regrasp_penalty: float = Field(10.0, ge=0.0, description="graph weight of one regrasp")
    motion_weight: float = Field(1.0, ge=0.0, description="graph weight per radian of joint motion")
    motion_time_limit: float = Field(
        5.0, gt=0.0,
        description="seconds per motion query: a wall-clock safety cap (the planner's iteration limit is the "
        "budget); a query it cuts is listed in the part's stats under wall_clock_cuts")
    max_attempts: int = Field(
        40, ge=1,
        description="per part: keyframe sequences tried (each after the last one's motion failed) before giving "
        "up; counted, so the same seed gives the same plan however loaded the machine is")
    time_budget: float = Field(
        600.0, gt=0.0,
        description="seconds per part: a wall-clock safety cap on the re-searches after max_attempts; when it "
        "cuts the search, the reason and wall_clock_cuts say so")
    acceleration: float = Field(2.0, gt=0.0, description="joint acceleration limit of the timed paths, rad/s^2")
    timing: Literal["toppra", "trapezoid"] = Field(
        "toppra",
        description="time parametrisation of each motion: 'toppra' once through all its waypoints (corners blended "
        "within 5 mrad, stops only at its ends), 'trapezoid' rest-to-rest at every waypoint (the old timing)")
    insertion_speed: float = Field(
        0.03, gt=0.0, le=0.2, description="TCP speed of the straight insertion with the toppra timing, m/s")


@dataclass(frozen=True)
class PlaceGoal:
    """Where a part must end: its pose, how it comes in, and what it may touch there."""

    slot: PoseSlot
    approach: np.ndarray
    """World vector (metres) from the placed pose back to where the straight final move starts."""
    touch: tuple[str, ...] = ("table",)
    """Obstacles the held part may touch on the final move (intended contact)."""
    on_table: bool = True
    """True when the part rests on the table at the goal (grasps then must come from above)."""


@dataclass
class Step:
    """One step of a plan: an untimed joint path of one arm, or a gripper event."""

    label: str
    kind: Literal["path", "gripper"]
    arm: str
    path: np.ndarray | None = None
    event: GripperEvent | None = None


@dataclass
class TransferResult:
    """Outcome of moving one part."""

    success: bool
    steps: list[Step] = field(default_factory=list)
    search: KeyframeSearch | None = None
    graph: nx.Graph | None = None
    reason: str | None = None
    stats: dict[str, Any] = field(default_factory=dict)
    q_end: dict[str, np.ndarray] = field(default_factory=dict)
    keyframes: list[dict[str, Any]] = field(default_factory=list)


class _MotionFailure(Exception):
    """A keyframe motion failed; ``edge`` is the graph edge to ban, ``node`` a node whose every edge is banned."""

    def __init__(self, edge: tuple[Any, Any], reason: str, node: Any | None = None, timed_out: bool = False) -> None:
        super().__init__(reason)
        self.edge = edge
        self.reason = reason
        self.node = node
        self.timed_out = timed_out  # a wall-clock limit, not the search, ended it: the result depends on the load


def placement_slots(
    placements: Sequence[Placement],
    xy: Sequence[float],
    table_height: float,
    settings: AssemblySettings,
    first: Sequence[np.ndarray] = (),
    every: bool = False,
) -> list[PoseSlot]:
    """Middle-layer slots: the most probable distinct placements at evenly sampled yaws at ``xy``.

    Placements that are the same up to the part's own symmetry (a square peg
    lying on any of its four sides) have the same centre-of-mass height,
    support area and margin; only the first of them is kept.

    ``first``: part orientations ``R_world_part`` (3x3) whose placements come
    first, in the exact variant, whatever their probability: the pose the part
    rests in at the start and the one it stands in at its goal. The grasp set
    is not symmetric like the part, so of a peg's four lying placements only
    the one it lies in shares its grasps from above with the start.

    ``every``: all placements, symmetric duplicates included, whatever
    ``max_placements`` says (the planner's second try).
    """
    chosen: list[Placement] = []
    seen: set[tuple[float, float, float]] = set()
    wanted = [p for R in first if (p := _placement_resting_as(placements, R)) is not None]
    wanted_ids = {p.id for p in wanted}
    by_probability = sorted(placements, key=lambda p: -p.probability)
    for p in wanted + by_probability:
        sig = (round(float(p.T_table_part[2, 3]) * 2000.0), round(_area(p.support_polygon) * 1e6), round(p.margin, 3))
        if p.id in {c.id for c in chosen} or (sig in seen and p.id not in wanted_ids and not every):
            continue
        seen.add(sig)
        chosen.append(p)
    if not every:
        chosen = chosen[: settings.max_placements]
    slots = []
    for p in chosen:
        for k in range(settings.placement_yaws):
            yaw = 2.0 * np.pi * k / settings.placement_yaws
            T = compose(from_rotation(np.eye(3), [xy[0], xy[1], table_height]), rot_z(yaw), p.T_table_part)
            slots.append(PoseSlot(f"placement{p.id}_yaw{round(np.degrees(yaw))}", "middle", T))
    return slots


def relocated_slots(
    slots: Sequence[PoseSlot],
    from_xy: Sequence[float],
    to_xy: Sequence[float],
    part: PartModel,
    collider: MeshCollider,
    clearance: float,
) -> list[PoseSlot]:
    """``slots``, placements made at table position ``from_xy``, moved to ``to_xy`` (world x, y, metres);
    none when the part would come within ``clearance`` metres of any obstacle of ``collider`` but the table
    in any of them. A slot's name gains ``_at{x}_{y}``, ``to_xy`` in millimetres.
    """
    shift = np.asarray(to_xy, float)[:2] - np.asarray(from_xy, float)[:2]
    x, y = (round(float(v) * 1000.0) for v in to_xy[:2])
    out = []
    for slot in slots:
        T = np.asarray(slot.T_world_part, float).copy()
        T[:2, 3] += shift
        if collider.distance(part.mesh, T, skip=("table",)) < clearance:
            return []
        out.append(PoseSlot(f"{slot.name}_at{x}_{y}", slot.layer, T))
    return out


def _placement_resting_as(placements: Sequence[Placement], R_world_part: np.ndarray) -> Placement | None:
    """The placement whose resting direction (part frame) is the table's down in ``R_world_part``, within 3 deg."""
    down = np.asarray(R_world_part, float).T @ np.array([0.0, 0.0, -1.0])
    best, cos = None, np.cos(np.radians(3.0))
    for p in placements:
        c = float(down @ (p.T_table_part[:3, :3].T @ np.array([0.0, 0.0, -1.0])))
        if c > cos:
            best, cos = p, c
    return best


def _area(polygon: np.ndarray) -> float:
    x, y = np.asarray(polygon, float).T
    return 0.5 * abs(float(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1))))


def cartesian_path(
    robot: Robot, arm: str, q_start: np.ndarray, T_goal: np.ndarray, step: float
) -> tuple[np.ndarray | None, str | None]:
    """Joint path moving the TCP on a straight line to ``T_goal`` (orientation kept; IK per step)."""
    T0 = robot.fk(arm, q_start)
    dist = float(np.linalg.norm(T_goal[:3, 3] - T0[:3, 3]))
    n = max(2, int(np.ceil(dist / step)) + 1)
    path = [np.asarray(q_start, float)]
    for s in np.linspace(0.0, 1.0, n)[1:]:
        T = T_goal.copy()
        T[:3, 3] = (1.0 - s) * T0[:3, 3] + s * T_goal[:3, 3]
        res = robot.ik(arm, T, q_seed=path[-1])
        if not res.success or res.q is None or getattr(res, "flipped", False):
            return None, f"IK fails {s * dist * 1000:.0f} mm along the straight line"
        if np.max(np.abs(res.q - path[-1])) > 0.3:
            return None, "the straight line crosses a singularity or a change of IK branch"
        path.append(np.asarray(res.q, float))
    return np.asarray(path), None


def _screen_settings(settings: AssemblySettings) -> ScreenSettings:
    return ScreenSettings(max_candidates=settings.max_candidates, min_down=settings.min_down,
                          pregrasp_distance=settings.pregrasp_distance)


def feasible_grasps_at(
    robot: Robot,
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
    reachable. The robot's obstacles are left holding ``world`` and no arm
    holds anything.
    """
    _reset_world(robot, world)
    slot = PoseSlot("probe", "goal", np.asarray(T_world_part, float))
    screen = _screen_settings(settings)
    screened = screen_slot(slot, grasps, world_collider(world), robot.hand, screen, on_table)
    return _grasp_ids([evaluate_slot(robot, slot, screened, list(robot.arms), settings=screen)])


def _grasp_dict(grasps: Sequence[Grasp]) -> dict[int, Grasp]:
    return {g.id: g for g in grasps}


def plan_transfer(
    robot: Robot,
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
    """
    t0 = time.perf_counter()
    by_id = _grasp_dict(grasps)
    arms = list(robot.arms)
    screen = _screen_settings(settings)
    seeds = {k: np.asarray(v, float).copy() for k, v in q_now.items()}
    collider = world_collider(world)

    def evaluate(slot: PoseSlot, on_table: bool = True, **kwargs: Any) -> GraspFeasibility:
        screened = screen_slot(slot, grasps, collider, robot.hand, screen, on_table)
        return evaluate_slot(robot, slot, screened, arms, settings=screen, seeds=seeds, **kwargs)

    start_slot = PoseSlot("start", "start", np.asarray(T_start, float))

    def start_and_goal() -> list[GraspFeasibility]:
        _reset_world(robot, world)
        start = evaluate(start_slot)
        return [start, evaluate(goal.slot, goal.on_table, prefer=_grasp_ids([start]))]

    def graph(layers: list[GraspFeasibility]) -> nx.Graph:
        return build_regrasp_graph(layers, regrasp_penalty=settings.regrasp_penalty,
                                   motion_weight=settings.motion_weight)

    layers = start_and_goal()
    stats: dict[str, Any] = {"feasible": {"start": len(layers[0].solutions), "goal": len(layers[1].solutions)}}
    G = graph(layers)
    middle_done = widened = False
    slots: list[PoseSlot] = []
    relocations = list(settings.relocations)
    start_xy = np.asarray(T_start, float)[:2, 3]
    goal_xy = np.asarray(goal.slot.T_world_part, float)[:2, 3]

    def middle_layers(slots: list[PoseSlot], prefer: set[int]) -> list[GraspFeasibility]:
        screens = [screen_slot(slot, grasps, collider, robot.hand, screen) for slot in slots]
        total = Counter(g.id for passed, _ in screens for g in passed)
        _reset_world(robot, world)  # a failed realisation may have left other obstacles or a held part
        shared = [{gid: n - (gid in {g.id for g in passed}) for gid, n in total.items()}
                  for passed, _ in screens]  # per slot: the other slots passing each grasp
        return evaluate_slots(robot, slots, screens, arms, settings=screen, prefer=prefer, shared=shared,
                              seeds=seeds)

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
            stats["feasible"]["middle"] = sum(len(f.solutions) for f in layers[2:])
            G = graph(layers)
            middle_done = True
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                progress(f"{part.name}: no direct grasp; {len(layers) - 2} intermediate placements added")
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
            stats["feasible"] = {"start": len(layers[0].solutions), "goal": len(layers[1].solutions),
                                 "middle": sum(len(f.solutions) for f in layers[2:]), "widened": True}
            G = graph(layers)
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                progress(f"{part.name}: no keyframe path; all {len(slots)} placement slots, "
                         f"{screen.max_candidates} grasps solved per slot")
            continue
        if not search.success and widened and relocations and settings.max_placements > 0:
            # Where the part starts, the arm may reach it in one way and not in the other (at the edge of
            # its reach): the same placements, further toward the goal and clear of the other obstacles.
            tg = time.perf_counter()
            fraction = relocations.pop(0)
            moved = relocated_slots(slots, start_xy, start_xy + fraction * (goal_xy - start_xy), part, collider,
                                    settings.relocation_clearance)
            stats.setdefault("relocations", []).append(fraction)
            if moved:
                layers += middle_layers(moved, _grasp_ids(layers))
                stats["feasible"]["middle"] = sum(len(f.solutions) for f in layers[2:])
                G = graph(layers)
            stats["graph_seconds"] += time.perf_counter() - tg
            if progress:
                where = f"{fraction:g} of the way to the goal"
                progress(f"{part.name}: no keyframe path; {len(moved)} placement slots added {where}" if moved
                         else f"{part.name}: placements {where} would come too near an obstacle; skipped")
            continue
        stats["graph_nodes"] = G.number_of_nodes() - 2
        stats["graph_edges"] = G.number_of_edges()
        if not search.success:
            reason = search.reason or "no keyframe path"
            if last_reason is not None:
                reason += f"; last motion failure: {last_reason}"
            return TransferResult(False, search=search, graph=G, reason=reason, stats=_rounded(stats),
                                  keyframes=_why_layers(layers))
        attempts += 1
        tm = time.perf_counter()
        try:
            steps, q_end, keyframes, min_clear = _realise(
                robot, planner, part, by_id, G, search, goal, world, q_now, settings
            )
        except _MotionFailure as fail:
            stats["motion_seconds"] += time.perf_counter() - tm
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
                    False, search=search, graph=G, stats=_rounded(stats),
                    reason=f"{attempts} keyframe sequences tried (max_attempts); last failure: {last_reason}",
                )
            if time.perf_counter() - t0 > settings.time_budget:
                stats["wall_clock_cuts"].append(f"time budget of {settings.time_budget:.0f} s")
                return TransferResult(
                    False, search=search, graph=G, stats=_rounded(stats),
                    reason=f"time budget of {settings.time_budget:.0f} s (wall clock) spent after {attempts} "
                    f"keyframe sequences; last failure: {last_reason}",
                )
            continue
        stats["motion_seconds"] += time.perf_counter() - tm
        stats.update(regrasps=search.regrasps, attempts=attempts, seconds=time.perf_counter() - t0,
                     min_clearance_m=min_clear)
        return TransferResult(True, steps=steps, search=search, graph=G, stats=_rounded(stats), q_end=q_end,
                              keyframes=keyframes)


def _grasp_ids(layers: Sequence[GraspFeasibility]) -> set[int]:
    """Grasp ids (not variants) with a solution in any of ``layers``: tried first at the next slots."""
    return {vid // 2 for f in layers for vid, _ in f.solutions}


def _set_world(robot: Robot, world: Sequence[Obstacle], *extra: Obstacle) -> None:
    """The robot's obstacles: ``world`` and ``extra`` without the table, which the robot models itself."""
    robot.set_obstacles([o for o in world if o.name != "table"] + list(extra))


def _reset_world(robot: Robot, world: Sequence[Obstacle]) -> None:
    """The robot's obstacles hold ``world`` (:func:`_set_world`) and no arm holds anything."""
    _set_world(robot, world)
    for arm in robot.arms:
        robot.attach(arm, None)


def _rounded(stats: dict[str, Any]) -> dict[str, Any]:
    return {k: round(v, 4) if isinstance(v, float) else v for k, v in stats.items()}


def _why_layers(layers: Sequence[GraspFeasibility]) -> list[dict[str, Any]]:
    """Per slot: feasible count and the most common rejection reasons (for failure reports)."""
    out = []
    for f in layers:
        counts: dict[str, int] = {}
        for r in f.rejected.values():
            key = r.split("(")[0].strip()
            counts[key] = counts.get(key, 0) + 1
        top = sorted(counts.items(), key=lambda kv: -kv[1])[:4]
        out.append({"slot": f.slot.name, "feasible": len(f.solutions), "rejected": dict(top)})
    return out


class _Checker:
    """Collision checks of one arm's paths against the robot's current world.

    ``valid`` and ``cost`` answer one configuration and, through ``.batch``,
    many at once (the robot's checker is ~25x cheaper per configuration in a
    batch; T-RRT checks whole edges that way).
    """

    def __init__(self, robot: Robot, arm: str) -> None:
        self.robot, self.arm = robot, arm
        self.valid = batched(
            lambda q: not bool(robot.in_collision(arm, np.asarray(q, float)[None, :])[0]),
            lambda qs: ~np.asarray(robot.in_collision(arm, qs), bool),
        )
        # T-RRT climbs this cost map: high within a few mm of obstacles, flat beyond 10 cm (metres),
        # so clearances beyond 10 cm need not be measured exactly.
        cap = 0.10
        clearance = batched(
            lambda q: float(robot.clearance(arm, np.asarray(q, float)[None, :], upto=cap)[0]),
            lambda qs: np.asarray(robot.clearance(arm, qs, upto=cap), float),
        )
        self.cost = inverse_clearance_cost(clearance, floor=0.005, cap=cap)

    def first_hit(self, path: np.ndarray, ignore: Sequence[str] = ()) -> int | None:
        hits = self.robot.in_collision(self.arm, np.asarray(path, float), ignore=ignore)
        return int(np.argmax(hits)) if np.any(hits) else None


@dataclass(frozen=True)
class _Scene:
    """What the robot's checker holds while one free motion is planned: the obstacles beyond ``world``,
    the part held (arm, part, ``T_tcp_part``, jaw width in metres) and every arm's configuration (radians)."""

    extra: tuple[Obstacle, ...]
    held: tuple[str, PartModel, np.ndarray, float] | None
    q: dict[str, np.ndarray]

    def apply(self, robot: Robot, world: Sequence[Obstacle]) -> None:
        _set_world(robot, world, *self.extra)
        for arm in robot.arms:
            if self.held is not None and self.held[0] == arm:
                robot.attach(arm, self.held[1], self.held[2], width=self.held[3])
            else:
                robot.attach(arm, None)
        for arm, q in self.q.items():
            robot.set_configuration(arm, q)


@dataclass(frozen=True)
class _FreeMotion:
    """A free motion left for the motion planner: ``steps[step]`` gets its path."""

    step: int
    arm: str
    q_a: np.ndarray
    q_b: np.ndarray
    edge: tuple[Any, Any]
    what: str
    scene: _Scene


def _realise(
    robot: Robot,
    planner: MotionPlanner,
    part: PartModel,
    grasps: dict[int, Grasp],
    G: nx.Graph,
    search: KeyframeSearch,
    goal: PlaceGoal,
    world: Sequence[Obstacle],
    q_now: dict[str, np.ndarray],
    settings: AssemblySettings,
) -> tuple[list[Step], dict[str, np.ndarray], list[dict[str, Any]], float]:
    """Keyframes to paths and the least clearance (m) of the free motions; raises
    :class:`_MotionFailure` with the edge to ban.

    Two passes: first every keyframe (IK) and straight line (Cartesian IK and
    collision), each free motion's end checked for collision and left as a
    query; then the motion planner's queries, in order. A keyframe sequence
    that fails at a straight line (an insertion whose fingers meet the other
    part, say) then costs milliseconds, not the free motions planned before it.
    """
    nodes = search.nodes
    steps: list[Step] = []
    keyframes: list[dict[str, Any]] = []
    queries: list[_FreeMotion] = []
    q_cur = {k: np.asarray(v, float).copy() for k, v in q_now.items()}
    q_set: dict[str, np.ndarray] = {}  # the configurations the robot holds now
    extra: tuple[Obstacle, ...] = ()
    held: tuple[str, PartModel, np.ndarray, float] | None = None
    T_part = G.nodes[nodes[0]]["slot"].T_world_part  # where the part lies now

    def put(arm: str, q: np.ndarray) -> None:
        robot.set_configuration(arm, q)
        q_set[arm] = np.asarray(q, float).copy()

    def free(arm: str, q_a: np.ndarray, q_b: np.ndarray, edge: tuple[Any, Any], what: str, label: str) -> None:
        """Leave a free motion for the second pass; its end must be collision-free in the robot's world now."""
        if bool(robot.in_collision(arm, np.asarray(q_b, float)[None, :])[0]):
            # No motion to it can succeed, whatever edge leads there: ban the node.
            raise _MotionFailure(edge, f"{what}: {FailureKind.GOAL_INVALID.value}", node=edge[1])
        queries.append(_FreeMotion(len(steps), arm, np.asarray(q_a, float), np.asarray(q_b, float), edge, what,
                                   _Scene(extra, held, dict(q_set))))
        steps.append(Step(label, "path", arm))

    i = 0
    while i < len(nodes):
        # one hold: pick at nodes[i], carry (transfer edges) to nodes[j]
        j = i
        while j + 1 < len(nodes) and G.edges[nodes[j], nodes[j + 1]]["kind"] == "transfer":
            j += 1
        if j == i:  # a lone node followed by a transit edge: the regrasp happens at this slot
            i += 1
            continue
        pick, place = nodes[i], nodes[j]
        into = START if i == 0 else nodes[i - 1]
        arm, vid = pick[2], pick[1]
        slot_pick, slot_place = G.nodes[pick]["slot"], G.nodes[place]["slot"]
        final = place[0] == goal.slot.name and j == len(nodes) - 1
        chk = _Checker(robot, arm)

        # 0. the other arms go home (the grasp graph was screened with them there) and stay put
        robot.attach(arm, None)
        held = None
        extra = (Obstacle(part.name, part.mesh, T_part),)
        _set_world(robot, world, *extra)
        for a in robot.arms:
            put(a, q_cur[a])
        for other in robot.arms:
            if other != arm and not np.allclose(q_cur[other], robot.home(other)):
                free(other, q_cur[other], robot.home(other), (into, pick),
                     f"{other} arm home before the {arm} arm picks", f"{other} arm home")
                q_cur[other] = robot.home(other)
                put(other, q_cur[other])
        # 1. free motion to the pre-grasp pose; the part is an obstacle where it lies
        T_grasp = slot_pick.T_world_part @ variant_tcp(grasps, vid)
        pre = robot.ik(arm, approach_offset(T_grasp, settings.pregrasp_distance), q_seed=G.nodes[pick]["q"])
        if not pre.success or pre.q is None or getattr(pre, "flipped", False):
            raise _MotionFailure((into, pick), f"pre-grasp pose at {pick[0]} has no IK solution", node=pick)
        free(arm, q_cur[arm], pre.q, (into, pick), f"motion to the pre-grasp at {pick[0]}",
             f"move to pre-grasp {vid} of {part.name} at {pick[0]}")
        keyframes.append({"name": f"pregrasp_{pick[0]}", "arm": arm, "q": np.asarray(pre.q).tolist()})
        # 2. straight approach without the part as obstacle (the fingers go around it)
        extra = ()
        _set_world(robot, world)
        down = _line(robot, chk, arm, pre.q, T_grasp, settings, (into, pick), f"approach at {pick[0]}", node=pick)
        steps.append(Step(f"approach grasp {vid}", "path", arm, down))
        keyframes.append({"name": f"grasp_{pick[0]}", "arm": arm, "q": down[-1].tolist()})
        width = grasps[vid // 2].width
        steps.append(Step(f"close on {part.name}", "gripper", arm,
                          event=GripperEvent(arm=arm, action="close", width=width, attach=part.name)))
        T_tcp_now = robot.fk(arm, down[-1])
        held = (arm, part, np.linalg.inv(T_tcp_now) @ slot_pick.T_world_part, width)
        robot.attach(arm, part, held[2], width=width)
        # 3. lift straight up (the part leaves the table it touched)
        T_lift = T_tcp_now.copy()
        T_lift[2, 3] += settings.lift
        up = _line(robot, chk, arm, down[-1], T_lift, settings, (pick, nodes[i + 1]), f"lift at {pick[0]}",
                   ignore=("table",), node=pick)
        steps.append(Step(f"lift {part.name}", "path", arm, up))
        # 4. carry to the start of the final straight move
        T_place_tcp = slot_place.T_world_part @ variant_tcp(grasps, vid)
        approach = goal.approach if final else np.array([0.0, 0.0, settings.lift])
        T_above = T_place_tcp.copy()
        T_above[:3, 3] += approach
        above = robot.ik(arm, T_above, q_seed=G.nodes[place]["q"])
        if not above.success or above.q is None or getattr(above, "flipped", False):
            raise _MotionFailure((pick, nodes[i + 1]), f"no IK solution above {place[0]}", node=place)
        free(arm, up[-1], above.q, (pick, nodes[i + 1]), f"carrying {part.name} to {place[0]}",
             f"carry {part.name} to {place[0]}")
        keyframes.append({"name": f"{'preassembly' if final and not goal.on_table else 'above'}_{place[0]}",
                          "arm": arm, "q": np.asarray(above.q).tolist()})
        # 5. final straight move: place on the table, or insert along v_a
        touch = goal.touch if final else ("table",)
        T_release = T_place_tcp.copy()
        if goal.on_table or not final:
            T_release[2, 3] += settings.release_gap
        last = _line(robot, chk, arm, above.q, T_release, settings, (pick, nodes[i + 1]),
                     f"{'insertion' if final and not goal.on_table else 'placing'} at {place[0]}", ignore=touch,
                     node=place)
        steps.append(Step(f"{'insert' if final and not goal.on_table else 'place'} {part.name} at {place[0]}",
                          "path", arm, last))
        keyframes.append({"name": f"placed_{place[0]}", "arm": arm, "q": last[-1].tolist()})
        # 6. release and back off along the approach axis
        steps.append(Step(f"release {part.name}", "gripper", arm, event=GripperEvent(arm=arm, action="open")))
        robot.attach(arm, None)
        held = None
        T_part = slot_place.T_world_part
        # the opened fingers back off past the part they let go of, now an obstacle where it was placed
        extra = (Obstacle(part.name, part.mesh, T_part),)
        _set_world(robot, world, *extra)
        back = _line(robot, chk, arm, last[-1],
                     approach_offset(robot.fk(arm, last[-1]), settings.pregrasp_distance), settings,
                     (pick, nodes[i + 1]), f"retreat at {place[0]}", node=place)
        steps.append(Step("retreat", "path", arm, back))
        q_cur[arm] = back[-1]
        i = j + 1  # the edge after a hold is a transit (regrasp at that slot) or the end
    # 7. home, with the part now an obstacle where it was placed
    extra = (Obstacle(part.name, part.mesh, T_part),)
    _set_world(robot, world, *extra)
    for arm in robot.arms:
        home = robot.home(arm)
        for other in robot.arms:
            put(other, q_cur[other])
        if np.allclose(q_cur[arm], home):
            continue
        free(arm, q_cur[arm], home, (nodes[-1], GOAL), f"{arm} arm back home", f"{arm} arm home")
        q_cur[arm] = home
    end = _Scene(extra, None, dict(q_set))
    # second pass: the motion planner, in the order the robot moves
    clearances: list[float] = []
    for m in queries:
        m.scene.apply(robot, world)
        steps[m.step].path = _free(robot, planner, m.arm, m.q_a, m.q_b, settings, m.edge, m.what, clearances)
    end.apply(robot, world)
    return steps, q_cur, keyframes, (min(clearances) if clearances else float("nan"))


def _free(
    robot: Robot,
    planner: MotionPlanner,
    arm: str,
    q_a: np.ndarray,
    q_b: np.ndarray,
    settings: AssemblySettings,
    edge: tuple[Any, Any],
    what: str,
    clearances: list[float],
) -> np.ndarray:
    """A collision-free joint path from the motion planner, cost = inverse clearance;
    its minimum clearance (metres) is appended to ``clearances``."""
    chk = _Checker(robot, arm)
    lo, hi = robot.joint_limits(arm)
    res = planner.plan(np.asarray(q_a, float), np.asarray(q_b, float), lower=lo, upper=hi, is_valid=chk.valid,
                       cost=chk.cost, time_limit=settings.motion_time_limit)
    if not res.success or res.path is None:
        # The goal configuration itself is in collision (a held part against the robot, say): no motion
        # to it can succeed, whatever edge leads there.
        bad_goal = edge[1] if res.kind is FailureKind.GOAL_INVALID else None
        raise _MotionFailure(edge, f"{what}: {res.reason}", node=bad_goal, timed_out=res.kind is FailureKind.TIMEOUT)
    path = np.asarray(res.path, float)
    # clearance of the free motion in the world it was planned in, every 0.05 rad (for the statistics)
    clearances.append(float(np.min(robot.clearance(arm, densify(path, 0.05)))))
    return path


def _line(
    robot: Robot,
    chk: _Checker,
    arm: str,
    q_from: np.ndarray,
    T_to: np.ndarray,
    settings: AssemblySettings,
    edge: tuple[Any, Any],
    what: str,
    ignore: Sequence[str] = (),
    node: Any | None = None,
) -> np.ndarray:
    """A straight TCP line; on failure ``node``, the grasp at the slot the line belongs to, is banned whole."""
    path, why = cartesian_path(robot, arm, np.asarray(q_from, float), T_to, settings.cartesian_step)
    if path is None:
        raise _MotionFailure(edge, f"{what}: {why}", node=node)
    hit = chk.first_hit(path, ignore=ignore)
    if hit is not None:
        pairs = robot.collision_report(arm, path[hit])
        who = ", ".join(f"{a}/{b}" for a, b in pairs[:2]) or "unknown pair"
        raise _MotionFailure(edge, f"{what}: collision at step {hit} ({who})", node=node)
    return path
