"""Assembly planning on the real Nextage model: goals, placement slots, a whole two-part plan."""

from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from asmteach.core import geometry, registry
from asmteach.core.config import SceneSettings
from asmteach.core.interfaces import AssemblyProblem, Robot
from asmteach.core.models import TablePlane
from asmteach.core.parts import build_part, load_structure
from asmteach.core.rests.placements import compute_placements
from asmteach.core.scene import random_start_poses
from asmteach.core.trajectory.interpolate import densify
from asmteach.plugins.planners.regrasp.goals import choose_assembly_goal
from asmteach.plugins.planners.regrasp.settings import AssemblySettings
from asmteach.plugins.planners.regrasp.slots import placement_slots

STRUCTURE = "configs/parts/set1/peg_in_hole.yaml"


@contextmanager
def random_scene(structure: str, seed: int) -> Iterator[tuple[Robot, AssemblyProblem]]:
    """The Nextage and the assembly sweep's scene ``seed`` of ``structure`` (both parts at random start poses);
    the robot is closed afterwards."""
    task = load_structure(structure)
    a, b = build_part(task.part_a), build_part(task.part_b)
    robot = registry.create("robots", "nextage_pybullet", {"ik": {"max_starts": 4}}, seed=seed)
    try:
        grasps = registry.create("grasp_planners", "antipodal", {}, seed=seed)
        T_a, T_b = random_start_poses([a, b], 0.0, SceneSettings(), np.random.default_rng([seed, 11]))
        yield (
            robot,
            AssemblyProblem(
                a, b, task, T_a, T_b, grasps.plan(a, robot.hand), grasps.plan(b, robot.hand), TablePlane(height=0.0)
            ),
        )
    finally:
        robot.close()


@pytest.fixture(scope="module")
def peg():
    task = load_structure(STRUCTURE)
    return task, build_part(task.part_a), build_part(task.part_b)


def test_goal_makes_the_insertion_vertical_and_keeps_b_above_the_table(peg) -> None:
    task, a, b = peg
    goal = choose_assembly_goal(
        a, b, task, compute_placements(a), xy=(0.4, 0.0), yaw=0.3, table_height=0.1, retract=0.05
    )
    np.testing.assert_allclose(goal.v_world, [0.0, 0.0, -1.0], atol=1e-9)
    np.testing.assert_allclose(goal.T_world_b, goal.T_world_a @ task.T_A_B, atol=1e-12)
    # pre-assembly: 50 mm back along -v_a, i.e. straight up
    np.testing.assert_allclose(goal.T_world_b_pre[:3, 3] - goal.T_world_b[:3, 3], [0, 0, 0.05], atol=1e-12)
    low_a = geometry.transform_points(goal.T_world_a, a.mesh.vertices)[:, 2].min()
    assert low_a == pytest.approx(0.1, abs=1e-9)


@pytest.mark.parametrize(("tilt_deg", "snapped"), [(0.9, True), (5.0, False)])
def test_a_taught_insertion_a_degree_off_vertical_goes_straight_down(peg, tilt_deg: float, snapped: bool) -> None:
    """Teaching noise of ~1 deg in v_a would start B 0.8 mm off the hole's axis 50 mm above it (0.4 mm
    where it enters a 25 mm deep hole with 0.5 mm clearance); a clearly slanted v_a is kept."""
    task, a, b = peg
    t = np.radians(tilt_deg)
    tilted = task.model_copy(update={"v_a": np.array([np.sin(t), 0.0, -np.cos(t)])})
    goal = choose_assembly_goal(
        a, b, tilted, compute_placements(a), xy=(0.4, 0.0), yaw=0.3, table_height=0.1, retract=0.05
    )
    np.testing.assert_allclose(goal.T_world_b, goal.T_world_a @ task.T_A_B, atol=1e-12)
    np.testing.assert_allclose(goal.T_world_b_pre[:3, 3] - goal.T_world_b[:3, 3], -0.05 * goal.v_world, atol=1e-12)
    if snapped:
        np.testing.assert_array_equal(goal.v_world, [0.0, 0.0, -1.0])
    else:
        assert np.degrees(np.arccos(-goal.v_world[2])) == pytest.approx(tilt_deg, abs=1e-6)
    off = choose_assembly_goal(
        a, b, tilted, compute_placements(a), xy=(0.4, 0.0), yaw=0.3, table_height=0.1, retract=0.05, vertical_snap=0.0
    )
    assert np.degrees(np.arccos(-off.v_world[2])) == pytest.approx(tilt_deg, abs=1e-6)


