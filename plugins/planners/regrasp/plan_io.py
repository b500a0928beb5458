"""Plan output: timed segments for the robot, and the regrasp-graph figure.

:func:`to_plan` turns the planner's untimed steps into a
:class:`~asmteach.core.models.Plan` whose trajectories respect the robot's
speed limits and an acceleration limit, ready for ``Robot.execute``. Two
timings (``TIMINGS``): ``"toppra"`` (the default) parametrises each motion once
through all its waypoints, time-optimally, with corner blends
(:mod:`asmteach.core.trajectory.blended`), and holds the insertion's
straight line at ``insertion_speed``; ``"trapezoid"`` (the old one) stops at
every waypoint (:mod:`asmteach.core.trajectory.timing`). Either way
the plan's stats carry the robot seconds by kind of motion
(:func:`segment_kinds`: transit, approach, insertion, regrasp) for the timing
used and, for comparison on the same paths, for the trapezoid.

:func:`render_regrasp_graph` draws the graph in the style of the paper's
figure: one column per layer (start, intermediate placements, goal), grasps as
dots, transfer and transit edges, the chosen keyframe path in red.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.interfaces import Obstacle, Robot
from asmteach.core.io import atomic_path
from asmteach.core.models import Plan, PlanSegment
from asmteach.core.robot import PlanningScene
from asmteach.core.trajectory.blended import DEFAULT_DEVIATION, BlendReport, time_optimal
from asmteach.core.trajectory.timing import segment_profile, time_parametrize, to_trajectory
from asmteach.plugins.planners.regrasp.graph import GOAL, START
from asmteach.plugins.planners.regrasp.realise import Step

__all__ = ["KINDS", "TIMINGS", "render_regrasp_graph", "robot_seconds", "segment_kinds", "table_obstacle", "to_plan"]

TIMINGS = ("toppra", "trapezoid")
"""Time parametrisations :func:`to_plan` offers: blended time-optimal (toppra), or rest-to-rest at every waypoint."""

KINDS = ("transit", "approach", "insertion", "regrasp")
"""Kinds of robot motion the robot seconds are split into (see :func:`segment_kinds`)."""

INSERTION_SPEED = 0.03
"""TCP speed (m/s) of the insertion with the toppra timing: as slow as the old timing's mean on the demo's 5 cm
insertion (2.2 cm/s) plus a little, so the peg meets the hole as gently as it always has."""

_END_SLOTS = ("start", "goal", "assembled")  # slot names that are not an intermediate placement


def table_obstacle(scene: PlanningScene, height: float) -> Obstacle:
    """The table top as a 5 cm slab whose upper face is at ``height`` (world z, metres), under the footprint
    (centre x, y and size) of the scene's own table; a 0.8 x 1.2 m table centred at (0.45, 0) m when the scene
    models none."""
    table = scene.table
    if table is None:
        center, size = (0.45, 0.0), (0.8, 1.2)
    else:
        center, size = table.T_world[:2, 3], table.mesh.extents[:2]
    T = np.eye(4)
    T[:3, 3] = [center[0], center[1], height - 0.025]
    return Obstacle("table", trimesh.creation.box(extents=[size[0], size[1], 0.05]), T)


def segment_kinds(labels: Sequence[str]) -> list[str]:
    """The kind of each plan segment, from its label and those before it.

    ``insertion``: the final straight move of B into A. ``regrasp``: what an
    intermediate placement costs, from putting the part down at a middle slot
    (``place ... at placementN...``) up to and including lifting it again there
    (the release, retreat, arms going home, the move to the new grasp and its
    approach). Otherwise the straight TCP lines (``approach grasp``, ``lift``,
    ``place``, ``retreat``) are ``approach`` and the planned free motions
    (``move to pre-grasp``, ``carry``, ``... arm home``) ``transit``. Gripper
    events are ``gripper`` (they take no robot seconds in the plan).
    """
    kinds: list[str] = []
    regrasp = False
    for label in labels:
        head = label.split(" ", 1)[0]
        if head in ("close", "release"):
            kinds.append("regrasp" if regrasp else "gripper")
            continue
        if head == "place" and " at " in label and label.rsplit(" at ", 1)[1] not in _END_SLOTS:
            regrasp = True  # the part goes down at an intermediate placement, to be picked up again
        if regrasp:
            kinds.append("regrasp")
            if head == "lift":
                regrasp = False  # picked up again: the regrasp is over
            continue
        if head == "insert":
            kinds.append("insertion")
        elif head in ("approach", "lift", "place", "retreat"):
            kinds.append("approach")
        else:
            kinds.append("transit")
    return kinds


def robot_seconds(durations: Sequence[float], kinds: Sequence[str]) -> dict[str, float]:
    """Robot seconds (simulated motion time) in total and per kind of :data:`KINDS`, rounded to milliseconds."""
    out = {"total": 0.0, **{k: 0.0 for k in KINDS}}
    for d, k in zip(durations, kinds, strict=True):
        out["total"] += float(d)
        if k in out:
            out[k] += float(d)
    return {k: round(v, 3) for k, v in out.items()}


def _trapezoid_seconds(path: np.ndarray, v_max: np.ndarray, acceleration: float) -> float:
    """Duration (s) of the old timing on ``path``: one rest-to-rest trapezoid per waypoint pair."""
    acc = np.full(path.shape[1], float(acceleration))
    return float(sum(segment_profile(b - a, v_max, acc)[0] for a, b in itertools.pairwise(path)))


def _path_speed(robot: Robot, arm: str, path: np.ndarray, tcp_speed: float) -> float | None:
    """Joint-space path speed (rad/s) that moves the TCP at ``tcp_speed`` (m/s) along ``path``'s straight line."""
    tcp = np.array([robot.fk(arm, q)[:3, 3] for q in (path[0], path[-1])])
    metres = float(np.linalg.norm(tcp[1] - tcp[0]))
    radians = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    if metres <= 1e-9 or radians <= 1e-12:
        return None
    return tcp_speed * radians / metres


