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
import pybullet

from asmteach.core import geometry
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


def _quat_matrices(q: np.ndarray) -> np.ndarray:
    """``(n, 4)`` unit quaternions (x, y, z, w) -> ``(n, 3, 3)`` rotation matrices."""
    x, y, z, w = q.T
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1),
        ],
        axis=1,
    )


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
        n = self.p.getNumJoints(self.robot)
        self.parent = np.array([self.p.getJointInfo(self.robot, j)[16] for j in range(n)], dtype=int)
        self.joint_type = np.array([self.p.getJointInfo(self.robot, j)[2] for j in range(n)], dtype=int)
        self.n_links = n
        for link in range(-1, n):
            self.p.changeDynamics(self.robot, link, collisionMargin=0.0)  # geometric distances
        self._link_radii()
        self._self_pairs({frozenset(p) for p in skip_pairs})

    # ------------------------------------------------------------ robot geometry
    def _link_radii(self) -> None:
        """Bounding spheres of every collision shape, in its link's centre-of-mass frame (metres).

        ``self.sphere_link`` / ``sphere_center`` / ``sphere_radius`` per shape; ``self.radius`` per link
        (index link + 1, base first; -1 = no geometry): radius about the centre of mass enclosing them all.
        """
        p = self.p
        links, centers, radii = [], [], []
        for link in range(-1, self.n_links):
            for i, sh in enumerate(p.getCollisionShapeData(self.robot, link)):
                kind, dims, pos = sh[2], np.asarray(sh[3], dtype=float), np.asarray(sh[5], dtype=float)
                if kind == pybullet.GEOM_BOX:
                    c, r = pos, 0.5 * float(np.linalg.norm(dims))
                elif kind == pybullet.GEOM_SPHERE:
                    c, r = pos, float(dims[0])
                elif kind in (pybullet.GEOM_CYLINDER, pybullet.GEOM_CAPSULE):
                    c, r = (
                        pos,
                        float(np.hypot(dims[1], 0.5 * dims[0])) + (dims[1] if kind == pybullet.GEOM_CAPSULE else 0.0),
                    )
                else:  # a mesh (URDF cylinders become convex hulls): its vertices, in the same frame
                    v = np.asarray(p.getMeshData(self.robot, link, collisionShapeIndex=i)[1], dtype=float)
                    if len(v) == 0:
                        raise UserError(
                            f"plan check: PyBullet gives no vertices for collision shape {i} of link "
                            f"{self.name_of[link]!r}; use boxes, cylinders or meshes in the URDF"
                        )
                    c = 0.5 * (v.min(axis=0) + v.max(axis=0))
                    r = float(np.max(np.linalg.norm(v - c, axis=1)))
                links.append(link)
                centers.append(c)
                radii.append(r)
        self.sphere_link = np.array(links, dtype=int)
        self.sphere_center = np.array(centers, dtype=float).reshape(-1, 3)
        self.sphere_radius = np.array(radii, dtype=float)
        self.radius = np.full(self.n_links + 1, -1.0)
        for link, c, r in zip(links, centers, radii, strict=True):
            self.radius[link + 1] = max(self.radius[link + 1], float(np.linalg.norm(c)) + r)

    def _self_pairs(self, skip: set[frozenset[str]]) -> None:
        """Shape pairs of the robot that are checked: other links, not joined by a joint, not skipped."""
        la, lb = np.triu_indices(len(self.sphere_link), k=1)
        A, B = self.sphere_link[la], self.sphere_link[lb]
        keep = np.ones(len(la), dtype=bool)
        for k, (a, b) in enumerate(zip(A.tolist(), B.tolist(), strict=True)):
            linked = a == b or (b >= 0 and self.parent[b] == a) or (a >= 0 and self.parent[a] == b)
            keep[k] = not linked and frozenset((self.name_of[a], self.name_of[b])) not in skip
        self.pair_sa, self.pair_sb = la[keep], lb[keep]
        self.pair_r = self.sphere_radius[self.pair_sa] + self.sphere_radius[self.pair_sb]

    def _sphere_centres(self) -> np.ndarray:
        """World centres ``(shapes, 3)`` of the shape spheres at the current configuration."""
        states = self.p.getLinkStates(self.robot, list(range(self.n_links)))
        base = self.p.getBasePositionAndOrientation(self.robot)
        pos = np.array([base[0]] + [s[0] for s in states])
        quat = np.array([base[1]] + [s[1] for s in states])
        R = _quat_matrices(quat)[self.sphere_link + 1]
        return pos[self.sphere_link + 1] + np.einsum("kij,kj->ki", R, self.sphere_center)

    def _descendants(self, link: int) -> np.ndarray:
        """Links below ``link`` in the tree, itself included."""
        out = [link]
        for k in range(link + 1, self.n_links):  # PyBullet numbers children after their parents
            if self.parent[k] in out:
                out.append(k)
        return np.array(out, dtype=int)

    def joint_reach(self, joint_ids: Sequence[int], held: Mapping[str, _Held]) -> np.ndarray:
        """``R_j`` (metres) of each moving joint: farthest collision geometry it carries, held parts included.

        Distances between a link's frame origin and its parent's are constant (both sit on the
        parent), so the sum along the tree from joint ``j`` to a link plus that link's radius bounds
        the distance from ``j``'s axis to any of its points, whatever the configuration.
        """
        states = self.p.getLinkStates(self.robot, list(range(self.n_links)), computeForwardKinematics=True)
        origin = np.array([s[4] for s in states])
        com = np.array([s[0] for s in states])
        base = np.asarray(self.p.getBasePositionAndOrientation(self.robot)[0])
        step = np.array(
            [
                np.linalg.norm(origin[k] - (origin[self.parent[k]] if self.parent[k] >= 0 else base))
                for k in range(self.n_links)
            ]
        )
        held_r = {}
        for arm, h in held.items():
            lo, hi = (np.asarray(v) for v in self.p.getAABB(self.world.parts[h.part][0], -1))
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            held_r[self.tcp_idx[arm]] = float(np.max(np.linalg.norm(corners - origin[self.tcp_idx[arm]], axis=1)))
        reach = np.zeros(len(joint_ids))
        for i, j in enumerate(joint_ids):
            if self.joint_type[j] == pybullet.JOINT_PRISMATIC:
                reach[i] = 1.0  # every point below translates by dq
                continue
            best = 0.0
            for k in self._descendants(j):
                path, m = 0.0, int(k)
                while m != j:  # chain length from j's origin to k's origin
                    path += step[m]
                    m = int(self.parent[m])
                if self.radius[k + 1] >= 0.0:
                    best = max(best, path + float(np.linalg.norm(com[k] - origin[k])) + self.radius[k + 1])
                if k in held_r:
                    best = max(best, path + held_r[k])
            reach[i] = best
        return reach

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
        cen = self._sphere_centres()
        sa, sb = self.pair_sa[pairs], self.pair_sb[pairs]
        near = np.linalg.norm(cen[sa] - cen[sb], axis=1) - self.pair_r[pairs] < d
        todo = {(int(a), int(b)) for a, b in zip(self.sphere_link[sa[near]], self.sphere_link[sb[near]], strict=True)}
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
            moving = np.unique(np.concatenate([self._descendants(j) for j in ids]))
            live = np.nonzero(
                np.isin(self.sphere_link[self.pair_sa], moving) | np.isin(self.sphere_link[self.pair_sb], moving)
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
