"""Placements moved toward the goal when none at the part's start connects start and goal (plan_transfer).

The fixture is made in code: a 20 x 20 x 80 mm square peg lying at y = 0.30 m
that must stand upright at (0.40, 0) m, three hand-made grasps, and a point
robot double whose IK reaches the table's edge (|y| > 0.2 m) only from
straight above. There the peg's grasp across its side (from above while it
lies) and its grasp on the top end (from above while it stands) are the only
ones that work, and no grasp works both lying and standing; nearer the middle
a diagonal grasp works both ways, so the peg must be put down there and
regrasped. When no placement anywhere connects with grasps from above, the
approaches from the side are allowed last (``min_down_last``).
"""

from collections.abc import Sequence

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.failures import FailureCause
from asmteach.core.hand_geometry import MeshCollider
from asmteach.core.interfaces import IKResult, MotionResult, Obstacle, PartModel, Robot
from asmteach.core.models import Grasp, HandSpec, PartSpec, Primitive, SolidSpec
from asmteach.core.parts import build_part
from asmteach.core.rests.placements import compute_placements
from asmteach.core.robot import PlanningScene
from asmteach.plugins.planners.regrasp.assembly import TransferResult, _search_cause, plan_transfer
from asmteach.plugins.planners.regrasp.feasibility import variant_tcp
from asmteach.plugins.planners.regrasp.graph import GraspFeasibility, KeyframeSearch, PoseSlot
from asmteach.plugins.planners.regrasp.realise import PlaceGoal
from asmteach.plugins.planners.regrasp.settings import AssemblySettings
from asmteach.plugins.planners.regrasp.slots import placement_slots, relocated_slots

HAND = HandSpec(
    name="test_2f",
    max_width=0.085,
    finger_size=[0.010, 0.020, 0.045],
    pad_size=(0.020, 0.030),
    palm_center=[0.0, 0.0, -0.050],
    palm_size=[0.040, 0.100, 0.040],
)
START_XY = np.array([0.30, 0.30])
GOAL_XY = np.array([0.40, 0.0])


class NothingCollides(PlanningScene):
    """A scene in which nothing collides and everything is 1 m clear."""

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        return np.zeros(len(np.atleast_2d(qs)), bool)

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        return np.full(len(np.atleast_2d(qs)), min(1.0, upto))


class EdgeOfReachArm(Robot):
    """One arm; configuration = TCP position and rotation vector. IK needs the approach (TCP +z) at least
    0.3 down (cosine), and at least 0.95 down where |y| > 0.2 m; nothing collides."""

    def __init__(self) -> None:
        super().__init__({})
        self.scene = NothingCollides({"left": self.home("left")})

    arms = property(lambda self: ["left"])
    hand = property(lambda self: HAND)

    def joint_names(self, arm: str) -> list[str]:
        return ["x", "y", "z", "rx", "ry", "rz"]

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        return np.full(6, -10.0), np.full(6, 10.0)

    def home(self, arm: str) -> np.ndarray:
        return np.array([0.3, 0.0, 0.3, np.pi, 0.0, 0.0])  # TCP 0.3 m up, pointing down

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        return geometry.from_rotvec(q[3:], q[:3])

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        down = -T_world_tcp[2, 2]
        if down < 0.3 or (abs(T_world_tcp[1, 3]) > 0.2 and down < 0.95):
            return IKResult(False, None, reason="wrist limit")
        q = np.concatenate([T_world_tcp[:3, 3], Rotation.from_matrix(T_world_tcp[:3, :3]).as_rotvec()])
        return IKResult(True, q, 0.0, 0.0)


class StraightLine:
    """Motion planner double: the straight joint-space line."""

    def plan(self, start: np.ndarray, goal: np.ndarray, **_: object) -> MotionResult:
        return MotionResult(True, np.stack([start, goal]))