def to_plan(
    steps: Sequence[Step],
    robot: Robot,
    acceleration: float,
    *,
    keyframes: list[dict[str, Any]] | None = None,
    stats: dict[str, Any] | None = None,
    timing: str = "toppra",
    insertion_speed: float = INSERTION_SPEED,
    max_deviation: float = DEFAULT_DEVIATION,
) -> Plan:
    """Time-parametrise every path step (robot speed limits, ``acceleration`` rad/s^2) with ``timing``.

    ``insertion_speed`` (m/s) is the TCP speed of the insertion and
    ``max_deviation`` (rad) the largest corner blend, both with the toppra
    timing. The plan's stats gain ``execution_seconds`` (the total),
    ``robot_seconds`` (by kind), ``robot_seconds_trapezoid`` (the old timing's
    on the same paths), ``timing`` and ``timing_seconds`` (computer seconds
    spent timing) and, for toppra, ``blends`` (corners blended, stops, and any
    fall-back to the trapezoid).
    """
    if timing not in TIMINGS:
        raise UserError(f"timing must be one of {', '.join(TIMINGS)} (got {timing!r})")
    kinds = segment_kinds([st.label for st in steps])
    segments, durations, old = [], [], []
    blends = BlendReport()
    t0 = time.perf_counter()
    for st, kind in zip(steps, kinds, strict=True):
        if st.kind == "gripper":
            segments.append(PlanSegment(label=st.label, gripper=st.event, kind=kind))
            durations.append(0.0)
            old.append(0.0)
            continue
        path = np.asarray(st.path, float)
        if len(path) == 1:
            path = np.vstack([path, path])
        v_max = np.asarray(robot.speed_limits(st.arm), float)
        old.append(_trapezoid_seconds(path, v_max, acceleration))
        if timing == "trapezoid":
            timed = time_parametrize(path, v_max, acceleration)
        else:
            speed = _path_speed(robot, st.arm, path, insertion_speed) if kind == "insertion" else None
            timed = time_optimal(
                path, v_max, acceleration, max_deviation=max_deviation, path_speed=speed, report=blends
            )
        durations.append(timed.duration)
        segments.append(
            PlanSegment(label=st.label, trajectory=to_trajectory(timed, st.arm, robot.joint_names(st.arm)), kind=kind)
        )
    all_stats = dict(stats or {})
    all_stats["execution_seconds"] = round(float(sum(durations)), 3)
    all_stats["robot_seconds"] = robot_seconds(durations, kinds)
    all_stats["robot_seconds_trapezoid"] = robot_seconds(old, kinds)
    all_stats["timing"] = timing
    all_stats["timing_seconds"] = round(time.perf_counter() - t0, 3)
    if timing == "toppra":
        all_stats["blends"] = asdict(blends)
    return Plan(keyframes=keyframes or [], segments=segments, stats=all_stats)


GRAPH_MAX_EDGES = 10000
"""Edges drawn in a regrasp graph's picture at most (besides the keyframe path's)."""

GRAPH_MAX_INCHES = 16.0
"""The picture's largest width and height, inches (110 dpi)."""