def test_a_slider_longer_than_the_retraction_is_retracted_clear_of_its_slot() -> None:
    """A 60 mm slider pushed 60 mm along -x into a 90 mm block: 50 mm back would leave it 10 mm in its slot."""
    from asmteach.core.models import AssemblyTask, PartSpec, Primitive, SolidSpec

    def spec(name: str, size: list[float], **kw) -> PartSpec:
        box = Primitive(shape="box", size=size, pose={"xyz": [0, 0, size[2] / 2]})
        return PartSpec(name=name, solid=SolidSpec(add=[box], **kw))

    block = spec(
        "slot_block",
        [0.090, 0.060, 0.040],
        subtract=[Primitive(shape="box", size=[0.100, 0.021, 0.020], pose={"xyz": [0, 0, 0.035]})],
    )
    slider = spec("slider", [0.060, 0.020, 0.020])
    task = AssemblyTask(name="slide", part_a=block, part_b=slider, T_A_B={"xyz": [-0.015, 0, 0.025]}, v_a=[-1, 0, 0])
    a, b = build_part(block), build_part(slider)
    goal = choose_assembly_goal(
        a, b, task, compute_placements(a), xy=(0.4, 0.0), yaw=0.0, table_height=0.0, retract=0.05
    )
    back = goal.T_world_b_pre[:3, 3] - goal.T_world_b[:3, 3]
    # along the insertion line, B's rear end (0.030 behind its origin at -0.015) passes A's end (+0.045)
    # by the 5 mm margin: 0.095 m back, whichever way A stands
    np.testing.assert_allclose(back, -0.095 * goal.v_world, atol=1e-9)
    pre_b = geometry.transform_points(goal.T_world_b_pre, b.mesh.vertices) @ -goal.v_world
    at_a = geometry.transform_points(goal.T_world_a, a.mesh.vertices) @ -goal.v_world
    assert pre_b.min() == pytest.approx(at_a.max() + 0.005, abs=1e-9)


def test_placement_slots_skip_placements_equal_under_the_parts_symmetry(peg) -> None:
    _, _, b = peg
    placements = compute_placements(b)  # square head: four lying placements are one
    slots = placement_slots(placements, (0.3, 0.2), 0.0, AssemblySettings(max_placements=10, placement_yaws=2))
    names = {s.name.split("_yaw")[0] for s in slots}
    assert len(placements) == 6 and len(names) == 3
    assert len(slots) == 6
    for s in slots:
        low = geometry.transform_points(s.T_world_part, b.mesh.vertices)[:, 2].min()
        assert low == pytest.approx(0.0, abs=1e-9)


def test_placement_slots_start_with_the_exact_start_and_goal_placements(peg) -> None:
    """The peg lies on the side its grasps from above belong to, and stands on its shank at its goal
    (the least probable placement): both come first, ahead of the symmetric lying variant ranked first."""
    _, _, b = peg
    placements = compute_placements(b)
    lying = [p for p in placements if abs(p.T_table_part[2, 3] - 0.020) < 1e-6]
    shank = min(placements, key=lambda p: p.probability)
    start = lying[-1]
    assert start.id != lying[0].id
    T_goal = geometry.from_rpy(0.0, 0.0, 0.7) @ shank.T_table_part
    slots = placement_slots(
        placements,
        (0.3, 0.2),
        0.0,
        AssemblySettings(max_placements=2, placement_yaws=1),
        first=(geometry.from_rpy(0.0, 0.0, -1.1)[:3, :3] @ start.T_table_part[:3, :3], T_goal[:3, :3]),
    )
    assert [s.name for s in slots] == [f"placement{start.id}_yaw0", f"placement{shank.id}_yaw0"]


