"""The regrasp graph of the paper's "Motion planning" section, with networkx.

Nodes are ``(slot, grasp_id, arm)``: a grasp of the part that is IK-feasible
and collision-free while the part sits at one *slot* (the detected start
pose, an intermediate stable placement at a sampled yaw, or the goal /
pre-assembly pose). Edges:

* **transfer** - same grasp and arm at two slots: the robot carries the part
  from one pose to the other without letting go;
* **transit** (a regrasp) - two grasps at one table slot (start or middle):
  the robot puts the part down, lets go and grasps it again.

Weights prefer fewer regrasps (``regrasp_penalty`` each), then shorter joint
motion (``motion_weight`` x joint-space distance, radians). A path from the
virtual ``START`` node to the virtual ``GOAL`` node is the keyframe sequence.
"""

from __future__ import annotations

import enum
import itertools
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import networkx as nx
import numpy as np

__all__ = [
    "GOAL",
    "START",
    "GraspFeasibility",
    "KeyframeSearch",
    "PoseSlot",
    "build_regrasp_graph",
    "explain_cut",
    "search_keyframes",
]

START = ("START", -1, "")
GOAL = ("GOAL", -1, "")
Layer = Literal["start", "middle", "goal"]
Node = tuple[str, int, str]


@dataclass(frozen=True)
class PoseSlot:
    """A pose of the part at which grasps are evaluated (``T_world_part``, metres)."""

    name: str
    layer: Layer
    T_world_part: np.ndarray = field(compare=False, hash=False, repr=False)


class Rejected(enum.StrEnum):
    """Why a grasp is unusable at a slot; the value is how a failure reason counts it."""

    NOT_FROM_ABOVE = "approach not from above"
    CANDIDATE_CAP = "beyond the candidate cap"
    HAND_COLLISION = "hand in collision"
    NO_IK = "no IK solution"
    PREGRASP_NO_IK = "no IK solution at the pre-grasp pose"
    ARM_COLLISION = "arm in collision"
    PREGRASP_COLLISION = "arm in collision at the pre-grasp pose"


@dataclass(frozen=True)
class Rejection:
    """One grasp's rejection at a slot: its kind, whether the table is in the collision, and the detail."""

    kind: Rejected
    detail: str = ""
    """E.g. the colliding pair (``"hand/finger0 with table"``, ``"LARM_JOINT5_Link/table"``) or the IK's reason."""
    table: bool = False
    """The table is one of the colliding bodies."""

    def __str__(self) -> str:
        return f"{self.kind.value}: {self.detail}" if self.detail else self.kind.value


@dataclass
class GraspFeasibility:
    """Grasps usable at one slot: ``(grasp_id, arm) -> q`` (joint positions, radians)."""

    slot: PoseSlot
    solutions: dict[tuple[int, str], np.ndarray]
    rejected: dict[tuple[int, str], Rejection] = field(default_factory=dict)
    """Why the other grasps are unusable here."""

    def counts(self) -> dict[str, Any]:
        """Structured failure counts at this slot: ``candidates`` (grasp variants tried), ``feasible``,
        ``rejected`` (kind value -> count) and ``with_table`` (kind value -> count of those hitting the table)."""
        kinds = Counter(r.kind.value for r in self.rejected.values())
        table = Counter(r.kind.value for r in self.rejected.values() if r.table)
        return {
            "slot": self.slot.name,
            "candidates": len(self.solutions) + len(self.rejected),
            "feasible": len(self.solutions),
            "rejected": dict(kinds.most_common()),
            "with_table": dict(table.most_common()),
        }

    def summary(self) -> str:
        """The counts in words: ``"of 80 grasp variants, 40 approach not from above, 12 hand in collision
        (9 with the table), ..."``."""
        c = self.counts()
        parts = [
            f"{n} {kind}" + (f" ({c['with_table'][kind]} with the table)" if kind in c["with_table"] else "")
            for kind, n in c["rejected"].items()
        ]
        return f"of {c['candidates']} grasp variants at {c['slot']}, " + (", ".join(parts) or "none rejected")


@dataclass
class KeyframeSearch:
    """Result of a search: the node path (without START/GOAL) or why there is none."""

    success: bool
    nodes: list[Node] = field(default_factory=list)
    cost: float = float("inf")
    regrasps: int = 0
    reason: str | None = None
    cut: Literal["start", "goal", "between"] | None = None
    """Where a failed search is cut off: no usable edge at the start, at the goal, or no path between them."""
    components: int | None = None
    """When cut ``"between"``: connected components of the grasp nodes left after the banned edges."""


