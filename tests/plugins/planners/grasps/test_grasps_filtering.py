"""Filtering grasps at a pose with a robot double, and with the real Nextage plugin."""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.hand_geometry import hand_boxes
from asmteach.core.interfaces import Obstacle
from asmteach.core.models import Grasp
from asmteach.plugins.planners.grasps.filtering import STATUS_COLORS, filter_grasps_at_pose, render_verdicts
from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner


def _hand_points(hand, g: Grasp, T_world_tcp: np.ndarray) -> np.ndarray:
    """Points filling the open hand's boxes (11 per axis), world frame."""
    u = np.stack(np.meshgrid(*[np.linspace(-0.5, 0.5, 11)] * 3, indexing="ij"), -1).reshape(-1, 3)
    pts = [b.center + u * b.size for b in hand_boxes(hand, min(g.width + 0.004, hand.max_width))]
    return np.concatenate(pts) @ T_world_tcp[:3, :3].T + T_world_tcp[:3, 3]


def _box_obstacle(name: str, size, centre) -> Obstacle:
    return Obstacle(name, trimesh.creation.box(extents=size), geometry.from_rotation(np.eye(3), centre))


def test_verdicts_match_geometry(block, hand, point_arm, table, tmp_path) -> None:
    """A block on a 30 mm pedestal 0.15 m above the table: every status occurs, each for the right reason."""
    grasps = AntipodalGraspPlanner({"cache": False}).plan(block, hand)
    T_world_part = geometry.from_rpy(0, 0, 0.3, t=[0.25, 0.05, 0.15])
    pedestal = _box_obstacle("pedestal", [0.03, 0.03, 0.15], [0.25, 0.05, 0.075])
    obstacles = [table, pedestal]
    before = point_arm.scene
    verdicts = filter_grasps_at_pose(grasps, T_world_part, point_arm, obstacles)
    assert point_arm.scene is before and before.obstacles == ()  # checked in a scene of its own
    assert len(verdicts) == len(grasps)
    counts = {s: sum(v.status == s for v in verdicts) for s in STATUS_COLORS}
    assert all(n > 0 for n in counts.values()), counts
    boxes = [(o.name, o.mesh.bounds + o.T_world[:3, 3]) for o in obstacles]
    checked = 0
    for v in verdicts:
        T = T_world_part @ v.grasp.T_part_tcp
        np.testing.assert_allclose(v.T_world_tcp, T, atol=1e-12)
        pts = _hand_points(hand, v.grasp, T)
        deep = [n for n, (lo, hi) in boxes if np.any(np.all((pts > lo + 1e-3) & (pts < hi - 1e-3), axis=1))]
        near = [n for n, (lo, hi) in boxes if np.any(np.all((pts > lo - 2e-3) & (pts < hi + 2e-3), axis=1))]
        if deep:
            assert v.status == "collision" and v.collision[0].startswith("hand/") and v.collision[1] in deep
            checked += 1
        elif not near:
            up = T[2, 2] > 0.3
            wrist = T[:3, 3] - 0.12 * T[:3, 2]
            wrist_hits = any(np.linalg.norm(wrist - np.clip(wrist, lo, hi)) < 0.03 for _, (lo, hi) in boxes)
            expected = "ik_infeasible" if up else ("collision" if wrist_hits else "feasible")
            assert v.status == expected, (v.grasp.id, v.status, v.reason)
            if v.status == "feasible":
                assert v.arm == "left"
                np.testing.assert_allclose(point_arm.fk("left", v.q), T, atol=1e-9)
            if v.status == "collision":
                assert v.collision[0] == "wrist"
            checked += 1
    assert checked > 0.8 * len(verdicts)
    png = render_verdicts(verdicts, block.mesh.copy().apply_transform(T_world_part), tmp_path / "v.png",
                          obstacles=obstacles, title="block on a pedestal")  # fmt: skip
    assert png.stat().st_size > 10_000


def test_out_of_reach_is_ik_infeasible(block, hand, point_arm, table) -> None:
    grasps = AntipodalGraspPlanner({"cache": False, "max_grasps": 30}).plan(block, hand)
    far = geometry.from_rotation(np.eye(3), [2.0, 0.0, 0.0])
    verdicts = filter_grasps_at_pose(grasps, far, point_arm, [])
    assert {v.status for v in verdicts} == {"ik_infeasible"}
    assert all("out of reach" in v.reason for v in verdicts)


def test_with_the_nextage_robot(hand, make_box, table) -> None:
    """The real robot plugin: IK solutions of feasible grasps reproduce the TCP pose."""
    from asmteach.core import registry
    from asmteach.core.hand_geometry import MeshCollider

    with registry.create("robots", "nextage_pybullet") as robot:
        part = make_box([0.040, 0.040, 0.040], name="cube")
        grasps = AntipodalGraspPlanner({"cache": False, "max_grasps": 40}).plan(part, robot.hand)
        T_world_part = geometry.from_rotation(np.eye(3), [0.40, 0.10, 0.0])
        verdicts = filter_grasps_at_pose(grasps, T_world_part, robot, [table])
        statuses = {v.status for v in verdicts}
        assert "feasible" in statuses and "collision" in statuses
        collider = MeshCollider({"table": (table.mesh, table.T_world)})
        for v in verdicts:
            if v.status == "feasible":
                T = robot.fk(v.arm, v.q)
                assert geometry.translation_distance(T, v.T_world_tcp) < 2e-3
                assert geometry.rotation_distance(T, v.T_world_tcp) < np.radians(1.0)
                assert not collider.collides(hand_boxes(robot.hand, v.grasp.width + 0.004), v.T_world_tcp)
