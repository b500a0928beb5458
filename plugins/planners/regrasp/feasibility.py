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

At a goal slot the part arrives held and is let go there, so the hand is
also checked closed on it (each finger's inner face half the grasp width
from the TCP, as the robot's fingers are on an insertion): a finger beside a
short pin's insertion end clears the face around the hole with the jaw
pre-shaped 2 mm wider a side, and meets it closed.

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
from asmteach.core.hand_geometry import MeshCollider, hand_boxes
from asmteach.core.interfaces import Obstacle, Robot
from asmteach.core.models import Grasp, HandSpec
from asmteach.core.robot import PlanningScene
from asmteach.plugins.planners.regrasp.graph import GraspFeasibility, PoseSlot, Rejected, Rejection

__all__ = [
    "FLIP_Z",
    "ScreenSettings",
    "approach_offset",
    "evaluate_slot",
    "evaluate_slots",
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
) -> tuple[list[Grasp], dict[int, Rejection]]:
    """Grasps passing the cheap tests at ``slot``, and why the others fail (keyed by grasp id).

    At a goal slot (``slot.layer == "goal"``) the hand is also checked closed at the grasp width
    (module docstring); a rejection for that says ``closed`` in its detail.
    """
    passed: list[Grasp] = []
    rejected: dict[int, Rejection] = {}
    closed_check = slot.layer == "goal"
    for g in grasps:
        T = slot.T_world_part @ g.T_part_tcp
        if on_table and -T[2, 2] < settings.min_down:
            rejected[g.id] = Rejection(Rejected.NOT_FROM_ABOVE)
            continue
        opening = min(g.width + 2.0 * settings.finger_clearance, hand.max_width)
        hit = collider.first_contact(hand_boxes(hand, opening, sweep=settings.pregrasp_distance), T)
        closed = ""
        if hit is None and closed_check:
            hit, closed = collider.first_contact(hand_boxes(hand, min(g.width, hand.max_width)), T), " closed"
        if hit is not None:
            rejected[g.id] = Rejection(
                Rejected.HAND_COLLISION, f"hand/{hit[0]}{closed} with {hit[1]}", hit[1] == "table"
            )
            continue
        passed.append(g)
    return passed, rejected


def evaluate_slot(
    robot: Robot,
    scene: PlanningScene,
    slot: PoseSlot,
    screened: tuple[list[Grasp], dict[int, str]],
    arms: Sequence[str],
    *,
    settings: ScreenSettings,
    prefer: Iterable[int] = (),
    shared: dict[int, int] | None = None,
    seeds: dict[str, np.ndarray] | None = None,
) -> GraspFeasibility:
    """:func:`evaluate_slots` of one slot."""
    return evaluate_slots(
        robot,
        scene,
        [slot],
        [screened],
        arms,
        settings=settings,
        prefer=prefer,
        shared=None if shared is None else [shared],
        seeds=seeds,
    )[0]


def evaluate_slots(
    robot: Robot,
    scene: PlanningScene,
    slots: Sequence[PoseSlot],
    screened: Sequence[tuple[list[Grasp], dict[int, str]]],
    arms: Sequence[str],
    *,
    settings: ScreenSettings,
    prefer: Iterable[int] = (),
    shared: Sequence[dict[int, int]] | None = None,
    seeds: dict[str, np.ndarray] | None = None,
) -> list[GraspFeasibility]:
    """IK and collision of the best screened grasps (:func:`screen_slot`) with the part at each slot.

    ``robot`` solves the IK; collisions are checked in ``scene``, whose
    obstacles must hold the world of these slots (the other part; the robot
    knows the table) and whose hands must be empty; the part
    itself is not an obstacle, since the fingers touch it by design. Every arm is
    tried and each that works is kept. ``prefer`` lists grasp ids (not
    variants) to try before the others; ``shared[k]`` counts, per grasp id, the
    other slots where it passes the screen (grasps usable at more slots are
    tried first, since only shared grasps make edges). ``seeds`` holds one IK
    seed per arm. All targets of an arm go to :meth:`Robot.ik_many` at once.
    Solutions are keyed by ``(variant_id, arm)``; rejections are a
    :class:`~.graph.Rejection` each, keyed the same way with ``arm = ""`` for
    grasps screened out before IK.
    """
    first = set(prefer)
    out: list[GraspFeasibility] = []
    jobs: list[tuple[int, Grasp]] = []  # (slot index, grasp) solved by IK
    for k, (slot, (passed, screened_out)) in enumerate(zip(slots, screened, strict=True)):
        counts = shared[k] if shared is not None else {}
        order = sorted(passed, key=lambda g: (g.id not in first, -counts.get(g.id, 0), -g.score))
        rejected: dict[tuple[int, str], Rejection] = {
            (variant_id(gid, False), ""): r for gid, r in screened_out.items()
        }
        for g in order[settings.max_candidates :]:
            rejected[(variant_id(g.id, False), "")] = Rejection(Rejected.CANDIDATE_CAP)
        out.append(GraspFeasibility(slot=slot, solutions={}, rejected=rejected))
        jobs += [(k, g) for g in order[: settings.max_candidates]]
    if not jobs:
        return out
    T_tcp = np.stack([slots[k].T_world_part @ g.T_part_tcp for k, g in jobs])
    for arm in arms:
        seed = None if seeds is None else seeds.get(arm)
        res = robot.ik_many(arm, T_tcp, seed)
        keys = [(variant_id(g.id, bool(r.flipped)), arm) for (_, g), r in zip(jobs, res, strict=True)]
        good = []
        for i, r in enumerate(res):
            if r.success and r.q is not None:
                good.append(i)
            else:
                out[jobs[i][0]].rejected[keys[i]] = Rejection(Rejected.NO_IK, r.reason or "")
        good = _collision_free(scene, arm, good, [res[i].q for i in good], out, jobs, keys, pregrasp=False)
        if not good:
            continue
        T_eff = np.stack([T_tcp[i] @ FLIP_Z if res[i].flipped else T_tcp[i] for i in good])
        pre_T = np.stack([approach_offset(T, settings.pregrasp_distance) for T in T_eff])
        pre = robot.ik_many(arm, pre_T, np.stack([res[i].q for i in good]))
        reach = []
        for i, p in zip(good, pre, strict=True):
            if not p.success or p.q is None or p.flipped:
                out[jobs[i][0]].rejected[keys[i]] = Rejection(Rejected.PREGRASP_NO_IK)
            else:
                reach.append((i, p.q))
        clear = _collision_free(
            scene, arm, [i for i, _ in reach], [q for _, q in reach], out, jobs, keys, pregrasp=True
        )
        for i in clear:
            out[jobs[i][0]].solutions[keys[i]] = np.asarray(res[i].q, float)
    return out


def _collision_free(
    scene: PlanningScene,
    arm: str,
    idx: list[int],
    qs: list[np.ndarray],
    out: list[GraspFeasibility],
    jobs: list[tuple[int, Grasp]],
    keys: list[tuple[int, str]],
    pregrasp: bool,
) -> list[int]:
    """The entries of ``idx`` whose configuration is free in ``scene``; the others get a collision rejection (with the
    colliding pairs at the grasp itself, which also tell whether the table is one of them)."""
    if not idx:
        return []
    hits = np.asarray(scene.in_collision(arm, np.asarray(qs, float)), bool)
    bad = [k for k, hit in enumerate(hits) if hit]
    if pregrasp:
        rejections = [Rejection(Rejected.PREGRASP_COLLISION)] * len(bad)
    else:
        reports = scene.collision_reports(arm, np.asarray([qs[k] for k in bad], float)) if bad else []
        rejections = [
            Rejection(
                Rejected.ARM_COLLISION,
                ", ".join(f"{a}/{b}" for a, b in pairs) or "unknown pair",
                any("table" in (a, b) for a, b in pairs),
            )
            for pairs in reports
        ]
    for k, rejection in zip(bad, rejections, strict=True):
        out[jobs[idx[k]][0]].rejected[keys[idx[k]]] = rejection
    return [i for i, hit in zip(idx, hits, strict=True) if not hit]
