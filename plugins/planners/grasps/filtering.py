"""Grasps at a part pose: the paper's ``g_s = IK(g_s') ∩ CD(g_s', world)``.

Each grasp (part frame) is moved to the part's pose ``T_world_part``; then, in
this order, the hand (palm and fingers open for the approach) is checked
against the world's obstacles with python-fcl, IK is solved on each arm (first
success wins) and the arm at that solution is checked in a planning scene
(the robot's own collision model; the robot is never changed). The verdict
keeps the reason of a rejection: which collision pair, or that no arm reached
the pose. The grasped part itself is not an obstacle (the hand touches it by
design); pass the table and other parts.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from asmteach.core.hand_geometry import MeshCollider, hand_boxes
from asmteach.core.interfaces import Obstacle, Robot
from asmteach.core.models import Grasp
from asmteach.core.robot import PlanningScene

__all__ = ["STATUS_COLORS", "GraspVerdict", "filter_grasps_at_pose", "render_verdicts"]

Status = Literal["feasible", "ik_infeasible", "collision"]

STATUS_COLORS: dict[str, str] = {"feasible": "#2ca02c", "ik_infeasible": "#1f77b4", "collision": "#d62728"}
"""The paper's colours: green feasible, blue IK-infeasible, red colliding."""


@dataclass
class GraspVerdict:
    """Outcome of one grasp at a pose (world frame, metres, radians)."""

    grasp: Grasp
    status: Status
    T_world_tcp: np.ndarray
    arm: str | None = None
    q: np.ndarray | None = None
    collision: tuple[str, str] | None = None
    """``(robot or hand body, obstacle)`` of the first contact found, for ``collision``."""
    reason: str = ""
    ik_failures: dict[str, str] = field(default_factory=dict)

    @property
    def feasible(self) -> bool:
        return self.status == "feasible"


def filter_grasps_at_pose(
    grasps: Sequence[Grasp],
    T_world_part: np.ndarray,
    robot: Robot,
    obstacles: Sequence[Obstacle],
    *,
    arms: Sequence[str] | None = None,
    clearance: float = 0.002,
    approach_sweep: float = 0.0,
    q_seed: dict[str, np.ndarray] | None = None,
    scene: PlanningScene | None = None,
) -> list[GraspVerdict]:
    """Verdict per grasp, in the order given.

    Parameters
    ----------
    grasps : grasps in the part frame.
    T_world_part : ``(4, 4)`` pose of the part.
    robot : kinematics (IK) and the hand.
    obstacles : the world (table, other parts) as meshes at world poses.
    arms : arms to try, in order; default ``robot.arms``.
    clearance : per-side finger clearance of the open hand (metres).
    approach_sweep : also check the hand swept back along its approach by this much (metres).
    q_seed : IK seed per arm; default the arm's home configuration.
    scene : where the arm is checked for collision (the other arms where it has them), with its obstacles
        replaced by ``obstacles``; default ``robot.scene``.
    """
    T_world_part = np.asarray(T_world_part, dtype=float)
    scene = (robot.scene if scene is None else scene).with_obstacles(list(obstacles))
    collider = MeshCollider({o.name: (o.mesh, np.asarray(o.T_world, dtype=float)) for o in obstacles})
    hand = robot.hand
    arm_list = list(arms) if arms is not None else list(robot.arms)
    out: list[GraspVerdict] = []
    for g in grasps:
        T = T_world_part @ g.T_part_tcp
        opening = min(g.width + 2.0 * clearance, hand.max_width)
        hit = collider.first_contact(hand_boxes(hand, opening, sweep=approach_sweep), T)
        if hit is not None:
            pair = (f"hand/{hit[0]}", hit[1])
            out.append(GraspVerdict(g, "collision", T, collision=pair, reason=f"{pair[0]} hits {pair[1]}"))
            continue
        verdict = _ik_and_arm(robot, scene, g, T, arm_list, q_seed or {})
        out.append(verdict)
    return out


def _ik_and_arm(
    robot: Robot, scene: PlanningScene, g: Grasp, T: np.ndarray, arms: list[str], q_seed: dict[str, np.ndarray]
) -> GraspVerdict:
    failures: dict[str, str] = {}
    colliding: GraspVerdict | None = None
    for arm in arms:
        seed = q_seed.get(arm, robot.home(arm))
        ik = robot.ik(arm, T, q_seed=seed)
        if not ik.success or ik.q is None:
            failures[arm] = ik.reason or "no IK solution"
            continue
        q = np.asarray(ik.q, dtype=float)
        if bool(scene.in_collision(arm, q[None, :])[0]):
            pairs = scene.collision_report(arm, q)
            pair = pairs[0] if pairs else (f"{arm} arm", "world")
            if colliding is None:
                colliding = GraspVerdict(
                    g, "collision", T, arm=arm, q=q, collision=pair, reason=f"{pair[0]} hits {pair[1]}"
                )
            continue
        return GraspVerdict(g, "feasible", T, arm=arm, q=q, reason="", ik_failures=failures)
    if colliding is not None:
        colliding.ik_failures = failures
        return colliding
    reason = "; ".join(f"{a}: {r}" for a, r in failures.items()) or "no arm"
    return GraspVerdict(g, "ik_infeasible", T, reason=f"IK failed ({reason})", ik_failures=failures)


def render_verdicts(
    verdicts: Sequence[GraspVerdict],
    part_mesh_world: trimesh.Trimesh,
    path: str | Path,
    *,
    obstacles: Sequence[Obstacle] = (),
    title: str = "",
) -> Path:
    """PNG of the grasps at the pose in the paper's colours (see :data:`STATUS_COLORS`)."""
    from asmteach.plugins.planners.grasps.render import draw_scene

    segments = [(v.T_world_tcp, v.grasp.width, STATUS_COLORS[v.status]) for v in verdicts]
    counts = {s: sum(v.status == s for v in verdicts) for s in STATUS_COLORS}
    legend = {f"{s.replace('_', ' ')} ({counts[s]})": c for s, c in STATUS_COLORS.items()}
    return draw_scene(part_mesh_world, segments, path, obstacles=obstacles, title=title, legend=legend)