def test_placement_slots_every_keeps_symmetric_duplicates(peg) -> None:
    """The planner's second try: every placement, the four equal lying ones of the peg included."""
    _, _, b = peg
    placements = compute_placements(b)
    slots = placement_slots(
        placements, (0.3, 0.2), 0.0, AssemblySettings(max_placements=1, placement_yaws=2), every=True
    )
    assert sorted({s.name.split("_yaw")[0] for s in slots}) == sorted(f"placement{p.id}" for p in placements)
    assert len(slots) == 2 * len(placements)


@pytest.mark.slow
def test_peg_in_hole_plan_is_collision_free_and_ends_assembled(peg_in_hole_plan) -> None:
    task, a, b = peg_in_hole_plan.task, peg_in_hole_plan.a, peg_in_hole_plan.b
    robot, res = peg_in_hole_plan.robot, peg_in_hole_plan.result
    assert res.success, res.reason
    plan = res.plan
    closes = [s.gripper for s in plan.segments if s.gripper is not None and s.gripper.action == "close"]
    assert closes[0].attach == a.name and closes[-1].attach == b.name
    # every trajectory: within joint limits, starts where the previous one of its arm ended
    last: dict[str, np.ndarray] = {arm: robot.home(arm) for arm in robot.arms}
    for seg in plan.segments:
        if seg.trajectory is None:
            continue
        tr = seg.trajectory
        lo, hi = robot.joint_limits(tr.arm)
        q = np.asarray(tr.positions)
        assert np.all(q >= lo - 1e-9) and np.all(q <= hi + 1e-9)
        np.testing.assert_allclose(q[0], last[tr.arm], atol=1e-6, err_msg=seg.label)
        last[tr.arm] = q[-1]
    # where B is released, its TCP holds it at the assembled pose
    insert = next(s for s in plan.segments if s.label.startswith("insert"))
    T_tcp = robot.fk(insert.trajectory.arm, np.asarray(insert.trajectory.positions)[-1])
    T_b_goal = res.T_world_b_goal
    grasp_at_goal = np.linalg.inv(T_b_goal) @ T_tcp  # constant part->tcp offset of the grasp used
    assert np.linalg.norm(grasp_at_goal[:3, 3]) < 0.1
    np.testing.assert_allclose(T_b_goal, res.T_world_a_goal @ task.T_A_B, atol=1e-9)
    # free motions re-checked densely against the world with no part held (home moves at the end)
    empty = robot.scene.with_obstacles([]).with_attached("left", None)
    home_moves = [s for s in plan.segments if s.label.endswith("home") and s.trajectory is not None]
    assert home_moves
    for seg in home_moves:
        dense = densify(np.asarray(seg.trajectory.positions), 0.01)
        assert not empty.in_collision(seg.trajectory.arm, dense).any()


