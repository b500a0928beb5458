"""From a keyframe path of the regrasp graph to joint paths: realising one part's transfer.

For each hold (pick at one slot, carry to the next): the other arms go home,
a free motion to the pre-grasp pose, a straight approach, close, a straight
lift, a free carry to above the place slot, a straight place or insertion,
release, a straight retreat; at the end every arm goes home. Two passes:
first every keyframe (IK) and straight line (Cartesian IK and collision),
each free motion's end checked for collision and left as a query; then the
motion planner's queries, in order. A failure raises :class:`.motions.MotionFailure`
naming the graph edge (and, when no path through it can succeed, the node)
to ban before the graph is searched again.

Collisions are checked on :class:`~asmteach.core.robot.PlanningScene` values
made from the one given with its ``with_*`` methods; the robot only lends its
kinematics and is never changed.

Frames: ``T_world_*`` 4x4 in metres; joint paths in radians.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import networkx as nx
import numpy as np

from asmteach.core.failures import FailureKind
from asmteach.core.interfaces import MotionPlanner, Obstacle, PartModel, Robot
from asmteach.core.models import Grasp, GripperEvent
from asmteach.core.robot import PlanningScene
from asmteach.plugins.planners.regrasp.feasibility import approach_offset, variant_tcp
from asmteach.plugins.planners.regrasp.graph import GOAL, START, KeyframeSearch, PoseSlot
from asmteach.plugins.planners.regrasp.motions import MotionFailure, free_motion, straight_line, world_scene
from asmteach.plugins.planners.regrasp.settings import AssemblySettings

__all__ = ["PlaceGoal", "Step", "realise_keyframes"]


@dataclass(frozen=True)
class PlaceGoal:
    """Where a part must end: its pose, how it comes in, and what it may touch there."""

    slot: PoseSlot
    approach: np.ndarray
    """World vector (metres) from the placed pose back to where the straight final move starts."""
    touch: tuple[str, ...] = ("table",)
    """Obstacles the held part may touch on the final move (intended contact)."""
    on_table: bool = True
    """True when the part rests on the table at the goal (grasps then must come from above)."""
    alternatives: tuple[PoseSlot, ...] = ()
    """Other goal slots as good as :attr:`slot`: a symmetric part's equivalent poses (the same solid in the same
    place, each a goal layer of its own, so a grasp need only be feasible at one of them)."""

    @property
    def slots(self) -> tuple[PoseSlot, ...]:
        """Every goal slot, :attr:`slot` first."""
        return (self.slot, *self.alternatives)


@dataclass
class Step:
    """One step of a plan: an untimed joint path of one arm, or a gripper event."""

    label: str
    kind: Literal["path", "gripper"]
    arm: str
    path: np.ndarray | None = None
    event: GripperEvent | None = None


@dataclass(frozen=True)
class _Scene:
    """What collision checking sees while one free motion is planned: the obstacles beyond ``world``,
    the part held (arm, part, ``T_tcp_part``, jaw width in metres) and every arm's configuration (radians)."""

    extra: tuple[Obstacle, ...]
    held: tuple[str, PartModel, np.ndarray, float] | None
    q: dict[str, np.ndarray]

    def apply(self, scene: PlanningScene, world: Sequence[Obstacle], arms: Sequence[str]) -> PlanningScene:
        """``scene`` made to hold this: ``world`` and :attr:`extra`, :attr:`held` in its hand, every other
        hand of ``arms`` empty, the arms at :attr:`q`."""
        scene = world_scene(scene, world, *self.extra)
        for arm in arms:
            if self.held is not None and self.held[0] == arm:
                scene = scene.with_attached(arm, self.held[1], self.held[2], width=self.held[3])
            else:
                scene = scene.with_attached(arm, None)
        for arm, q in self.q.items():
            scene = scene.with_configuration(arm, q)
        return scene


@dataclass(frozen=True)
class _FreeMotion:
    """A free motion left for the motion planner: ``steps[step]`` gets its path."""

    step: int
    arm: str
    q_a: np.ndarray
    q_b: np.ndarray
    edge: tuple[Any, Any]
    what: str
    scene: _Scene


