"""The robot contracts of asmteach.core.robot: PlanningScene is a value; Robot's scene methods never touch a world."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
import trimesh

from asmteach.core.errors import UserError
from asmteach.core.interfaces import IKResult, Obstacle, PartModel, Robot
from asmteach.core.models import HandSpec, PartSpec, Primitive, SolidSpec
from asmteach.core.robot import PlanningScene, RobotModel, World


class BallScene(PlanningScene):
    """A point TCP at ``q`` (x, y, z) colliding with obstacles' bounding boxes; the held part is a ball of radius
    ``width``. Counts its queries."""

    queries = 0

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        BallScene.queries += 1
        return self.clearance(arm, qs) <= 0.0

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        qs = np.atleast_2d(qs)
        held = self.attached.get(arm)
        r = 0.0 if held is None or held.width is None else held.width
        out = np.full(len(qs), float(upto))
        for ob in self.obstacles:
            lo, hi = ob.mesh.bounds + ob.T_world[:3, 3]
            gap = np.linalg.norm(np.maximum(0.0, np.maximum(lo - qs, qs - hi)), axis=1) - r
            out = np.minimum(out, gap)
        return out


class PointRobot(Robot):
    """One arm whose configuration is the TCP position (metres), within a 1 m cube."""

    def __init__(self) -> None:
        super().__init__({})
        self.scene = BallScene({"main": self.home("main")})

    arms = property(lambda self: ["main"])
    hand = property(lambda self: HandSpec())

    def joint_names(self, arm: str) -> list[str]:
        return ["x", "y", "z"]

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        return np.full(3, -1.0), np.full(3, 1.0)

    def home(self, arm: str) -> np.ndarray:
        return np.array([0.0, 0.0, 0.5])

    def fk(self, arm: str, q: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, 3] = q
        return T

    def ik(self, arm: str, T_world_tcp: np.ndarray, q_seed: np.ndarray | None = None) -> IKResult:
        return IKResult(True, np.asarray(T_world_tcp, float)[:3, 3].copy(), 0.0, 0.0)


def _cube(name: str = "cube") -> Obstacle:
    T = np.eye(4)
    T[:3, 3] = (0.5, 0.0, 0.5)
    return Obstacle(name, trimesh.creation.box((0.1, 0.1, 0.1)), T)


def _part() -> PartModel:
    spec = PartSpec(name="ball", solid=SolidSpec(add=[Primitive(shape="box", size=[0.02, 0.02, 0.02])]))
    return PartModel(spec=spec, mesh=trimesh.creation.box((0.02, 0.02, 0.02)), mass=0.01, center_of_mass=np.zeros(3))


def test_with_methods_return_new_scenes_and_leave_the_old_one_alone() -> None:
    empty = BallScene({"main": np.zeros(3)})
    near = np.array([[0.42, 0.0, 0.5]])  # 3 cm from the cube's face
    walled = empty.with_obstacles([_cube()])
    holding = walled.with_attached("main", _part(), np.eye(4), width=0.05)
    moved = holding.with_configuration("main", near[0])
    assert type(moved) is BallScene
    assert empty.obstacles == () and not empty.attached and np.array_equal(empty.configuration["main"], np.zeros(3))
    assert empty.table is None  # the default: a scene without a table of its own
    assert walled.attached == {} and holding.attached["main"].width == 0.05
    np.testing.assert_array_equal(moved.configuration["main"], near[0])
    assert not walled.in_collision("main", near)[0] and holding.in_collision("main", near)[0]
    assert holding.with_attached("main", None).attached == {}
    assert not empty.in_collision("main", near)[0]


def test_a_scene_cannot_be_changed_in_place() -> None:
    q = np.array([0.1, 0.2, 0.3])
    scene = BallScene({"main": q})
    q[0] = 9.0  # the caller's array is copied
    assert scene.configuration["main"][0] == pytest.approx(0.1)
    with pytest.raises(ValueError, match="read-only"):
        scene.configuration["main"][0] = 1.0
    with pytest.raises(TypeError):
        scene.configuration["main"] = q  # type: ignore[index]
    with pytest.raises(ValueError, match="T_tcp_part is required"):
        scene.with_attached("main", _part())


def test_robot_scene_setters_replace_the_value_and_never_need_a_world() -> None:
    robot = PointRobot()
    assert not isinstance(robot, World) and isinstance(robot, RobotModel)
    before = robot.scene
    robot.set_obstacles([_cube()])
    robot.set_configuration("main", [0.42, 0.0, 0.5])
    robot.attach("main", _part(), np.eye(4), width=0.05)
    assert before.obstacles == () and np.array_equal(before.configuration["main"], robot.home("main"))
    assert robot.in_collision("main", robot.current("main")[None])[0]
    assert robot.clearance("main", np.array([[0.0, 0.0, 0.5]]))[0] == pytest.approx(0.45 - 0.05)
    assert robot.collision_report("main", robot.current("main")) == []  # the default names no pairs
    with pytest.raises(UserError, match="outside its joint limits"):
        robot.set_configuration("main", [2.0, 0.0, 0.0])


def test_world_members_are_declared_and_the_optional_ones_say_so() -> None:
    declared = World.__abstractmethods__
    assert declared == {"reset_world", "current", "execute", "grip", "part_pose", "sense_depth"}
    assert RobotModel.__abstractmethods__ == {"arms", "hand", "joint_names", "joint_limits", "home", "fk", "ik"}
    assert PlanningScene.__abstractmethods__ == {"in_collision", "clearance"}

    class Blind(World):
        reset_world = current = execute = grip = part_pose = sense_depth = None  # type: ignore[assignment]

    with pytest.raises(NotImplementedError, match="colour camera"):
        Blind().sense_rgb()
    with pytest.raises(NotImplementedError, match="camera pose"):
        Blind().camera_pose()


def test_a_run_refuses_a_robot_without_a_world_in_one_line(toy_config, tmp_path, capsys) -> None:
    from asmteach.core.cli import main

    assert main(["run", str(toy_config), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'toy_robot' plans but has no world to run in" in err[0], err
    assert not (tmp_path / "out" / "report.json").exists()  # refused before the run starts