@pytest.mark.slow
def test_plan_insertion_aims_b_at_an_a_seen_off_its_goal(peg_in_hole_plan) -> None:
    """A seen 1 mm and 1 deg off its planned goal: B's segments alone, from where the arms are, into that A."""
    p = peg_in_hole_plan
    robot, task = p.robot, p.task
    T_seen = geometry.compose(
        geometry.from_rpy(0, 0, 0, t=[0.001, 0.0, 0.0]), p.result.T_world_a_goal, geometry.rot_z(np.radians(1.0))
    )
    grasps = registry.create("grasp_planners", "antipodal", {}, seed=0)
    problem = AssemblyProblem(
        p.a,
        p.b,
        task,
        T_seen,
        p.T_b,
        grasps.plan(p.a, robot.hand),
        grasps.plan(p.b, robot.hand),
        TablePlane(height=0.0),
    )
    planner = registry.create("assembly_planners", "regrasp", {}, seed=0)
    motion = registry.create("motion_planners", "rrtconnect", {}, seed=0)
    q_now = {arm: robot.current(arm) for arm in robot.arms}
    before = robot.scene
    res = planner.plan_insertion(problem, robot, motion, T_world_a=T_seen)
    assert robot.scene is before  # planning makes scene values of its own and leaves the robot's alone
    assert res.success, res.reason
    assert {seg.part for seg in res.plan.segments} == {p.b.name}
    first = next(s for s in res.plan.segments if s.trajectory is not None).trajectory
    np.testing.assert_allclose(first.positions[0], q_now[first.arm], atol=1e-6)
    # the plan returns the scene it ends in: every arm where its last segment left it
    last = {seg.trajectory.arm: seg.trajectory for seg in res.plan.segments if seg.trajectory is not None}
    assert res.scene is not None and res.scene is not before
    for arm, traj in last.items():
        np.testing.assert_allclose(res.scene.configuration[arm], np.asarray(traj.positions)[-1], atol=1e-6)
    np.testing.assert_allclose(res.T_world_b_goal, T_seen @ task.T_A_B, atol=1e-12)
    # B ends at the assembled pose in the A seen: follow B through each pick and place (a regrasp, when the
    # grasp set makes one the planner's choice) to the grasp it is inserted with
    segs = res.plan.segments
    k_insert = next(k for k, s in enumerate(segs) if s.label.startswith("insert"))
    T_b_world, T_b_tcp = p.T_b, None
    for k, seg in enumerate(segs[:k_insert]):
        if seg.gripper is None:
            continue
        last = next(s for s in reversed(segs[:k]) if s.trajectory is not None).trajectory
        T_tcp = robot.fk(last.arm, np.asarray(last.positions)[-1])
        if seg.gripper.action == "close":
            T_b_tcp = np.linalg.inv(T_b_world) @ T_tcp
        elif T_b_tcp is not None:  # let go just above the table, B lands on it (table top z = 0)
            T_b_world = T_tcp @ np.linalg.inv(T_b_tcp)
            T_b_world[2, 3] -= geometry.transform_points(T_b_world, p.b.mesh.vertices)[:, 2].min()
    insert = segs[k_insert].trajectory
    T_b_end = robot.fk(insert.arm, np.asarray(insert.positions)[-1]) @ np.linalg.inv(T_b_tcp)
    err = geometry.invert(res.T_world_b_goal) @ T_b_end
    assert np.linalg.norm(err[:3, 3]) < 2e-4
    for arm, q in q_now.items():  # planning leaves the arms where they were
        np.testing.assert_allclose(robot.current(arm), q, atol=1e-9)


def test_goals_are_ranked_by_how_vertical_they_make_the_insertion() -> None:
    """The T-slot's slider goes in along A's -x: A standing on its end makes that straight down, but the slot
    goes through and the slider would drop out of it, so that goal comes last; of those holding the slider,
    the most vertical come first, and lying flat (A's likeliest placement) makes the insertion horizontal."""
    from asmteach.plugins.planners.regrasp.goals import ranked_assembly_goals

    task = load_structure("configs/parts/set1/t_slot.yaml")
    a, b = build_part(task.part_a), build_part(task.part_b)
    placements = compute_placements(a)
    goals = ranked_assembly_goals(a, b, task, placements, xy=(0.4, 0.0), yaw=0.0, table_height=0.0, retract=0.05)
    held = [g for g in goals if g.held]
    down = [float(-g.v_world[2]) for g in held]
    assert down == sorted(down, reverse=True) and goals[: len(held)] == held
    assert [g.held for g in goals[len(held) :]] == [False] and goals[-1].v_world[2] == -1.0  # on its end
    likeliest = max(placements, key=lambda p: p.probability).id
    flat = next(g for g in goals if g.placement_id == likeliest)
    assert abs(flat.v_world[2]) < 1e-9 and flat.held
    first = choose_assembly_goal(a, b, task, placements, xy=(0.4, 0.0), yaw=0.0, table_height=0.0, retract=0.05)
    assert first.placement_id == goals[0].placement_id