def render_regrasp_graph(G: nx.Graph, path_nodes: Sequence[Any], out: Path, *, title: str = "") -> Path:
    """PNG of a regrasp graph; the keyframe path ``path_nodes`` drawn in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    slots: list[str] = []
    for n, d in G.nodes(data=True):
        if n in (START, GOAL):
            continue
        if d["slot"].name not in slots:
            slots.append(d["slot"].name)
    order = {"start": 0, "middle": 1, "goal": 2}
    layer = {d["slot"].name: d["layer"] for n, d in G.nodes(data=True) if n not in (START, GOAL)}
    slots.sort(key=lambda name: (order[layer.get(name, "middle")], name))
    col = {name: k for k, name in enumerate(slots)}
    members: dict[str, list[Any]] = {name: [] for name in slots}
    for n, d in G.nodes(data=True):
        if n not in (START, GOAL):
            members[d["slot"].name].append(n)
    pos: dict[Any, tuple[float, float]] = {}
    for name, nodes in members.items():
        nodes.sort(key=lambda n: (n[2], n[1]))
        for k, n in enumerate(nodes):
            pos[n] = (float(col[name]), -(k - 0.5 * (len(nodes) - 1)))
    height = max((len(v) for v in members.values()), default=1)
    pos[START] = (-1.0, 0.0)
    pos[GOAL] = (float(len(slots)), 0.0)
    width, tall = max(6.0, 1.3 * len(slots) + 3), max(4.0, 0.28 * height + 2)
    fig, ax = plt.subplots(figsize=(min(width, GRAPH_MAX_INCHES), min(tall, GRAPH_MAX_INCHES)))
    chosen = set(zip([START, *path_nodes], [*path_nodes, GOAL], strict=True)) if path_nodes else set()
    chosen |= {(b, a) for a, b in chosen}
    styles = {"transfer": ("#9ecae1", "-"), "transit": ("#fdae6b", "--"), "virtual": ("#d9d9d9", ":")}
    # One LineCollection per edge style, not one Line2D per edge: a graph has up to ~60 000 edges and
    # creating and drawing that many artists took minutes of a trial; the picture is the same.
    segments: dict[tuple[str, str], list[tuple[tuple[float, float], tuple[float, float]]]] = {}
    # A widened search's graph (18 000 nodes, 670 000 edges) took 11 minutes of a trial to draw into a 15 MB PNG;
    # beyond GRAPH_MAX_EDGES every k-th edge is drawn (the path always), and the title says how many.
    others = [(a, b, d) for a, b, d in G.edges(data=True) if (a, b) not in chosen]
    step = -(-len(others) // GRAPH_MAX_EDGES)
    for a, b, d in others[::step]:
        segments.setdefault(styles.get(d["kind"], ("#cccccc", "-")), []).append((pos[a], pos[b]))
    if step > 1:
        title = f"{title or 'regrasp graph'} ({len(others[::step])} of {len(others)} edges drawn)"
    for (color, ls), segs in segments.items():
        ax.add_collection(LineCollection(segs, colors=color, linestyles=ls, linewidths=0.5, alpha=0.6, zorder=1))
    for a, b in chosen:
        if (b, a) in chosen and id(a) > id(b):
            continue
        ax.plot(*zip(pos[a], pos[b], strict=True), color="#d62728", lw=2.5, zorder=3)
    arm_colors = {"left": "#1f77b4", "right": "#2ca02c"}
    # Nodes too: one scatter per (arm colour, on the path) group instead of one per node.
    groups: dict[tuple[str, bool], list[tuple[float, float]]] = {}
    on_path_nodes = set(path_nodes)
    for n in pos:
        if n in (START, GOAL):
            ax.scatter(*pos[n], s=160, c="k", marker="s", zorder=4)
            ax.annotate(n[0].lower(), pos[n], textcoords="offset points", xytext=(0, 10), ha="center")
            continue
        groups.setdefault((arm_colors.get(n[2], "#7f7f7f"), n in on_path_nodes), []).append(pos[n])
    for (color, on_path), xy in groups.items():
        xs, ys = zip(*xy, strict=True)
        ax.scatter(
            xs,
            ys,
            s=40 if on_path else 14,
            c=color,
            edgecolors="#d62728" if on_path else "none",
            linewidths=1.5,
            zorder=5,
        )
    ax.autoscale_view()  # collections added with add_collection do not update the data limits by themselves
    ax.set_xticks(range(len(slots)))
    ax.set_xticklabels(slots, rotation=35, ha="right", fontsize=8)
    ax.set_yticks([])
    for name, c in arm_colors.items():
        ax.scatter([], [], c=c, s=14, label=f"grasp ({name} arm)")
    ax.plot([], [], color=styles["transfer"][0], label="transfer (same grasp)")
    ax.plot([], [], color=styles["transit"][0], ls="--", label="transit (regrasp)")
    ax.plot([], [], color="#d62728", lw=2.5, label="keyframe path")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    ax.set_title(title or "regrasp graph")
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return out
