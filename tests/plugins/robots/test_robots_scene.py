"""The arm robot's planning scene: values the planner may keep; planning never moves the simulator."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core.interfaces import Obstacle
from asmteach.core.models import TablePlane
from asmteach.plugins.robots.nextage.robot import NextagePyBullet


@pytest.fixture(scope="module")
def robot():
    r = NextagePyBullet({"ik": {"max_starts": 4}}, seed=0)
    yield r
    r.close()


def _wall() -> Obstacle:
    T = np.eye(4)
    T[:3, 3] = (0.3, 0.2, 0.15)
    return Obstacle("wall", trimesh.creation.box((0.3, 0.02, 0.3)), T)


def test_old_scenes_answer_as_they_were_after_newer_ones_were_queried(robot: NextagePyBullet) -> None:
    lo, hi = robot.joint_limits("left")
    qs = np.random.default_rng(3).uniform(lo, hi, size=(200, 6))
    empty = robot.scene.with_obstacles([])
    walled = empty.with_obstacles([_wall()])
    hits_empty, hits_walled = empty.in_collision("left", qs), walled.in_collision("left", qs)
    assert hits_walled.sum() > hits_empty.sum()  # the wall is in the way of some configurations
    # querying one then the other brings the shared checker back and forth
    np.testing.assert_array_equal(empty.in_collision("left", qs), hits_empty)
    np.testing.assert_array_equal(walled.in_collision("left", qs), hits_walled)
    np.testing.assert_allclose(empty.clearance("left", qs[:20], upto=0.1), empty.clearance("left", qs[:20], upto=0.1))


def test_the_other_arm_is_where_the_scene_puts_it(robot: NextagePyBullet) -> None:
    """The right arm reaching across in front of the left one blocks some left-arm configurations only in the
    scene that has it there."""
    lo, hi = robot.joint_limits("left")
    qs = np.random.default_rng(5).uniform(lo, hi, size=(300, 6))
    home = robot.scene.with_obstacles([])
    ik = robot.ik("right", robot.fk("left", robot.home("left")))
    across = home.with_configuration("right", ik.q if ik.success else (lo + hi) / 2.0)
    assert not np.array_equal(home.in_collision("left", qs), across.in_collision("left", qs))
    np.testing.assert_array_equal(home.configuration["right"], robot.home("right"))


def test_the_scene_names_the_table_the_checker_uses(robot: NextagePyBullet) -> None:
    table = robot.scene.table
    assert table is not None and table.name == "table"
    top = table.T_world[2, 3] + table.mesh.bounds[1, 2]
    assert top == pytest.approx(robot.settings.table_height)
    np.testing.assert_allclose(table.mesh.extents[:2], robot.settings.table_size)
    # the checker's table is there: the TCP 1 cm into the table top collides, 5 cm above does not
    down = robot.fk("left", robot.home("left"))
    for depth, hit in ((0.05, False), (-0.01, True)):
        T = down.copy()
        T[:3, 3] = [0.35, 0.25, robot.settings.table_height + depth]
        res = robot.ik("left", T)
        assert res.success and robot.scene.in_collision("left", res.q[None])[0] == hit


def test_planning_never_moves_the_simulator(robot: NextagePyBullet) -> None:
    from asmteach.core.models import PartSpec, Primitive, SolidSpec
    from asmteach.core.parts import build_part

    spec = PartSpec(
        name="cube", solid=SolidSpec(add=[Primitive(shape="box", size=[0.03, 0.03, 0.03], pose={"xyz": [0, 0, 0.015]})])
    )
    cube = build_part(spec)
    T = np.eye(4)
    T[:3, 3] = (0.4, 0.1, 0.0)
    robot.reset_world(TablePlane(height=0.0), {"cube": (cube, T)})
    sim_q = robot.sim.get_joints(robot.joint_names("left"))
    away = robot.home("left") + 0.3
    robot.set_configuration("left", away)  # the scene moves, the world does not
    robot.attach("left", cube, np.eye(4), width=0.03)
    assert robot.in_collision("left", away[None]).shape == (1,)
    np.testing.assert_array_equal(robot.sim.get_joints(robot.joint_names("left")), sim_q)
    np.testing.assert_allclose(robot.current("left"), robot.home("left"))
    np.testing.assert_allclose(robot.scene.configuration["left"], away)
    robot.reset_world(TablePlane(height=0.0), {"cube": (cube, T)})
    assert robot.scene.attached == {} and np.allclose(robot.scene.configuration["left"], robot.home("left"))
