"""Keyframe motions check collisions in the planning scene they are given, never in the robot's own.

The fixture is made in code: a two-joint point robot whose configuration
``(x, y)`` (radians, read as metres in the plane z = 0) collides with an
obstacle when it lies inside the obstacle's bounding box, and a wall across
the straight line from start to goal.
"""

import itertools
from collections.abc import Sequence

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry, registry
from asmteach.core.interfaces import IKResult, Obstacle, Robot
from asmteach.core.models import HandSpec, PartSpec, Primitive, SolidSpec
from asmteach.core.parts import build_part
from asmteach.core.robot import PlanningScene
from asmteach.plugins.planners.regrasp.motions import (
    Checker,
    MotionFailure,
    cleared_scene,
    first_hit,
    free_motion,
    straight_line,
    world_scene,
)
from asmteach.plugins.planners.regrasp.settings import AssemblySettings


class BoxScene(PlanningScene):
    """The point ``q`` against the obstacles' bounding boxes (their x, y extent)."""

    def _distance(self, qs: np.ndarray) -> np.ndarray:
        qs = np.atleast_2d(np.asarray(qs, float))
        out = np.full(len(qs), np.inf)
        for ob in self.obstacles:
            lo, hi = trimesh.Trimesh(ob.mesh.vertices, ob.mesh.faces).apply_transform(ob.T_world).bounds
            d = np.abs(qs - 0.5 * (lo + hi)[:2]) - 0.5 * (hi - lo)[:2]
            out = np.minimum(out, np.linalg.norm(np.maximum(d, 0.0), axis=1) + np.minimum(d.max(axis=1), 0.0))
        return out

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        return self._distance(qs) <= 0.0

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        return np.minimum(self._distance(qs), upto)

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        return [[("point", o.name) for o in self.obstacles] if hit else [] for hit in self.in_collision(arm, qs)]


class PlanarPoint(Robot):
    """Two joints in [-1, 1]; FK puts the TCP at ``(x, y, 0)`` pointing down."""

    def __init__(self) -> None:
        super().__init__({})
        self.scene = BoxScene({"main": self.home("main")})

    arms = property(lambda self: ["main"])
    hand = property(lambda self: HandSpec(name="none", max_width=0.05))

    def joint_names(self, arm: str) -> list[str]:
        return ["x", "y"]

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        return np.full(2, -1.0), np.full(2, 1.0)

    def home(self, arm: str) -> np.ndarray:
        return np.zeros(2)

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        return geometry.from_rpy(np.pi, 0, 0, t=[q[0], q[1], 0.0])

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        return IKResult(True, np.asarray(T_world_tcp[:2, 3], float), 0.0, 0.0)


def wall() -> Obstacle:
    """A wall at x = 0 from y = -0.5 to 0.5 (0.1 thick)."""
    return Obstacle("wall", trimesh.creation.box(extents=[0.1, 1.0, 0.1]), np.eye(4))


def table() -> Obstacle:
    return Obstacle("table", trimesh.creation.box(extents=[2.0, 2.0, 0.05]), geometry.from_rpy(0, 0, 0, t=[0, 0, -0.1]))


START, GOAL = np.array([-0.5, 0.0]), np.array([0.5, 0.0])


def test_world_scene_leaves_the_table_to_the_robot_and_the_old_scene_as_it_was() -> None:
    robot = PlanarPoint()
    before = robot.scene
    walled = world_scene(before, [table(), wall()])
    assert [o.name for o in walled.obstacles] == ["wall"] and before.obstacles == ()
    part = build_part(PartSpec(name="p", solid=SolidSpec(add=[Primitive(shape="box", size=[0.01] * 3)])))
    holding = walled.with_attached("main", part, np.eye(4), width=0.01)
    cleared = cleared_scene(holding, [wall()])
    assert not cleared.attached and "main" in holding.attached
    assert robot.scene is before


def test_checks_answer_for_their_own_scene_whichever_was_asked_last() -> None:
    robot = PlanarPoint()
    free, walled = robot.scene, world_scene(robot.scene, [wall()])
    at_wall = np.array([0.0, 0.2])
    open_check, wall_check = Checker(free, "main"), Checker(walled, "main")
    assert not wall_check.valid(at_wall) and open_check.valid(at_wall)
    assert not wall_check.valid(at_wall)  # asked again after the other scene
    np.testing.assert_array_equal(wall_check.valid.batch(np.stack([START, at_wall])), [True, False])
    line = np.linspace(START, GOAL, 11)
    assert first_hit(walled, "main", line) == 5 and first_hit(free, "main", line) is None


@pytest.mark.parametrize("walled", [False, True])
def test_trrt_plans_around_the_wall_of_the_scene_it_is_given(walled: bool) -> None:
    robot = PlanarPoint()
    scene = world_scene(robot.scene, [wall()]) if walled else robot.scene
    clearances: list[float] = []
    settings = AssemblySettings(motion_time_limit=10.0)
    path = free_motion(
        robot,
        scene,
        registry.create("motion_planners", "trrt", {}, seed=3),
        "main",
        START,
        GOAL,
        settings,
        ("a", "b"),
        "test",
        clearances,
    )
    np.testing.assert_allclose(path[[0, -1]], [START, GOAL])
    dense = np.concatenate([np.linspace(p, q, 50) for p, q in itertools.pairwise(path)])
    through_wall = BoxScene({}, [wall()]).in_collision("main", dense).any()
    assert through_wall != walled  # the free scene's path is the straight line, through where the wall would be
    assert clearances[0] > 0.0
    assert robot.scene.obstacles == ()


def test_a_straight_path_through_the_scenes_wall_is_refused_naming_the_pair() -> None:
    robot = PlanarPoint()
    walled = world_scene(robot.scene, [wall()])
    T_goal = robot.fk("main", GOAL)
    settings = AssemblySettings()
    with pytest.raises(MotionFailure, match=r"collision at step \d+ \(point/wall\)"):
        straight_line(robot, walled, "main", START, T_goal, settings, ("a", "b"), "line")
    path = straight_line(robot, robot.scene, "main", START, T_goal, settings, ("a", "b"), "line")
    np.testing.assert_allclose(path[-1], GOAL, atol=1e-12)


@pytest.mark.parametrize("seed", [3, 4, 5])
def test_a_free_motion_keeps_the_transit_clearance_where_its_ends_allow(seed: int) -> None:
    robot = PlanarPoint()
    walled = world_scene(robot.scene, [wall()])

    def least_clearance(wanted: float, start: np.ndarray = START) -> float:
        path = free_motion(
            robot,
            walled,
            registry.create("motion_planners", "trrt", {}, seed=seed),
            "main",
            start,
            GOAL,
            AssemblySettings(motion_time_limit=10.0, transit_clearance=wanted),
            ("a", "b"),
            "test",
            [],
        )
        dense = np.concatenate([np.linspace(p, q, 200) for p, q in itertools.pairwise(path)])
        return float(walled.clearance("main", dense).min())

    # the ends are 0.45 from the wall; around its end (y = +-0.5) there is room up to the joint limit (1.0).
    # The floor holds at the states the planner checks; between them a path may dip by a share of its step
    assert least_clearance(0.1) >= 0.09
    assert least_clearance(0.0) < 0.1  # without it the shortcut hugs the wall's corner
    # an end closer than the floor (0.05 from the wall): the motion keeps what that end has, with slack
    assert least_clearance(0.1, np.array([-0.1, 0.0])) >= 0.9 * 0.9 * 0.05
