"""Which grasps the robot can use with the part at a given pose.

The paper's ``g_s = IK(g_s') ∩ CD(g_s', table)``: each grasp (part frame) is
moved to the part's world pose, solved by IK, and checked for collision of
arm and hand with the world (the table and the other part). A grasp also
needs its pre-grasp pose (the TCP backed off along its approach axis) to be
reachable, or the hand could not get there.

IK is the expensive step (tens of milliseconds when it fails), so grasps are
screened first with cheap tests and only the best ``max_candidates`` survivors
are solved: the open hand swept back along its approach must not touch the
world (python-fcl), the approach must come from above for a part resting on
the table, and the TCP must lie within the arm's reach. Grasps feasible at
other slots are tried first so that layers share grasps (transfer edges).

A parallel jaw is symmetric: IK may succeed only for the TCP turned 180 deg
about its approach axis. Such a solution is a different *grasp variant*;
variant ``2 * grasp.id + flipped`` names it in the graph so that transfer
edges only join identical hand poses relative to the part.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from asmteach.core.geometry import compose, from_rotation
from asmteach.core.interfaces import Obstacle, Robot
from asmteach.core.models import Grasp, HandSpec
from asmteach.plugins.planners.grasps.hand_geometry import MeshCollider, hand_boxes
from asmteach.plugins.planners.regrasp.graph import GraspFeasibility, PoseSlot

__all__ = [
    "FLIP_Z",
    "ScreenSettings",
    "approach_offset",
    "evaluate_slot",
    "screen_slot",
    "variant_id",
    "variant_tcp",
    "world_collider",
]

FLIP_Z = np.diag([-1.0, -1.0, 1.0, 1.0])
"""The TCP turned 180 deg about its own z (the other finger order)."""


@dataclass(frozen=True)
class ScreenSettings:
    """Cheap tests before IK (metres; ``min_down`` is a cosine)."""

    max_candidates: int = 16
    """Grasps solved by IK per slot, after screening (best first)."""
    min_down: float = 0.5
    """For parts on the table: the approach axis (TCP +z) must point down at least this much
    (``-z_tcp . up``; 0.5 = within 60 deg of vertical)."""
    pregrasp_distance: float = 0.06
    """Stand-off of the pre-grasp pose along the TCP -z, and the hand sweep checked (metres)."""
    finger_clearance: float = 0.002
    """Per-side opening beyond the grasp width while approaching (metres)."""


def variant_id(grasp_id: int, flipped: bool) -> int:
    """Graph id of a grasp or of its jaw-flipped twin."""
    return 2 * int(grasp_id) + int(bool(flipped))


def variant_tcp(grasps: dict[int, Grasp], vid: int) -> np.ndarray:
    """``T_part_tcp`` of grasp variant ``vid``."""
    T = grasps[vid // 2].T_part_tcp
    return T @ FLIP_Z if vid % 2 else T


def approach_offset(T_world_tcp: np.ndarray, distance: float) -> np.ndarray:
    """The TCP backed off by ``distance`` metres along its own -z (out of the grasp)."""
    return compose(T_world_tcp, from_rotation(np.eye(3), [0.0, 0.0, -distance]))


def world_collider(world: Sequence[Obstacle]) -> MeshCollider:
    """The world's obstacles (table included) for the open-hand screen; build once per world."""
    return MeshCollider({o.name: (o.mesh, np.asarray(o.T_world, float)) for o in world})


