"""The PyBullet plan re-checker: replays a plan in its own DIRECT client and measures every contact.

What counts as a collision, the touch rules and the result models are in
:mod:`asmteach.core.arm.plan_check`; :func:`recheck_plan` is the entry point.
Frames: world, z up, metres; joint values in radians.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmteach.core import geometry
from asmteach.core.arm.link_spheres import LinkSpheres
from asmteach.core.arm.plan_check import (
    OTHER_PARTS,
    TOUCH_RULES,
    CheckedArm,
    PlanCheck,
    PlanCollision,
    densify_by_reach,
)
from asmteach.core.arm.sim import PyBulletWorld
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.models import GripperEvent, Plan

__all__ = ["DROP_GAP", "PlanChecker", "recheck_plan"]


# ---------------------------------------------------------------- the checker
DROP_GAP = 0.003
"""Metres: a released part whose lowest point is at most this far above the table is put down on it."""


@dataclass
class _Held:
    """A part welded to an arm's TCP: its PyBullet base (centre-of-mass) frame in the TCP frame."""

    part: str
    pos: list[float]
    quat: list[float]


class PlanChecker:
    """Replays plans in one PyBullet world and reports contacts (see the module docstring).

    Parameters
    ----------
    world : a PyBullet world of its own (not the one executing plans); its parts are replaced
        by :meth:`check`.
    arms : the arms by name.
    table_center, table_size, table_height : the table (x, y centre and extent; world z of the top), metres.
    skip_pairs : robot link-name pairs never checked (SRDF-disabled); linked pairs are skipped anyway.
    tolerance : penetration (metres) tolerated before a contact is a collision.
    query_distance : pairs farther apart than this (metres) are not measured; caps ``min_distance_m``.
    touch : what a held part may touch, by the first word of the segment label.
    """

    def __init__(
        self,
        world: PyBulletWorld,
        arms: Mapping[str, CheckedArm],
        *,
        table_center: Sequence[float],
        table_size: Sequence[float],
        table_height: float,
        skip_pairs: Sequence[tuple[str, str]] | set[frozenset[str]] = (),
        tolerance: float = 0.0005,
        query_distance: float = 0.02,
        touch: Mapping[str, Sequence[str]] = TOUCH_RULES,
    ) -> None:
        if tolerance < 0.0 or query_distance <= 0.0:
            raise UserError(
                f"plan check: tolerance ({tolerance}) must be >= 0 and query_distance ({query_distance}) > 0 metres"
            )
        self.world, self.p = world, world.p
        self.arms = dict(arms)
        self.table = (tuple(table_center), tuple(table_size), float(table_height))
        self.tolerance, self.query_distance = float(tolerance), float(query_distance)
        self.touch = {k: tuple(v) for k, v in touch.items()}
        self.robot = world.robot
        self.name_of = {i: n for n, i in world.link_index.items()}
        for arm, spec in self.arms.items():
            world.joint_ids(list(spec.joints) + list(spec.finger_joints))  # UserError on unknown names
            for ln in (spec.tcp_link, *spec.hand_links):
                if ln not in world.link_index:
                    raise UserError(f"plan check: arm {arm!r} names link {ln!r}, which the URDF lacks")
        self.hand_idx = {a: {world.link_index[ln] for ln in s.hand_links} for a, s in self.arms.items()}
        self.tcp_idx = {a: world.link_index[s.tcp_link] for a, s in self.arms.items()}
        for link in range(-1, self.p.getNumJoints(self.robot)):
            self.p.changeDynamics(self.robot, link, collisionMargin=0.0)  # geometric distances
        self.spheres = LinkSpheres(self.p, self.robot, self.name_of, {frozenset(p) for p in skip_pairs})

    def joint_reach(self, joint_ids: Sequence[int], held: Mapping[str, _Held]) -> np.ndarray:
        """``R_j`` (metres) of each moving joint, held parts included: see :meth:`LinkSpheres.joint_reach`."""
        return self.spheres.joint_reach(
            joint_ids, {self.tcp_idx[a]: self.world.parts[h.part][0] for a, h in held.items()}
        )

    # ------------------------------------------------------------ world state
    def _follow(self, arm: str, h: _Held) -> None:
        """Move a held part with its arm's TCP (PyBullet's own transform composition)."""
        st = self.p.getLinkState(self.robot, self.tcp_idx[arm], computeForwardKinematics=True)
        pos, quat = self.p.multiplyTransforms(st[4], st[5], h.pos, h.quat)
        self.p.resetBasePositionAndOrientation(self.world.parts[h.part][0], pos, quat)

    def _grab(self, arm: str, part: str) -> _Held:
        """Weld ``part`` to ``arm``'s TCP where both are now."""
        st = self.p.getLinkState(self.robot, self.tcp_idx[arm], computeForwardKinematics=True)
        T_world_tcp = geometry.from_quat(st[5], st[4])
        pos, quat = self.p.getBasePositionAndOrientation(self.world.parts[part][0])
        T_tcp_com = np.linalg.solve(T_world_tcp, geometry.from_quat(quat, pos))
        return _Held(part, T_tcp_com[:3, 3].tolist(), geometry.to_quat(T_tcp_com).tolist())

    def _drop_onto_table(self, part: str) -> None:
        """A part let go just above the table falls onto it: lower it by the gap when that is under
        :data:`DROP_GAP` (planners release parts a millimetre up so as not to push them)."""
        body = self.world.parts[part][0]
        near = self.p.getClosestPoints(body, self.world.table_id, DROP_GAP)
        if not near:
            return
        gap = min(c[8] for c in near)
        if gap > 0.0:
            pos, quat = self.p.getBasePositionAndOrientation(body)
            self.p.resetBasePositionAndOrientation(body, (pos[0], pos[1], pos[2] - gap), quat)

    def _set_q(self, ids: Sequence[int], q: np.ndarray) -> None:
        reset = self.p.resetJointState
        for j, v in zip(ids, q, strict=True):
            reset(self.robot, j, float(v), 0.0)

    # ------------------------------------------------------------ one configuration
    def _measure(
        self,
        holder: str | None,
        touch: tuple[str, ...],
        held: Mapping[str, _Held],
        moved: Mapping[str, str],
        pairs: np.ndarray | slice = slice(None),
    ) -> list[tuple[str, str, float]]:
        """Signed distances (metres) of every checked, not allowed pair within the query distance.

        ``holder`` is the arm of the segment; ``touch`` what its held part may touch; ``moved``
        maps held part name -> holding arm; ``pairs`` selects the robot self pairs to measure.
        """
        d, robot = self.query_distance, self.robot
        closest = self.p.getClosestPoints  # bound once: BulletClient builds a new partial per attribute access
        out: list[tuple[str, str, float]] = []
        table = self.world.table_id
        for c in closest(robot, table, d):
            out.append((self.name_of[c[3]], "table", c[8]))
        for name, (body, _) in self.world.parts.items():
            arm = moved.get(name)
            hand = self.hand_idx[arm] if arm is not None else ()
            for c in closest(robot, body, d):
                if c[3] not in hand:
                    out.append((self.name_of[c[3]], name, c[8]))
        names = list(self.world.parts)
        for arm, h in held.items():
            body = self.world.parts[h.part][0]
            allowed = touch if arm == holder else ()
            if "table" not in allowed:
                out += [(h.part, "table", c[8]) for c in closest(body, table, d)]
            for other in names:
                if other == h.part or OTHER_PARTS in allowed or other in allowed:
                    continue
                if other in moved and names.index(other) < names.index(h.part):
                    continue  # two held parts: measured once
                out += [(h.part, other, c[8]) for c in closest(body, self.world.parts[other][0], d)]
        # robot self pairs: bounding-sphere prune of shape pairs (numpy), then Bullet on the link pairs left
        sp = self.spheres
        cen = sp.centres()
        sa, sb = sp.pair_sa[pairs], sp.pair_sb[pairs]
        near = np.linalg.norm(cen[sa] - cen[sb], axis=1) - sp.pair_r[pairs] < d
        todo = {(int(a), int(b)) for a, b in zip(sp.sphere_link[sa[near]], sp.sphere_link[sb[near]], strict=True)}
        for a, b in sorted(todo):
            out += [(self.name_of[a], self.name_of[b], c[8]) for c in closest(robot, robot, d, a, b)]
        return out

    # ------------------------------------------------------------ replay
    def check(
        self,
        plan: Plan,
        parts: Mapping[str, tuple[PartModel, np.ndarray]],
        home: Mapping[str, np.ndarray],
        *,
        resolution: float = 0.005,
    ) -> PlanCheck:
        """Replay ``plan`` from ``home`` with ``parts`` at their start poses ``T_world_part``; see the module doc."""
        t0 = time.perf_counter()
        if not resolution > 0.0:
            raise UserError(f"plan check: resolution must be > 0 metres, got {resolution}")
        center, size, height = self.table
        self.world.reset_world(center, size, height, dict(parts))
        for body, _ in self.world.parts.values():
            self.p.changeDynamics(body, -1, collisionMargin=0.0)
        for arm, spec in self.arms.items():
            if arm not in home:
                raise UserError(f"plan check: no home configuration for arm {arm!r}; give one per arm")
            self._set_q(self.world.joint_ids(list(spec.joints)), np.asarray(home[arm], dtype=float))
            self._set_q(self.world.joint_ids(list(spec.finger_joints)), np.asarray(spec.open_values))
        held: dict[str, _Held] = {}
        hits: dict[tuple[int, str, str], PlanCollision] = {}
        warnings: list[str] = []
        best = (self.query_distance, None)
        count = 0

        def record(k: int, label: str, t: float, found: list[tuple[str, str, float]]) -> None:
            nonlocal best
            for a, b, dist in found:
                if dist < best[0]:
                    best = (dist, f"segment {k} ({label}): {a} / {b}")
                if dist < -self.tolerance:
                    key = (k, a, b)
                    if key not in hits:
                        hits[key] = PlanCollision(
                            segment=k,
                            label=label,
                            time_s=round(float(t), 4),
                            a=a,
                            b=b,
                            penetration_m=-dist,
                            configurations=0,
                        )
                    c = hits[key]
                    c.penetration_m = max(c.penetration_m, -dist)
                    c.configurations += 1

        for k, seg in enumerate(plan.segments):
            touch = self.touch.get(seg.label.split(" ", 1)[0], ())
            if seg.gripper is not None:
                self._gripper(seg.gripper, parts, held, k)
                moved = {h.part: a for a, h in held.items()}
                record(k, seg.label, 0.0, self._measure(seg.gripper.arm, touch, held, moved))
                count += 1
            if seg.trajectory is None:
                continue
            tr = seg.trajectory
            if tr.arm not in self.arms:
                raise UserError(
                    f"plan check: segment {k} ({seg.label}) moves arm {tr.arm!r}; the robot has {sorted(self.arms)}"
                )
            ids = self.world.joint_ids(list(tr.joint_names))
            q = np.atleast_2d(np.asarray(tr.positions, dtype=float))
            gap = float(np.max(np.abs(q[0] - self.world.get_joints(list(tr.joint_names)))))
            if gap > 1e-4:
                warnings.append(f"segment {k} ({seg.label}) starts {gap:.4f} rad from where its joints are")
            times, dense = densify_by_reach(
                np.asarray(tr.times, dtype=float), q, self.joint_reach(ids, held), resolution
            )
            moved = {h.part: a for a, h in held.items()}
            # self pairs that cannot change within this segment are measured at its first configuration only
            sp = self.spheres
            moving = np.unique(np.concatenate([sp.descendants(j) for j in ids]))
            live = np.nonzero(
                np.isin(sp.sphere_link[sp.pair_sa], moving) | np.isin(sp.sphere_link[sp.pair_sb], moving)
            )[0]
            for i, (t, qi) in enumerate(zip(times, dense, strict=True)):
                self._set_q(ids, qi)
                for arm, h in held.items():  # a moving chest joint may move the idle arm's part too
                    self._follow(arm, h)
                found = self._measure(tr.arm, touch, held, moved, slice(None) if i == 0 else live)
                record(k, seg.label, float(t), found)
            count += len(dense)
        collisions = sorted(hits.values(), key=lambda c: (c.segment, -c.penetration_m))
        return PlanCheck(
            ok=not collisions,
            resolution_m=float(resolution),
            tolerance_m=self.tolerance,
            n_configurations_checked=count,
            min_distance_m=float(best[0]),
            closest=best[1],
            collisions=collisions,
            warnings=warnings,
            seconds=round(time.perf_counter() - t0, 3),
        )

    def _gripper(
        self, ev: GripperEvent, parts: Mapping[str, tuple[PartModel, np.ndarray]], held: dict[str, _Held], k: int
    ) -> None:
        if ev.arm not in self.arms:
            raise UserError(f"plan check: segment {k} grips with arm {ev.arm!r}; the robot has {sorted(self.arms)}")
        spec = self.arms[ev.arm]
        fingers = self.world.joint_ids(list(spec.finger_joints))
        if ev.action == "open":
            self._set_q(fingers, np.asarray(spec.open_values))
            h = held.pop(ev.arm, None)  # the part stays where it is, an obstacle from now on
            if h is not None:
                self._drop_onto_table(h.part)
            return
        half = 0.0 if ev.width is None else 0.5 * float(ev.width)
        self._set_q(fingers, np.minimum(np.asarray(spec.open_values), half))
        if ev.attach is not None:
            if ev.attach not in parts:
                raise UserError(
                    f"plan check: segment {k} attaches {ev.attach!r}, which is not among the parts {sorted(parts)}"
                )
            held[ev.arm] = self._grab(ev.arm, ev.attach)


