"""Batch collision checking and clearance for serial arms, with python-fcl and numpy.

The robot's collision geometry comes from its URDF through pinocchio's
geometry model (boxes, cylinders, spheres, meshes), attached to the joints of
the pinocchio model. For a batch of ``n`` arm configurations:

1. joint poses for all ``n`` at once (:meth:`Kinematics.batch_joint_poses`, numpy);
2. every pair that may touch (robot link vs robot link, excluding adjacent and
   listed pairs; robot vs table and obstacles; held part vs everything but the
   hand) is pruned by bounding spheres and then tested with the separating-axis
   test on oriented bounding boxes, vectorised over all ``n x pairs``;
3. a box's OBB is the box itself, so box-box pairs (the Nextage, the table) are
   decided exactly by step 2; pairs involving cylinders, meshes (parts) or the
   held part that survive step 2 go to python-fcl's exact narrow phase.

Frames: world (z up, metres). Clearance is python-fcl's minimum distance.
The collision objects are built in :mod:`~asmteach.core.arm.collision_geometry`;
the vectorised box tests are in :mod:`~asmteach.core.arm.obb`.
"""

from __future__ import annotations

from collections.abc import Sequence

import fcl
import numpy as np

from asmteach.core.arm.collision_geometry import Geom, box_geom, fcl_transform, mesh_geom, robot_geoms
from asmteach.core.arm.kinematics import Kinematics
from asmteach.core.arm.obb import obb_gap, obb_overlap
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Obstacle, PartModel

__all__ = ["CollisionChecker"]


