"""Plan output: timed segments for the robot, and the regrasp-graph figure.

:func:`to_plan` turns the planner's untimed steps into a
:class:`~asmteach.core.models.Plan` whose trajectories respect the robot's
speed limits and an acceleration limit (trapezoidal profiles through every
waypoint), ready for ``Robot.execute``. :func:`render_regrasp_graph` draws the
graph in the style of the paper's figure: one column per layer (start,
intermediate placements, goal), grasps as dots, transfer and transit edges,
the chosen keyframe path in red.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import networkx as nx
import numpy as np
import trimesh

from asmteach.core.interfaces import Obstacle, Robot
from asmteach.core.io import atomic_path
from asmteach.core.models import Plan, PlanSegment
from asmteach.plugins.planners.motion.timing import time_parametrize, to_trajectory
from asmteach.plugins.planners.regrasp.assembly import Step
from asmteach.plugins.planners.regrasp.graph import GOAL, START

__all__ = ["render_regrasp_graph", "table_obstacle", "to_plan"]


def table_obstacle(robot: Robot, height: float) -> Obstacle:
    """The table top as a 5 cm slab whose upper face is at ``height`` (world z, metres)."""
    st = getattr(robot, "settings", None)
    center = getattr(st, "table_center", (0.45, 0.0))
    size = getattr(st, "table_size", (0.8, 1.2))
    T = np.eye(4)
    T[:3, 3] = [center[0], center[1], height - 0.025]
    return Obstacle("table", trimesh.creation.box(extents=[size[0], size[1], 0.05]), T)


def to_plan(
    steps: Sequence[Step],
    robot: Robot,
    acceleration: float,
    *,
    keyframes: list[dict[str, Any]] | None = None,
    stats: dict[str, Any] | None = None,
) -> Plan:
    """Time-parametrise every path step (robot speed limits, ``acceleration`` rad/s^2)."""
    segments = []
    for st in steps:
        if st.kind == "gripper":
            segments.append(PlanSegment(label=st.label, gripper=st.event))
            continue
        path = np.asarray(st.path, float)
        if len(path) == 1:
            path = np.vstack([path, path])
        timed = time_parametrize(path, robot.speed_limits(st.arm), acceleration)
        segments.append(PlanSegment(label=st.label, trajectory=to_trajectory(timed, st.arm, robot.joint_names(st.arm))))
    duration = sum(s.trajectory.times[-1] for s in segments if s.trajectory is not None)
    all_stats = dict(stats or {})
    all_stats["execution_seconds"] = round(float(duration), 3)
    return Plan(keyframes=keyframes or [], segments=segments, stats=all_stats)


def render_regrasp_graph(G: nx.Graph, path_nodes: Sequence[Any], out: Path, *, title: str = "") -> Path:
    """PNG of a regrasp graph; the keyframe path ``path_nodes`` drawn in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    slots: list[str] = []
    for n, d in G.nodes(data=True):
        if n in (START, GOAL):
            continue
        if d["slot"].name not in slots:
            slots.append(d["slot"].name)
    order = {"start": 0, "middle": 1, "goal": 2}
    slots.sort(key=lambda name: (order[_layer_of(G, name)], name))
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
    fig, ax = plt.subplots(figsize=(max(6.0, 1.3 * len(slots) + 3), max(4.0, 0.28 * height + 2)))
    chosen = set(zip([START, *path_nodes], [*path_nodes, GOAL], strict=True)) if path_nodes else set()
    chosen |= {(b, a) for a, b in chosen}
    styles = {"transfer": ("#9ecae1", "-"), "transit": ("#fdae6b", "--"), "virtual": ("#d9d9d9", ":")}
    for a, b, d in G.edges(data=True):
        if (a, b) in chosen:
            continue
        color, ls = styles.get(d["kind"], ("#cccccc", "-"))
        ax.plot(*zip(pos[a], pos[b], strict=True), color=color, ls=ls, lw=0.5, alpha=0.6, zorder=1)
    for a, b in chosen:
        if (b, a) in chosen and id(a) > id(b):
            continue
        ax.plot(*zip(pos[a], pos[b], strict=True), color="#d62728", lw=2.5, zorder=3)
    arm_colors = {"left": "#1f77b4", "right": "#2ca02c"}
    for n in pos:
        if n in (START, GOAL):
            ax.scatter(*pos[n], s=160, c="k", marker="s", zorder=4)
            ax.annotate(n[0].lower(), pos[n], textcoords="offset points", xytext=(0, 10), ha="center")
            continue
        on_path = n in path_nodes
        ax.scatter(*pos[n], s=40 if on_path else 14, c=arm_colors.get(n[2], "#7f7f7f"),
                   edgecolors="#d62728" if on_path else "none", linewidths=1.5, zorder=5)
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


def _layer_of(G: nx.Graph, slot_name: str) -> str:
    for n, d in G.nodes(data=True):
        if n not in (START, GOAL) and d["slot"].name == slot_name:
            return d["layer"]
    return "middle"