def realise_keyframes(
    robot: Robot,
    scene: PlanningScene,
    planner: MotionPlanner,
    part: PartModel,
    grasps: dict[int, Grasp],
    G: nx.Graph,
    search: KeyframeSearch,
    goal: PlaceGoal,
    world: Sequence[Obstacle],
    q_now: dict[str, np.ndarray],
    settings: AssemblySettings,
) -> tuple[list[Step], dict[str, np.ndarray], list[dict[str, Any]], float, PlanningScene]:
    """Keyframes to paths, the arms' configurations at the end, the keyframes, the least clearance (m) of
    the free motions and the scene it ends with; raises :class:`MotionFailure` with the edge to ban and
    the scene reached (:attr:`MotionFailure.scene`).

    ``scene`` is the planning scene as the transfer starts; ``world`` holds
    the table and the other obstacles, not this part.

    Two passes: first every keyframe (IK) and straight line (Cartesian IK and
    collision), each free motion's end checked for collision and left as a
    query; then the motion planner's queries, in order. A keyframe sequence
    that fails at a straight line (an insertion whose fingers meet the other
    part, say) then costs milliseconds, not the free motions planned before it.
    """
    nodes = search.nodes
    steps: list[Step] = []
    keyframes: list[dict[str, Any]] = []
    queries: list[_FreeMotion] = []
    q_cur = {k: np.asarray(v, float).copy() for k, v in q_now.items()}
    q_set: dict[str, np.ndarray] = {}  # the arms' configurations set in the scene so far
    extra: tuple[Obstacle, ...] = ()
    held: tuple[str, PartModel, np.ndarray, float] | None = None
    T_part = G.nodes[nodes[0]]["slot"].T_world_part  # where the part lies now

    def put(arm: str, q: np.ndarray) -> None:
        nonlocal scene
        scene = scene.with_configuration(arm, q)
        q_set[arm] = np.asarray(q, float).copy()

    def hold(arm: str, held: tuple[str, PartModel, np.ndarray, float] | None) -> None:
        """``arm``'s hand in the scene: holding ``held`` (arm, part, ``T_tcp_part``, width) or empty."""
        nonlocal scene
        if held is None:
            scene = scene.with_attached(arm, None)
        else:
            scene = scene.with_attached(arm, held[1], held[2], width=held[3])

    def obstacles(*extra: Obstacle) -> None:
        nonlocal scene
        scene = world_scene(scene, world, *extra)

    def free(arm: str, q_a: np.ndarray, q_b: np.ndarray, edge: tuple[Any, Any], what: str, label: str) -> None:
        """Leave a free motion for the second pass; its end must be collision-free in the scene now."""
        if bool(scene.in_collision(arm, np.asarray(q_b, float)[None, :])[0]):
            # No motion to it can succeed, whatever edge leads there: ban the node.
            raise MotionFailure(edge, f"{what}: {FailureKind.GOAL_INVALID.value}", node=edge[1])
        queries.append(
            _FreeMotion(
                len(steps),
                arm,
                np.asarray(q_a, float),
                np.asarray(q_b, float),
                edge,
                what,
                _Scene(extra, held, dict(q_set)),
            )
        )
        steps.append(Step(label, "path", arm))

    try:
        i = 0
        while i < len(nodes):
            # one hold: pick at nodes[i], carry (transfer edges) to nodes[j]
            j = i
            while j + 1 < len(nodes) and G.edges[nodes[j], nodes[j + 1]]["kind"] == "transfer":
                j += 1
            if j == i:  # a lone node followed by a transit edge: the regrasp happens at this slot
                i += 1
                continue
            pick, place = nodes[i], nodes[j]
            into = START if i == 0 else nodes[i - 1]
            arm, vid = pick[2], pick[1]
            slot_pick, slot_place = G.nodes[pick]["slot"], G.nodes[place]["slot"]
            final = place[0] in {g.name for g in goal.slots} and j == len(nodes) - 1

            # 0. the other arms go home (the grasp graph was screened with them there) and stay put
            hold(arm, None)
            held = None
            extra = (Obstacle(part.name, part.mesh, T_part),)
            obstacles(*extra)
            for a in robot.arms:
                put(a, q_cur[a])
            for other in robot.arms:
                if other != arm and not np.allclose(q_cur[other], robot.home(other)):
                    free(
                        other,
                        q_cur[other],
                        robot.home(other),
                        (into, pick),
                        f"{other} arm home before the {arm} arm picks",
                        f"{other} arm home",
                    )
                    q_cur[other] = robot.home(other)
                    put(other, q_cur[other])
            # 1. free motion to the pre-grasp pose; the part is an obstacle where it lies
            T_grasp = slot_pick.T_world_part @ variant_tcp(grasps, vid)
            pre = robot.ik(arm, approach_offset(T_grasp, settings.pregrasp_distance), q_seed=G.nodes[pick]["q"])
            if not pre.success or pre.q is None or getattr(pre, "flipped", False):
                raise MotionFailure((into, pick), f"pre-grasp pose at {pick[0]} has no IK solution", node=pick)
            free(
                arm,
                q_cur[arm],
                pre.q,
                (into, pick),
                f"motion to the pre-grasp at {pick[0]}",
                f"move to pre-grasp {vid} of {part.name} at {pick[0]}",
            )
            keyframes.append({"name": f"pregrasp_{pick[0]}", "arm": arm, "q": np.asarray(pre.q).tolist()})
            # 2. straight approach without the part as obstacle (the fingers go around it)
            extra = ()
            obstacles()
            down = straight_line(
                robot, scene, arm, pre.q, T_grasp, settings, (into, pick), f"approach at {pick[0]}", node=pick
            )
            steps.append(Step(f"approach grasp {vid}", "path", arm, down))
            keyframes.append({"name": f"grasp_{pick[0]}", "arm": arm, "q": down[-1].tolist()})
            width = grasps[vid // 2].width
            steps.append(
                Step(
                    f"close on {part.name}",
                    "gripper",
                    arm,
                    event=GripperEvent(arm=arm, action="close", width=width, attach=part.name),
                )
            )
            T_tcp_now = robot.fk(arm, down[-1])
            held = (arm, part, np.linalg.inv(T_tcp_now) @ slot_pick.T_world_part, width)
            hold(arm, held)
            # 3. lift straight up (the part leaves the table it touched)
            T_lift = T_tcp_now.copy()
            T_lift[2, 3] += settings.lift
            up = straight_line(
                robot,
                scene,
                arm,
                down[-1],
                T_lift,
                settings,
                (pick, nodes[i + 1]),
                f"lift at {pick[0]}",
                ignore=("table",),
                node=pick,
            )
            steps.append(Step(f"lift {part.name}", "path", arm, up))
            # 4. carry to the start of the final straight move
            T_place_tcp = slot_place.T_world_part @ variant_tcp(grasps, vid)
            approach = goal.approach if final else np.array([0.0, 0.0, settings.lift])
            T_above = T_place_tcp.copy()
            T_above[:3, 3] += approach
            above = robot.ik(arm, T_above, q_seed=G.nodes[place]["q"])
            if not above.success or above.q is None or getattr(above, "flipped", False):
                raise MotionFailure((pick, nodes[i + 1]), f"no IK solution above {place[0]}", node=place)
            free(
                arm,
                up[-1],
                above.q,
                (pick, nodes[i + 1]),
                f"carrying {part.name} to {place[0]}",
                f"carry {part.name} to {place[0]}",
            )
            keyframes.append(
                {
                    "name": f"{'preassembly' if final and not goal.on_table else 'above'}_{place[0]}",
                    "arm": arm,
                    "q": np.asarray(above.q).tolist(),
                }
            )
            # 5. final straight move: place on the table, or insert along v_a
            touch = goal.touch if final else ("table",)
            T_release = T_place_tcp.copy()
            if goal.on_table or not final:
                T_release[2, 3] += settings.release_gap
            last = straight_line(
                robot,
                scene,
                arm,
                above.q,
                T_release,
                settings,
                (pick, nodes[i + 1]),
                f"{'insertion' if final and not goal.on_table else 'placing'} at {place[0]}",
                ignore=touch,
                node=place,
            )
            steps.append(
                Step(
                    f"{'insert' if final and not goal.on_table else 'place'} {part.name} at {place[0]}",
                    "path",
                    arm,
                    last,
                )
            )
            keyframes.append({"name": f"placed_{place[0]}", "arm": arm, "q": last[-1].tolist()})
            # 6. release and back off along the approach axis
            steps.append(Step(f"release {part.name}", "gripper", arm, event=GripperEvent(arm=arm, action="open")))
            hold(arm, None)
            held = None
            T_part = slot_place.T_world_part
            # the opened fingers back off past the part they let go of, now an obstacle where it was placed
            extra = (Obstacle(part.name, part.mesh, T_part),)
            obstacles(*extra)
            back = straight_line(
                robot,
                scene,
                arm,
                last[-1],
                approach_offset(robot.fk(arm, last[-1]), settings.pregrasp_distance),
                settings,
                (pick, nodes[i + 1]),
                f"retreat at {place[0]}",
                node=place,
            )
            steps.append(Step("retreat", "path", arm, back))
            q_cur[arm] = back[-1]
            i = j + 1  # the edge after a hold is a transit (regrasp at that slot) or the end
        # 7. home, with the part now an obstacle where it was placed
        extra = (Obstacle(part.name, part.mesh, T_part),)
        obstacles(*extra)
        for arm in robot.arms:
            home = robot.home(arm)
            for other in robot.arms:
                put(other, q_cur[other])
            if np.allclose(q_cur[arm], home):
                continue
            free(arm, q_cur[arm], home, (nodes[-1], GOAL), f"{arm} arm back home", f"{arm} arm home")
            q_cur[arm] = home
        # the plan ends with every arm where its last motion leaves it (home), not where the loop last set it
        end = _Scene(extra, None, {arm: q.copy() for arm, q in q_cur.items()})
        # second pass: the motion planner, in the order the robot moves
        clearances: list[float] = []
        for m in queries:
            scene = m.scene.apply(scene, world, robot.arms)
            steps[m.step].path = free_motion(
                robot, scene, planner, m.arm, m.q_a, m.q_b, settings, m.edge, m.what, clearances
            )
        scene = end.apply(scene, world, robot.arms)
    except MotionFailure as fail:
        fail.scene = scene  # where the checks had got to: the next search starts from there
        raise
    return steps, q_cur, keyframes, (min(clearances) if clearances else float("nan")), scene
