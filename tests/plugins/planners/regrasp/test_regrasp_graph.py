import numpy as np
import pytest

from asmteach.plugins.planners.regrasp.graph import (
    GOAL,
    START,
    GraspFeasibility,
    PoseSlot,
    Rejected,
    Rejection,
    build_regrasp_graph,
    search_keyframes,
)

I4 = np.eye(4)


def feas(name, layer, grasps, arm="left"):
    slot = PoseSlot(name, layer, I4)
    return GraspFeasibility(slot, {(g, arm): np.full(3, 0.1 * g) for g in grasps})


def test_direct_transfer_when_a_grasp_is_shared():
    G = build_regrasp_graph([feas("start", "start", [1, 2]), feas("goal", "goal", [2, 3])])
    res = search_keyframes(G)
    assert res.success and res.regrasps == 0
    assert res.nodes == [("start", 2, "left"), ("goal", 2, "left")]


def test_regrasp_through_an_intermediate_placement():
    layers = [
        feas("start", "start", [1]),
        feas("p0_yaw0", "middle", [1, 5]),
        feas("goal", "goal", [5]),
    ]
    res = search_keyframes(build_regrasp_graph(layers))
    assert res.success and res.regrasps == 1
    assert res.nodes == [("start", 1, "left"), ("p0_yaw0", 1, "left"), ("p0_yaw0", 5, "left"), ("goal", 5, "left")]


def test_fewer_regrasps_beat_shorter_motion():
    layers = [
        feas("start", "start", [1, 9]),
        feas("mid", "middle", [1, 2]),
        feas("goal", "goal", [2, 9]),
    ]
    # grasp 9 goes straight through (far in joint space); 1 -> 2 needs a regrasp.
    res = search_keyframes(build_regrasp_graph(layers, regrasp_penalty=10.0))
    assert res.regrasps == 0 and res.nodes[0][1] == 9


def test_banned_edge_forces_the_next_best_path():
    G = build_regrasp_graph([feas("start", "start", [1, 2]), feas("goal", "goal", [1, 2])])
    first = search_keyframes(G)
    second = search_keyframes(G, banned_edges=[(first.nodes[0], first.nodes[1])])
    assert second.success and second.nodes[0][1] != first.nodes[0][1]


@pytest.mark.parametrize(
    "layers, reason, cut",
    [
        ([feas("start", "start", []), feas("goal", "goal", [1])], "start pose", "start"),
        ([feas("start", "start", [1]), feas("goal", "goal", [])], "goal pose", "goal"),
        ([feas("start", "start", [1]), feas("goal", "goal", [2])], "no grasp is shared", "between"),
    ],
)
def test_failures_say_which_layer(layers, reason, cut):
    res = search_keyframes(build_regrasp_graph(layers))
    assert not res.success and reason in res.reason and res.cut == cut


def test_a_cut_graph_counts_its_unconnected_groups():
    """Start grasps 1, 2 (regrasp on the table joins them), a middle slot sharing nothing, goal grasp 7."""
    layers = [feas("start", "start", [1, 2]), feas("mid", "middle", [5, 6]), feas("goal", "goal", [7])]
    res = search_keyframes(build_regrasp_graph(layers))
    assert not res.success and res.cut == "between" and res.components == 3
    assert "the 5 feasible grasps form 3 unconnected groups" in res.reason


def test_rejections_are_counted_by_kind_and_table():
    f = feas("start", "start", [1])
    f.rejected = {
        (2, ""): Rejection(Rejected.NOT_FROM_ABOVE),
        (4, ""): Rejection(Rejected.HAND_COLLISION, "hand/finger0 with table", table=True),
        (6, ""): Rejection(Rejected.HAND_COLLISION, "hand/palm with box"),
        (8, "left"): Rejection(Rejected.NO_IK, "unreachable"),
        (10, "left"): Rejection(Rejected.ARM_COLLISION, "LARM_JOINT5_Link/table", table=True),
    }
    c = f.counts()
    assert c["candidates"] == 6 and c["feasible"] == 1
    assert c["rejected"] == {
        "hand in collision": 2,
        "approach not from above": 1,
        "no IK solution": 1,
        "arm in collision": 1,
    }
    assert c["with_table"] == {"hand in collision": 1, "arm in collision": 1}
    assert f.summary().startswith("of 6 grasp variants at start, 2 hand in collision (1 with the table), ")
    assert str(f.rejected[(8, "left")]) == "no IK solution: unreachable"


def test_transfer_needs_the_same_arm():
    layers = [
        GraspFeasibility(PoseSlot("start", "start", I4), {(1, "left"): np.zeros(3)}),
        GraspFeasibility(PoseSlot("goal", "goal", I4), {(1, "right"): np.zeros(3)}),
    ]
    G = build_regrasp_graph(layers)
    assert not search_keyframes(G).success
    assert G.degree(START) == 1 and G.degree(GOAL) == 1


def test_graph_needs_one_start_and_a_goal():
    with pytest.raises(ValueError, match="exactly one start"):
        build_regrasp_graph([feas("goal", "goal", [1])])