def build_regrasp_graph(
    layers: Sequence[GraspFeasibility],
    *,
    regrasp_penalty: float = 10.0,
    motion_weight: float = 1.0,
) -> nx.Graph:
    """Build the graph from the feasible grasps of every slot.

    Exactly one slot must be in the ``start`` layer and at least one in the
    ``goal`` layer. Node attributes: ``q``, ``slot``, ``layer``, ``grasp``,
    ``arm``. Edge attributes: ``kind`` (``transfer`` / ``transit``) and ``weight``.
    """
    if sum(f.slot.layer == "start" for f in layers) != 1:
        raise ValueError("the regrasp graph needs exactly one start slot")
    if not any(f.slot.layer == "goal" for f in layers):
        raise ValueError("the regrasp graph needs a goal slot")
    G = nx.Graph()
    G.add_node(START)
    G.add_node(GOAL)
    by_key: dict[tuple[int, str], list[Node]] = {}
    for feas in layers:
        nodes = []
        for (gid, arm), q in sorted(feas.solutions.items()):
            node = (feas.slot.name, gid, arm)
            G.add_node(node, q=np.asarray(q, float), slot=feas.slot, layer=feas.slot.layer, grasp=gid, arm=arm)
            nodes.append(node)
            by_key.setdefault((gid, arm), []).append(node)
            if feas.slot.layer == "start":
                G.add_edge(START, node, kind="virtual", weight=0.0)
            if feas.slot.layer == "goal":
                G.add_edge(node, GOAL, kind="virtual", weight=0.0)
        if feas.slot.layer in ("start", "middle"):
            # Regrasp on the table: any two grasps at the same slot; an arm change costs the same.
            for i, a in enumerate(nodes):
                qa = G.nodes[a]["q"]
                for b in nodes[i + 1 :]:
                    motion = _joint_distance(qa, G.nodes[b]["q"]) if a[2] == b[2] else 0.0
                    G.add_edge(a, b, kind="transit", weight=regrasp_penalty + motion_weight * motion)
    for nodes in by_key.values():
        for i, a in enumerate(nodes):
            for b in nodes[i + 1 :]:
                if G.nodes[a]["layer"] == "goal" and G.nodes[b]["layer"] == "goal":
                    continue
                motion = _joint_distance(G.nodes[a]["q"], G.nodes[b]["q"])
                G.add_edge(a, b, kind="transfer", weight=1.0 + motion_weight * motion)
    return G


def _joint_distance(qa: np.ndarray, qb: np.ndarray) -> float:
    return float(np.linalg.norm(qa - qb)) if qa.shape == qb.shape else 0.0


def search_keyframes(G: nx.Graph, *, banned_edges: Iterable[tuple[Node, Node]] = ()) -> KeyframeSearch:
    """Cheapest START -> GOAL path, ignoring ``banned_edges`` (motions that failed).

    A failure says which layer is cut off (``cut``, and in its reason): no
    feasible grasp at the start, none at the goal, or no grasp shared between
    the layers (then ``components`` counts the unconnected groups of grasps).
    """
    banned = {frozenset(e) for e in banned_edges}
    view = nx.subgraph_view(G, filter_edge=lambda a, b: frozenset((a, b)) not in banned)
    if view.degree(START) == 0:
        return KeyframeSearch(False, reason="no grasp is feasible at the start pose (IK or collision)", cut="start")
    if view.degree(GOAL) == 0:
        return KeyframeSearch(False, reason="no grasp is feasible at the goal pose (IK or collision)", cut="goal")
    try:
        cost, path = nx.single_source_dijkstra(view, START, GOAL, weight="weight")
    except nx.NetworkXNoPath:
        grasps = view.subgraph([n for n in view if n not in (START, GOAL)])
        k = nx.number_connected_components(grasps)
        return KeyframeSearch(
            False,
            reason="no grasp is shared between the start and goal layers, even through intermediate placements "
            f"(the {grasps.number_of_nodes()} feasible grasps form {k} unconnected groups)",
            cut="between",
            components=k,
        )
    nodes = [n for n in path if n not in (START, GOAL)]
    regrasps = sum(G.edges[a, b]["kind"] == "transit" for a, b in itertools.pairwise(nodes))
    return KeyframeSearch(True, nodes=nodes, cost=float(cost), regrasps=regrasps)


def explain_cut(G: nx.Graph, layers: Sequence[GraspFeasibility]) -> str:
    """Why no path joins the start to the goal, in words: the slots the start's grasps reach (the start's
    connected group of grasp nodes), and how the same grasps fail at every other table slot, counted by
    rejection kind (:class:`Rejected`, those hitting the table in brackets). Empty when no grasp is feasible
    at the start."""
    start = [n for n in G.neighbors(START)]
    if not start:
        return ""
    grasps = G.subgraph([n for n in G if n not in (START, GOAL)])
    group: set[Node] = set()
    for n in start:
        if n not in group:
            group |= nx.node_connected_component(grasps, n)
    reached = sorted({n[0] for n in group} - {"start"})
    variants = {n[1] for n in group}
    kinds: Counter[str] = Counter()
    table: Counter[str] = Counter()
    others = [f for f in layers if f.slot.layer == "middle" and f.slot.name not in reached]
    for f in others:
        for (vid, _), r in f.rejected.items():
            if vid in variants or (vid % 2 == 0 and vid + 1 in variants):  # a screened grasp is keyed unflipped
                kinds[r.kind.value] += 1
                table[r.kind.value] += r.table
    names = ", ".join(reached[:3]) + (", ..." if len(reached) > 3 else "")
    where = f"{len(reached)} other slots ({names})" if reached else "no other slot"
    why = ", ".join(f"{n} {k}" + (f" ({table[k]} with the table)" if table[k] else "") for k, n in kinds.most_common())
    return f"the start's {len(variants)} grasp variants reach {where}" + (
        f"; at the {len(others)} other table slots: {why}" if why else ""
    )