def grasp(gid: int, approach: Sequence[float], z: float) -> Grasp:
    """Across the peg's y (20 mm) at height ``z`` of its axis, the TCP approaching along ``approach`` (part)."""
    zt = np.asarray(approach, float) / np.linalg.norm(approach)
    yt = np.array([0.0, 1.0, 0.0])
    return Grasp(
        id=gid, p0=[0.0, -0.01, z], p1=[0.0, 0.01, z], R=np.column_stack([np.cross(yt, zt), yt, zt]), width=0.02
    )


@pytest.fixture(scope="module")
def peg() -> PartModel:
    box = Primitive(shape="box", size=[0.02, 0.02, 0.08], pose={"xyz": [0, 0, 0.04]})
    return build_part(PartSpec(name="peg", solid=SolidSpec(add=[box])))


GRASPS = [
    grasp(0, [1, 0, 0], 0.04),  # across the side: from above while the peg lies on its -x face
    grasp(1, [0, 0, -1], 0.07),  # on the top end: from above while the peg stands
    grasp(2, [1, 0, -1], 0.06),
]  # diagonal: 45 deg from vertical lying and standing


LYING = Rotation.from_euler("y", 90, degrees=True).as_matrix()  # on its -x face, the axis along world +x


class SideReachArm(EdgeOfReachArm):
    """As :class:`EdgeOfReachArm`, but its IK reaches any approach not from below (cosine >= 0) where
    |y| > 0.2 m, and only near-vertical ones (>= 0.95) nearer the middle, where the goal is."""

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        down = -T_world_tcp[2, 2]
        if down < (-1e-9 if abs(T_world_tcp[1, 3]) > 0.2 else 0.95):
            return IKResult(False, None, reason="wrist limit")
        q = np.concatenate([T_world_tcp[:3, 3], Rotation.from_matrix(T_world_tcp[:3, :3]).as_rotvec()])
        return IKResult(True, q, 0.0, 0.0)


def transfer(
    peg: PartModel,
    settings: AssemblySettings,
    world: Sequence[Obstacle] = (),
    T_goal: np.ndarray | None = None,
    grasps: Sequence[Grasp] = GRASPS,
    robot: Robot | None = None,
):
    T_start = geometry.from_rotation(LYING, [*START_XY, 0.01])
    T_goal = geometry.from_rotation(np.eye(3), [*GOAL_XY, 0.0]) if T_goal is None else T_goal
    calls: list[bool] = []

    def middle(every: bool) -> list[PoseSlot]:
        calls.append(every)
        return placement_slots(compute_placements(peg), T_start[:2, 3], 0.0, settings, every=every)

    robot = EdgeOfReachArm() if robot is None else robot
    before = robot.scene
    res = plan_transfer(
        robot,
        robot.scene,
        StraightLine(),
        peg,
        grasps,
        T_start=T_start,
        goal=PlaceGoal(PoseSlot("goal", "goal", T_goal), np.array([0.0, 0.0, 0.05]), on_table=False),
        middle_slots=middle,
        world=list(world),
        q_now={"left": robot.home("left")},
        settings=settings,
    )
    assert robot.scene is before and before.obstacles == () and not before.attached  # the robot's is left alone
    assert res.scene is not None and not res.scene.attached  # the scene the transfer ends with: hands empty
    return res, calls


