"""Bounding spheres of a PyBullet robot's collision shapes: the plan re-checker's prune and reach bounds.

For every collision shape of every link, a sphere in the link's centre-of-mass frame (PyBullet's link
frame for queries); the robot's self pairs worth measuring (other links, not joined by a joint, not
skipped); and each joint's reach ``R_j``, the farthest collision geometry it carries, which bounds how far
any point moves for a joint step (see :mod:`asmteach.core.arm.plan_check`). Metres, radians.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pybullet
from pybullet_utils import bullet_client

from asmteach.core.errors import UserError

__all__ = ["LinkSpheres", "quat_matrices"]


def quat_matrices(q: np.ndarray) -> np.ndarray:
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


class LinkSpheres:
    """The collision-shape spheres of ``robot`` in client ``p``.

    ``name_of`` maps a link index (-1: the base) to its name; ``skip`` holds link-name pairs never
    checked (SRDF-disabled). Link indices are PyBullet's (children after their parents).
    """

    def __init__(
        self,
        p: bullet_client.BulletClient,
        robot: int,
        name_of: Mapping[int, str],
        skip: set[frozenset[str]],
    ) -> None:
        self.p, self.robot, self.name_of = p, robot, dict(name_of)
        n = p.getNumJoints(robot)
        self.parent = np.array([p.getJointInfo(robot, j)[16] for j in range(n)], dtype=int)
        self.joint_type = np.array([p.getJointInfo(robot, j)[2] for j in range(n)], dtype=int)
        self.n_links = n
        self._link_radii()
        self._self_pairs(skip)

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

    def centres(self) -> np.ndarray:
        """World centres ``(shapes, 3)`` of the shape spheres at the current configuration."""
        states = self.p.getLinkStates(self.robot, list(range(self.n_links)))
        base = self.p.getBasePositionAndOrientation(self.robot)
        pos = np.array([base[0]] + [s[0] for s in states])
        quat = np.array([base[1]] + [s[1] for s in states])
        R = quat_matrices(quat)[self.sphere_link + 1]
        return pos[self.sphere_link + 1] + np.einsum("kij,kj->ki", R, self.sphere_center)

    def descendants(self, link: int) -> np.ndarray:
        """Links below ``link`` in the tree, itself included."""
        out = [link]
        for k in range(link + 1, self.n_links):  # PyBullet numbers children after their parents
            if self.parent[k] in out:
                out.append(k)
        return np.array(out, dtype=int)

    def joint_reach(self, joint_ids: Sequence[int], held: Mapping[int, int] | None = None) -> np.ndarray:
        """``R_j`` (metres) of each moving joint: farthest collision geometry it carries, held parts included.

        ``held`` maps a link index (a TCP) to the PyBullet body welded to it; its bounding box counts.

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
        for tcp, body in (held or {}).items():
            lo, hi = (np.asarray(v) for v in self.p.getAABB(body, -1))
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            held_r[tcp] = float(np.max(np.linalg.norm(corners - origin[tcp], axis=1)))
        reach = np.zeros(len(joint_ids))
        for i, j in enumerate(joint_ids):
            if self.joint_type[j] == pybullet.JOINT_PRISMATIC:
                reach[i] = 1.0  # every point below translates by dq
                continue
            best = 0.0
            for k in self.descendants(j):
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