@pytest.mark.slow
def test_a_slider_whose_upright_goal_leaves_one_grasp_is_assembled_with_a_lying_flat() -> None:
    """Stood on its end, the T-slot leaves only 19 mm of the slider's rib outside it, beside its face, and the
    Nextage reaches one grasp of it there; the slot goes through, so the slider would drop out of it too: the
    planner puts A down flat and slides B in sideways."""
    from asmteach.plugins.planners.regrasp.plan_io import table_obstacle

    with random_scene("configs/parts/set1/t_slot.yaml", 0) as (robot, problem):
        task = problem.task
        motion = registry.create("motion_planners", "trrt", {}, seed=0)
        unchecked = registry.create("assembly_planners", "regrasp", {"min_goal_grasps": 0}, seed=0)
        chosen = unchecked._choose_goal(problem, robot, robot.scene, table_obstacle(robot.scene, 0.0), None)[0]
        assert chosen.held  # unchecked: the first ranked, the slider held (on its end it drops out of the slot)
        messages: list[str] = []
        res = registry.create("assembly_planners", "regrasp", {}, seed=0).plan(
            problem, robot, motion, progress=messages.append
        )
        assert res.success, res.reason
        assert abs(res.details["v_world"][2]) < 1e-9  # sideways into a lying A
        assert res.details["goal_grasps_b"] >= 3
        assert res.details["goal_holds_b"]  # the first ranked: no message about passing over the upright goal
        assert not any("goal placement" in m for m in messages)
        np.testing.assert_allclose(res.T_world_b_goal, res.T_world_a_goal @ task.T_A_B, atol=1e-12)


class _CountingPlanner:
    """A motion planner that counts its queries and passes them on."""

    def __init__(self, inner) -> None:
        self.inner, self.calls = inner, 0

    def plan(self, *args, **kwargs):
        self.calls += 1
        return self.inner.plan(*args, **kwargs)

    def __getattr__(self, name: str):
        return getattr(self.inner, name)


@pytest.mark.slow
def test_keyframe_sequences_failing_at_a_straight_line_never_reach_the_motion_planner() -> None:
    """Notched block, seed 0: one of A's carries ends in collision. Lines and ends are checked before any free
    motion is planned, so the motion planner sees only the free motions of the plan that succeeds. (Before the
    goal screen checked the hand closed at the grasp width, session 14, eight and then one of B's sequences also
    ended in an insertion whose fingers met A; the screen now removes those grasps before any sequence.)"""
    with random_scene("configs/parts/set1/notched_block.yaml", 0) as (robot, problem):
        motion = _CountingPlanner(registry.create("motion_planners", "trrt", {}, seed=0))
        messages: list[str] = []
        res = registry.create("assembly_planners", "regrasp", {}, seed=0).plan(
            problem, robot, motion, progress=messages.append
        )
        assert res.success, res.reason
        assert any("goal in collision" in m for m in messages)
        free = [
            s
            for s in res.plan.segments
            if s.trajectory is not None
            and (s.label.startswith(("move to pre-grasp", "carry")) or s.label.endswith("home"))
        ]
        assert motion.calls == len(free)


@pytest.mark.slow
def test_the_opened_hand_retreats_clear_of_the_part_it_let_go_of() -> None:
    """Ring on post, seed 36: the right hand's opened finger, backing off from the post base it has just put down,
    went 0.6 mm into it (the re-check found it); the retreat is checked with the part placed as an obstacle."""
    with random_scene("configs/parts/set2/ring_on_post.yaml", 36) as (robot, problem):
        motion = registry.create("motion_planners", "trrt", {}, seed=36)
        res = registry.create("assembly_planners", "regrasp", {}, seed=36).plan(problem, robot, motion)
        assert res.success, res.reason
        a, b = problem.part_a, problem.part_b
        chk = robot.verify_plan(
            res.plan, {a.name: (a, problem.T_world_a), b.name: (b, problem.T_world_b)}, problem.table, resolution=0.005
        )
        assert chk.ok, chk.summary()