def recheck_plan(
    urdf: str | Path,
    T_world_base: np.ndarray,
    plan: Plan,
    parts: Mapping[str, tuple[PartModel, np.ndarray]],
    arms: Mapping[str, CheckedArm],
    home: Mapping[str, np.ndarray],
    *,
    table_center: Sequence[float],
    table_size: Sequence[float],
    table_height: float,
    skip_pairs: Sequence[tuple[str, str]] | set[frozenset[str]] = (),
    resolution: float = 0.005,
    tolerance: float = 0.0005,
    query_distance: float = 0.02,
) -> PlanCheck:
    """Re-check every configuration of ``plan`` in a fresh PyBullet DIRECT client (closed afterwards).

    ``parts`` maps each part's name to its model and start pose ``T_world_part``; ``home`` gives each
    arm's start configuration (radians). See :class:`PlanChecker` for the other parameters and the
    module docstring for what counts as a collision.
    """
    world = PyBulletWorld(Path(urdf), np.asarray(T_world_base, dtype=float))
    try:
        checker = PlanChecker(
            world,
            arms,
            table_center=table_center,
            table_size=table_size,
            table_height=table_height,
            skip_pairs=skip_pairs,
            tolerance=tolerance,
            query_distance=query_distance,
        )
        return checker.check(plan, parts, home, resolution=resolution)
    finally:
        world.close()
