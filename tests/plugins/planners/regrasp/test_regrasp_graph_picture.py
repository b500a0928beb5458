"""The regrasp graph's picture stays bounded for a widened search's graph (tens of thousands of nodes, hundreds of
thousands of edges): a capped size and a share of the edges, said in the title."""

from __future__ import annotations

import itertools
from pathlib import Path

import networkx as nx
import numpy as np
from PIL import Image

from asmteach.plugins.planners.regrasp import plan_io
from asmteach.plugins.planners.regrasp.graph import GOAL, START, PoseSlot


def _graph(slots: int, per_slot: int) -> tuple[nx.Graph, list]:
    """``slots`` middle slots of ``per_slot`` grasp nodes, every node of a slot joined to every node of the next."""
    G = nx.Graph()
    G.add_node(START)
    G.add_node(GOAL)
    layers = []
    for k in range(slots):
        slot = PoseSlot(f"placement{k}", "middle", np.eye(4))
        nodes = [(slot.name, g, "left" if g % 2 else "right") for g in range(per_slot)]
        for n in nodes:
            G.add_node(n, slot=slot, layer="middle")
        layers.append(nodes)
    for a_nodes, b_nodes in itertools.pairwise(layers):
        G.add_edges_from(((a, b) for a in a_nodes for b in b_nodes), kind="transfer")
    G.add_edge(START, layers[0][0], kind="virtual")
    G.add_edge(layers[-1][0], GOAL, kind="virtual")
    return G, [layer[0] for layer in layers]


def test_a_large_graph_draws_a_share_of_its_edges_in_a_capped_picture(tmp_path: Path, monkeypatch) -> None:
    import matplotlib.axes

    monkeypatch.setattr(plan_io, "GRAPH_MAX_EDGES", 1000)
    seen: list[str] = []
    real = matplotlib.axes.Axes.set_title
    monkeypatch.setattr(
        matplotlib.axes.Axes, "set_title", lambda ax, t, *a, **k: seen.append(t) or real(ax, t, *a, **k)
    )
    G, path = _graph(slots=3, per_slot=150)  # 2 x 22 500 edges; uncapped, 44 inches tall
    out = plan_io.render_regrasp_graph(G, path, tmp_path / "g.png", title="B")
    w, h = Image.open(out).size
    assert w <= plan_io.GRAPH_MAX_INCHES * 110 + 1 and h <= plan_io.GRAPH_MAX_INCHES * 110 + 1
    drawn = -(-(G.number_of_edges() - 4) // 45)  # every 45th of the edges off the path (4 on it)
    assert seen[-1] == f"B ({drawn} of {G.number_of_edges() - 4} edges drawn)"


def test_a_small_graph_is_drawn_whole(tmp_path: Path, monkeypatch) -> None:
    import matplotlib.axes

    seen: list[str] = []
    real = matplotlib.axes.Axes.set_title
    monkeypatch.setattr(
        matplotlib.axes.Axes, "set_title", lambda ax, t, *a, **k: seen.append(t) or real(ax, t, *a, **k)
    )
    G, path = _graph(slots=3, per_slot=10)
    plan_io.render_regrasp_graph(G, path, tmp_path / "g.png", title="B")
    assert seen[-1] == "B"