def test_a_peg_is_stood_up_further_toward_the_goal_when_no_placement_at_its_start_connects(peg) -> None:
    res, calls = transfer(peg, AssemblySettings(placement_yaws=2))
    assert res.success, res.reason
    assert calls == [False, True]  # the chosen placements, every placement, then the same moved
    assert res.stats["relocations"] == [0.5]
    # picked across the side at the start, put down half way (0.35, 0.15), regrasped diagonally, stood up
    names = [n[0] for n in res.search.nodes]
    assert names[0] == "start" and names[-1] == "goal" and res.search.regrasps == 1
    moved = [n for n in names if n.endswith("_at350_150")]
    assert moved and all(n in moved for n in names[1:-1])
    assert [n[1] // 2 for n in res.search.nodes] == [0, 0, 2, 2]


def test_a_peg_that_needs_no_regrasp_is_carried_straight_there(peg) -> None:
    """The cheap search comes first: no placement is evaluated, let alone moved."""
    res, calls = transfer(
        peg, AssemblySettings(placement_yaws=2), T_goal=geometry.from_rotation(LYING, [*GOAL_XY, 0.01])
    )
    assert res.success, res.reason
    assert calls == [] and "relocations" not in res.stats
    assert [n[0] for n in res.search.nodes] == ["start", "goal"]


def test_without_relocations_the_peg_cannot_be_turned(peg) -> None:
    res, calls = transfer(peg, AssemblySettings(placement_yaws=2, relocations=()))
    assert not res.success and calls == [False, True]
    assert "relocations" not in res.stats
    # grasps at the start and at the goal, none connecting them: the regrasp graph is cut, not the grasps
    assert res.stats["cut"] == "between" and res.cause is FailureCause.REGRASP_GRAPH
    # and the reason says how far the start's grasps get, and why they fail at the other placements
    assert "the start's 1 grasp variants reach 2 other slots (placement" in res.reason
    # (screened last with approaches from the side allowed, which this arm's IK does not reach)
    assert res.stats["feasible"]["sideways"] is True
    assert "other table slots: 8 no IK solution, 2 approach not from above;" in res.reason


def test_a_peg_no_grasp_from_above_can_turn_is_turned_with_a_grasp_from_the_side(peg) -> None:
    """Without the diagonal grasp, no placement shares a grasp from above (cosine >= 0.3) between lying and
    standing, and the goal takes only the grasp on the top end: the lying peg is picked by that end from the
    side and carried upright to its goal."""
    settings = AssemblySettings(placement_yaws=2, relocations=())
    res, _ = transfer(peg, settings, grasps=GRASPS[:2], robot=SideReachArm())
    assert res.success, res.reason
    assert res.stats["feasible"]["sideways"] is True
    assert [n[1] // 2 for n in res.search.nodes] == [1, 1] and res.search.regrasps == 0
    start = res.search.nodes[0]
    T_world_tcp = res.graph.nodes[start]["slot"].T_world_part @ variant_tcp(dict(enumerate(GRASPS)), start[1])
    assert abs(T_world_tcp[2, 2]) < 1e-9  # the approach is horizontal
    # the bound at or above min_down: never from the side, and the graph stays cut
    off, _ = transfer(peg, settings.model_copy(update={"min_down_last": 0.3}), grasps=GRASPS[:2], robot=SideReachArm())
    assert not off.success and off.stats["cut"] == "between" and "sideways" not in off.stats["feasible"]


def test_a_position_too_near_an_obstacle_is_skipped_for_the_next(peg) -> None:
    """A box on the half-way point: the placements go three quarters of the way instead (0.375, 0.075)."""
    box = Obstacle(
        "box", trimesh.creation.box(extents=[0.02, 0.02, 0.02]), geometry.from_rotation(np.eye(3), [0.35, 0.15, 0.01])
    )
    settings = AssemblySettings(placement_yaws=2, relocations=(0.5, 0.75), relocation_clearance=0.01)
    res, _ = transfer(peg, settings, world=[box])
    assert res.success, res.reason
    assert res.stats["relocations"] == [0.5, 0.75]
    assert any(n[0].endswith("_at375_75") for n in res.search.nodes)


def test_relocated_slots_move_every_slot_or_none(peg) -> None:
    slots = placement_slots(compute_placements(peg), START_XY, 0.0, AssemblySettings(placement_yaws=2))
    far = MeshCollider(
        {
            "box": (
                trimesh.creation.box(extents=[0.04, 0.04, 0.04]),
                geometry.from_rotation(np.eye(3), [0.35, 0.40, 0.02]),
            )
        }
    )
    moved = relocated_slots(slots, START_XY, (0.35, 0.15), peg, far, clearance=0.03)
    assert [s.name for s in moved] == [f"{s.name}_at350_150" for s in slots]
    for s, m in zip(slots, moved, strict=True):
        np.testing.assert_allclose(m.T_world_part[:3, :3], s.T_world_part[:3, :3])
        np.testing.assert_allclose(m.T_world_part[:3, 3] - s.T_world_part[:3, 3], [0.05, -0.15, 0.0], atol=1e-12)
    assert relocated_slots(slots, START_XY, (0.30, 0.35), peg, far, clearance=0.03) == []  # within 3 cm of the box


class TimesOut:
    """Motion planner double: every query cut by its wall-clock limit."""

    def plan(self, start: np.ndarray, goal: np.ndarray, **_: object) -> MotionResult:
        from asmteach.core.failures import FailureKind

        return MotionResult(False, reason="timeout after 5.0 s", kind=FailureKind.TIMEOUT)


def test_re_searches_are_counted_and_wall_clock_cuts_reported(peg) -> None:
    """The search gives up after max_attempts keyframe sequences (a count, not the machine's speed), and
    every motion a wall-clock limit cut is listed: the plan then depends on the load, and says so."""
    T_start = geometry.from_rotation(LYING, [*START_XY, 0.01])
    robot = EdgeOfReachArm()
    res = plan_transfer(
        robot,
        robot.scene,
        TimesOut(),
        peg,
        GRASPS,
        T_start=T_start,
        goal=PlaceGoal(
            PoseSlot("goal", "goal", geometry.from_rotation(LYING, [*GOAL_XY, 0.01])),
            np.array([0.0, 0.0, 0.05]),
            on_table=False,
        ),
        middle_slots=lambda every: [],
        world=[],
        q_now={"left": robot.home("left")},
        settings=AssemblySettings(placement_yaws=2, max_attempts=1),
    )
    assert not res.success
    assert "1 keyframe sequences tried (max_attempts)" in (res.reason or "")
    assert res.cause is FailureCause.MOTION  # keyframes were found; their motions were not
    assert res.stats["wall_clock_cuts"] == ["motion to the pre-grasp at start: timeout after 5.0 s"]


def test_a_goal_no_grasp_reaches_says_how_many_fail_and_why(peg) -> None:
    """The peg upside down at its goal: every grasp approaches from below there, past the wrist limit; the
    reason counts them, and the result holds the counts per slot and where the time went."""
    flipped = geometry.from_rotation(Rotation.from_euler("x", np.pi).as_matrix() @ LYING, [*GOAL_XY, 0.3])
    res, _ = transfer(peg, AssemblySettings(placement_yaws=2, max_placements=0), T_goal=flipped)
    assert not res.success and res.stats["cut"] == "goal" and res.cause is FailureCause.NO_GRASP
    assert (
        "no grasp is feasible at the goal pose (IK or collision): of 3 grasp variants at goal, 3 no IK " in res.reason
    )
    assert " s spent: " in res.reason and " s on motions" in res.reason
    goal = next(c for c in res.layers if c["slot"] == "goal")
    assert goal == {"slot": "goal", "candidates": 3, "feasible": 0, "rejected": {"no IK solution": 3}, "with_table": {}}


def test_a_layer_emptied_by_banned_motions_is_a_motion_failure_not_a_missing_grasp() -> None:
    cut = KeyframeSearch(False, cut="start")
    empty = [
        GraspFeasibility(PoseSlot("start", "start", np.eye(4)), {}),
        GraspFeasibility(PoseSlot("goal", "goal", np.eye(4)), {}),
    ]
    solved = [GraspFeasibility(PoseSlot("start", "start", np.eye(4)), {(1, "left"): np.zeros(6)}), empty[1]]
    assert _search_cause(cut, empty) is FailureCause.NO_GRASP
    assert _search_cause(cut, solved) is FailureCause.MOTION  # every start grasp banned after its motion failed
    assert _search_cause(KeyframeSearch(False, cut="between", components=2), solved) is FailureCause.REGRASP_GRAPH


def test_the_assembly_planner_returns_the_failed_transfers_cause() -> None:
    from asmteach.core.interfaces import AssemblyResult
    from asmteach.core.models import Plan
    from asmteach.plugins.planners.regrasp.planner import RegraspAssemblyPlanner

    planner = RegraspAssemblyPlanner(RegraspAssemblyPlanner.Settings(), seed=0)
    failed = TransferResult(False, reason="no grasp is feasible at the goal pose", cause=FailureCause.NO_GRASP)
    result = planner._fail(AssemblyResult(False, Plan()), failed, "part A (peg)", 0.0, EdgeOfReachArm())
    assert not result.success and result.cause is FailureCause.NO_GRASP
    assert result.reason == "part A (peg): no grasp is feasible at the goal pose"


# ---------------------------------------------------------------- symmetric goals


def test_an_upside_down_goal_of_a_symmetric_peg_is_reached_through_its_equivalent(peg) -> None:
    """The goal no grasp reaches (above), with the peg's 180 deg turn about x as an equivalent goal slot: the
    same solid in the same place, upright, so the top-end grasp puts it there."""
    from asmteach.plugins.planners.regrasp.planner import RegraspAssemblyPlanner

    flipped = geometry.from_rotation(Rotation.from_euler("x", np.pi).as_matrix() @ LYING, [*GOAL_XY, 0.3])
    planner = RegraspAssemblyPlanner({"goal_symmetries": 8}, seed=0)
    first, others = planner._goal_slots(peg, flipped)
    assert first.name == "assembled" and len(others) == 7  # a square bar: 4 turns about its axis x 2 ends
    for slot in others:  # every one the same solid in the same place
        np.testing.assert_allclose(
            np.sort(transform(slot.T_world_part, peg), axis=0), np.sort(transform(flipped, peg), axis=0), atol=1e-6
        )
    assert len(RegraspAssemblyPlanner({"goal_symmetries": 1}, seed=0)._goal_slots(peg, flipped)[1]) == 0
    T_start = geometry.from_rotation(LYING, [*START_XY, 0.01])
    robot = EdgeOfReachArm()
    res = plan_transfer(
        robot,
        robot.scene,
        StraightLine(),
        peg,
        GRASPS,
        T_start=T_start,
        goal=PlaceGoal(first, np.array([0.0, 0.0, 0.05]), on_table=False, alternatives=others),
        middle_slots=lambda every: placement_slots(
            compute_placements(peg), T_start[:2, 3], 0.0, AssemblySettings(), every=every
        ),
        world=[],
        q_now={"left": robot.home("left")},
        settings=AssemblySettings(),
    )
    assert res.success, res.reason
    assert res.stats["feasible"]["goal_slots"] == 8 and res.stats["feasible"]["goal"] > 0
    end = res.search.nodes[-1]
    assert end[0].startswith("assembled_sym")  # the taught pose itself has no feasible grasp
    assert [s.label for s in res.steps if s.label.startswith("insert")] == [f"insert peg at {end[0]}"]


def transform(T: np.ndarray, part: PartModel) -> np.ndarray:
    """The part's vertices at pose ``T`` (world, metres)."""
    return geometry.transform_points(T, part.mesh.vertices)


def test_no_grasp_at_any_goal_slot_is_a_missing_grasp() -> None:
    goals = [GraspFeasibility(PoseSlot(f"g{k}", "goal", np.eye(4)), {}) for k in range(3)]
    start = GraspFeasibility(PoseSlot("start", "start", np.eye(4)), {(1, "left"): np.zeros(6)})
    cut = KeyframeSearch(False, cut="goal")
    assert _search_cause(cut, [start, *goals], 4) is FailureCause.NO_GRASP
    goals[2].solutions[(1, "left")] = np.zeros(6)
    assert _search_cause(cut, [start, *goals], 4) is FailureCause.MOTION