class CollisionChecker:
    """Self and world collision of a robot's arms, for planners (batch) and error messages (report).

    Parameters
    ----------
    kin : the robot's kinematics (its ``q_full`` gives the joints not being checked).
    disabled : link-name pairs never checked (adjacent links are added automatically).
    hand_links : per arm, the links that may touch a held part (gripper body, fingers).
    """

    def __init__(
        self,
        kin: Kinematics,
        *,
        disabled: Sequence[tuple[str, str]] = (),
        hand_links: dict[str, Sequence[str]] | None = None,
    ) -> None:
        self.kin = kin
        self.disabled: set[frozenset[str]] = set(kin.info.adjacent) | {frozenset(p) for p in disabled}
        self.hand_links = {a: set(v) for a, v in (hand_links or {}).items()}
        self.robot: list[Geom] = robot_geoms(kin)
        self.table: Geom | None = None
        self.obstacles: list[Geom] = []
        self.held: dict[str, Geom] = {}
        self._pairs: dict[tuple[str, ...], tuple[list[Geom], np.ndarray, np.ndarray, np.ndarray]] = {}

    # ------------------------------------------------------------ geometry
    def set_table(
        self, center_xy: Sequence[float], size_xy: Sequence[float], height: float, thickness: float = 0.05
    ) -> None:
        """The table as a box whose top face is at ``height`` (world z, metres)."""
        T = np.eye(4)
        T[:3, 3] = [center_xy[0], center_xy[1], height - 0.5 * thickness]
        g = box_geom("table", "table", -1, T, np.array([size_xy[0], size_xy[1], thickness]))
        g.fcl_obj = fcl.CollisionObject(g.fcl_geom, fcl_transform(T))
        self.table = g
        self._pairs.clear()

    def set_obstacles(self, obstacles: Sequence[Obstacle]) -> None:
        """Replace the static obstacles (meshes at world poses)."""
        out = []
        for ob in obstacles:
            T = np.asarray(ob.T_world, dtype=float)
            g = mesh_geom(ob.name, ob.name, -1, T, ob.mesh)
            g.fcl_obj = fcl.CollisionObject(g.fcl_geom, fcl_transform(T))
            out.append(g)
        self.obstacles = out
        self._pairs.clear()

    def attach(self, arm: str, part: PartModel | None, T_tcp_part: np.ndarray | None = None) -> None:
        """Hold ``part`` at ``T_tcp_part`` in ``arm``'s TCP frame (``None`` releases it)."""
        chain = self.kin.chain(arm)
        if part is None:
            self.held.pop(arm, None)
        else:
            if T_tcp_part is None:
                raise UserError(f"attach({arm!r}, {part.name!r}): T_tcp_part is required")
            frame = self.kin.model.frames[self.kin.model.getFrameId(chain.tcp_frame)]
            P = frame.placement.homogeneous @ np.asarray(T_tcp_part, dtype=float)
            g = mesh_geom(f"held:{part.name}", f"held:{part.name}", frame.parentJoint, P, part.mesh)
            g.fcl_obj = fcl.CollisionObject(g.fcl_geom, fcl.Transform())
            g.tags.add(arm)
            self.held[arm] = g
        self._pairs.clear()

    # ------------------------------------------------------------ pairs
    def _pair_set(self, arm: str, ignore: Sequence[str]) -> tuple[list[Geom], np.ndarray, np.ndarray, np.ndarray]:
        """Objects (moving first) and the candidate pairs ``(a, b)`` with an exactness flag, cached."""
        key = (arm, *sorted(ignore))
        if key in self._pairs:
            return self._pairs[key]
        moving_j = set(self.kin.moving_joints(arm))
        moving = [g for g in self.robot if g.joint in moving_j]
        static = [g for g in self.robot if g.joint not in moving_j]
        # a part held by another arm is an obstacle that moves with that arm
        static += [g for a, g in self.held.items() if a != arm]
        held = self.held.get(arm)
        if held is not None:
            moving.append(held)
        world = ([self.table] if self.table is not None else []) + self.obstacles
        objs = moving + static + world
        idx = {id(g): k for k, g in enumerate(objs)}
        hand = self.hand_links.get(arm, set())
        pa: list[int] = []
        pb: list[int] = []
        for i, a in enumerate(moving):
            for b in objs[i + 1 :]:
                if a is held:
                    if b.link in hand or (b.joint == -1 and b.name in ignore):
                        continue
                elif b is held:
                    if a.link in hand:
                        continue
                elif a.link == b.link or frozenset((a.link, b.link)) in self.disabled:
                    continue
                pa.append(i)
                pb.append(idx[id(b)])
        A, B = np.array(pa, dtype=int), np.array(pb, dtype=int)
        exact = np.array([objs[a].exact and objs[b].exact for a, b in zip(pa, pb, strict=True)], dtype=bool)
        self._pairs[key] = (objs, A, B, exact)
        return self._pairs[key]

    def _poses(self, arm: str, qs: np.ndarray, objs: list[Geom]) -> np.ndarray:
        """World poses of every object's geometry frame: ``(n, len(objs), 4, 4)``."""
        moving, static = self.kin.batch_joint_poses(arm, qs)
        n = qs.shape[0]
        out = np.empty((n, len(objs), 4, 4))
        for k, g in enumerate(objs):
            if g.joint < 0:
                out[:, k] = g.placement
            elif g.joint in moving:
                out[:, k] = moving[g.joint] @ g.placement
            else:
                out[:, k] = static[g.joint] @ g.placement
        return out

    # ------------------------------------------------------------ queries
    def _hits(
        self, arm: str, qs: np.ndarray, ignore: Sequence[str], stop_early: bool = True
    ) -> tuple[list[Geom], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Contacts for ``n`` configurations: ``(objs, poses, config index, pair index, hit)``."""
        objs, A, B, exact = self._pair_set(arm, ignore)
        n = qs.shape[0]
        poses = self._poses(arm, qs, objs)
        half = np.stack([g.half for g in objs])
        rad = np.linalg.norm(half, axis=1)
        W = poses @ np.stack([g.obb for g in objs])[None]  # OBB frames in the world, (n, objs, 4, 4)
        # bounding-sphere prune in float32 (a 1e-3 m slack covers its rounding)
        cT = np.ascontiguousarray(W[:, :, :3, 3].transpose(1, 0, 2), dtype=np.float32)  # (objs, n, 3)
        diff = cT[A] - cT[B]  # (pairs, n, 3)
        d2 = diff[..., 0] ** 2 + diff[..., 1] ** 2 + diff[..., 2] ** 2
        pi, ci = np.nonzero(d2 <= ((rad[A] + rad[B] + 1e-3) ** 2).astype(np.float32)[:, None])
        if len(ci) == 0:
            return objs, poses, ci, pi, np.zeros(0, dtype=bool)
        a, b = A[pi], B[pi]
        over = obb_overlap(W[ci, a, :3, 3], W[ci, a, :3, :3], half[a], W[ci, b, :3, 3], W[ci, b, :3, :3], half[b])
        ci, pi = ci[over], pi[over]
        # Cylinders: also test their OBB turned by 30 and 60 deg about the axis (a 12-gon prism around the
        # cylinder); separation from any of these proves the pair apart.
        cyl = np.array([g.kind == "cylinder" for g in objs])
        for ang in (np.pi / 6.0, np.pi / 3.0):
            sel = cyl[A[pi]] | cyl[B[pi]]
            if not np.any(sel):
                break
            Rz = np.eye(4)
            Rz[:2, :2] = [[np.cos(ang), -np.sin(ang)], [np.sin(ang), np.cos(ang)]]
            a, b, cs = A[pi[sel]], B[pi[sel]], ci[sel]
            Wa, Wb = W[cs, a], W[cs, b]
            Wa = np.where(cyl[a][:, None, None], Wa @ Rz, Wa)
            Wb = np.where(cyl[b][:, None, None], Wb @ Rz, Wb)
            keep = np.ones(len(ci), dtype=bool)
            keep[np.nonzero(sel)[0]] = obb_overlap(
                Wa[:, :3, 3], Wa[:, :3, :3], half[a], Wb[:, :3, 3], Wb[:, :3, :3], half[b]
            )
            ci, pi = ci[keep], pi[keep]
        hit = exact[pi].copy()
        done = np.zeros(n, dtype=bool)
        done[ci[hit]] = True
        req = fcl.CollisionRequest()
        for k in np.nonzero(~hit)[0]:
            if stop_early and done[ci[k]]:
                continue  # this configuration is already known to collide
            ga, gb = objs[A[pi[k]]], objs[B[pi[k]]]
            ga.fcl_obj.setTransform(fcl_transform(poses[ci[k], A[pi[k]]]))
            gb.fcl_obj.setTransform(fcl_transform(poses[ci[k], B[pi[k]]]))
            hit[k] = fcl.collide(ga.fcl_obj, gb.fcl_obj, req, fcl.CollisionResult()) > 0
            done[ci[k]] |= hit[k]
        return objs, poses, ci, pi, hit

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        """``(n, dof)`` configurations -> ``(n,)`` bool, True where anything touches.

        ``ignore`` names obstacles the held part may touch (e.g. the part it is placed on).
        """
        qs = np.atleast_2d(self.kin.check_limits(arm, qs))
        out = np.zeros(qs.shape[0], dtype=bool)
        if qs.shape[0] == 0:
            return out
        _, _, ci, _, hit = self._hits(arm, qs, ignore)
        out[ci[hit]] = True
        return out

    def report(self, arm: str, q: np.ndarray, *, ignore: Sequence[str] = ()) -> list[tuple[str, str]]:
        """Pairs ``(robot link or held part, other link or obstacle)`` in contact at ``q``."""
        return self.reports(arm, np.asarray(q, dtype=float).reshape(1, -1), ignore=ignore)[0]

    def reports(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> list[list[tuple[str, str]]]:
        """:meth:`report` of each of ``qs`` ``(n, dof)``, in one pass over all of them."""
        qs = np.atleast_2d(self.kin.check_limits(arm, qs))
        objs, A, B, _ = self._pair_set(arm, ignore)
        _, _, ci, pi, hit = self._hits(arm, qs, ignore, stop_early=False)
        out: list[set[tuple[str, str]]] = [set() for _ in range(qs.shape[0])]
        for c, p in zip(ci[hit], pi[hit], strict=True):
            out[c].add((objs[A[p]].link, objs[B[p]].link))
        return [sorted(pairs) for pairs in out]

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        """``(n,)`` minimum distance (metres, 0 when touching) from the moving robot geometry and the
        held part to the table and the obstacles; distances of ``upto`` or more come back as ``upto``.

        Every pair gets a lower bound from its two OBBs (the separation along
        either box's face normals); pairs are measured with fcl in order of that
        bound, until the bound reaches the smallest distance found (or ``upto``).
        Most pairs of a free configuration are never measured.
        """
        qs = np.atleast_2d(self.kin.check_limits(arm, qs))
        objs, _, _, _ = self._pair_set(arm, ())
        moving_j = set(self.kin.moving_joints(arm))
        mov = np.array([k for k, g in enumerate(objs) if g.joint in moving_j and g.joint >= 0], dtype=int)
        world = np.array([k for k, g in enumerate(objs) if g.joint < 0], dtype=int)
        out = np.full(qs.shape[0], float(upto))
        if mov.size == 0 or world.size == 0:
            return out
        poses = self._poses(arm, qs, objs)
        W = poses @ np.stack([g.obb for g in objs])[None]  # OBB frames in the world, (n, objs, 4, 4)
        half = np.stack([g.half for g in objs])
        lb = np.maximum(
            obb_gap(W[:, mov], half[mov], W[:, world], half[world]),
            obb_gap(W[:, world], half[world], W[:, mov], half[mov]).transpose(0, 2, 1),
        )
        pair_m, pair_w = np.meshgrid(mov, world, indexing="ij")
        pair_m, pair_w = pair_m.ravel(), pair_w.ravel()
        lb = np.maximum(lb.reshape(qs.shape[0], -1), 0.0)
        req = fcl.DistanceRequest()
        for i in range(qs.shape[0]):
            best = float(upto)
            for p in np.argsort(lb[i]):
                if lb[i, p] >= best:
                    break
                ga, gb = objs[pair_m[p]], objs[pair_w[p]]
                ga.fcl_obj.setTransform(fcl_transform(poses[i, pair_m[p]]))
                gb.fcl_obj.setTransform(fcl_transform(poses[i, pair_w[p]]))
                best = min(best, max(0.0, float(fcl.distance(ga.fcl_obj, gb.fcl_obj, req, fcl.DistanceResult()))))
                if best <= 0.0:
                    break
            out[i] = best
        return out