def screen_slot(
    slot: PoseSlot,
    grasps: Sequence[Grasp],
    collider: MeshCollider,
    hand: HandSpec,
    settings: ScreenSettings,
    on_table: bool = True,
) -> tuple[list[Grasp], dict[int, str]]:
    """Grasps passing the cheap tests at ``slot``, and why the others fail (keyed by grasp id)."""
    passed: list[Grasp] = []
    rejected: dict[int, str] = {}
    for g in grasps:
        T = slot.T_world_part @ g.T_part_tcp
        if on_table and -T[2, 2] < settings.min_down:
            rejected[g.id] = "screen: approach not from above"
            continue
        opening = min(g.width + 2.0 * settings.finger_clearance, hand.max_width)
        hit = collider.first_contact(hand_boxes(hand, opening, sweep=settings.pregrasp_distance), T)
        if hit is not None:
            rejected[g.id] = f"collision: hand/{hit[0]} with {hit[1]}"
            continue
        passed.append(g)
    return passed, rejected


def evaluate_slot(
    robot: Robot,
    slot: PoseSlot,
    screened: tuple[list[Grasp], dict[int, str]],
    arms: Sequence[str],
    *,
    settings: ScreenSettings,
    prefer: Iterable[int] = (),
    shared: dict[int, int] | None = None,
    seeds: dict[str, np.ndarray] | None = None,
) -> GraspFeasibility:
    """IK and collision of the best screened grasps (:func:`screen_slot`) with the part at ``slot``.

    The robot's obstacles must already hold the world for this slot (the
    other part; the robot knows the table) and nothing may be held; the part
    itself is not an obstacle, since the fingers touch it by design. Every arm is
    tried (nearest first) and each that works is kept. ``prefer`` lists grasp
    ids (not variants) to try before the others; ``shared`` counts, per grasp
    id, the other slots where it passes the screen (grasps usable at more
    slots are tried first, since only shared grasps make edges). Solutions are keyed by
    ``(variant_id, arm)``; rejections keep their reason, keyed the same way
    with ``arm = ""`` for grasps screened out before IK.
    """
    passed, screened_out = list(screened[0]), screened[1]
    rejected: dict[tuple[int, str], str] = {(variant_id(gid, False), ""): r for gid, r in screened_out.items()}
    first = set(prefer)
    counts = shared or {}
    passed.sort(key=lambda g: (g.id not in first, -counts.get(g.id, 0), -g.score))
    for g in passed[settings.max_candidates :]:
        rejected[(variant_id(g.id, False), "")] = "screen: beyond the candidate cap"
    solutions: dict[tuple[int, str], np.ndarray] = {}
    centre = slot.T_world_part[:3, 3]
    order = sorted(arms, key=lambda a: float(np.linalg.norm(robot.fk(a, robot.home(a))[:3, 3] - centre)))
    for g in passed[: settings.max_candidates]:
        T_tcp = slot.T_world_part @ g.T_part_tcp
        # every arm: a transfer edge needs the same grasp *and* arm at both slots
        for arm in order:
            seed = None if seeds is None else seeds.get(arm)
            res = robot.ik(arm, T_tcp, q_seed=seed)
            flipped = bool(getattr(res, "flipped", False))
            key = (variant_id(g.id, flipped), arm)
            if not res.success or res.q is None:
                rejected[key] = f"ik: {res.reason or 'no solution'}"
                continue
            q = np.asarray(res.q, float)
            if bool(robot.in_collision(arm, q[None, :])[0]):
                pairs = robot.collision_report(arm, q)
                rejected[key] = "collision: " + (", ".join(f"{a}/{b}" for a, b in pairs) or "unknown pair")
                continue
            T_eff = T_tcp @ FLIP_Z if flipped else T_tcp
            pre = robot.ik(arm, approach_offset(T_eff, settings.pregrasp_distance), q_seed=q)
            if not pre.success or pre.q is None or bool(getattr(pre, "flipped", False)):
                rejected[key] = "ik: pre-grasp pose unreachable"
                continue
            if bool(robot.in_collision(arm, np.asarray(pre.q, float)[None, :])[0]):
                rejected[key] = "collision: at the pre-grasp pose"
                continue
            solutions[key] = q
            if seeds is not None:
                seeds[arm] = q
    return GraspFeasibility(slot=slot, solutions=solutions, rejected=rejected)
