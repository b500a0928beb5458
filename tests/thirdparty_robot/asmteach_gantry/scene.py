"""The gantry's planning scene: the hand's boxes and the held part against the table and the obstacles.

Written against :class:`asmteach.core.robot.PlanningScene` only. The table is
a half-space below ``table_height`` over the table's extent (checked on box
corners and hull vertices, exact for boxes and convex parts); obstacles are
meshes checked with python-fcl. The gantry's beams and wrist column are
assumed to stay above the workspace and are not modelled.

Frames: world, z up, metres.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import fcl
import numpy as np
import trimesh

from asmteach.core.hand_geometry import hand_boxes
from asmteach.core.interfaces import Obstacle
from asmteach.core.models import HandSpec
from asmteach.core.robot import Attachment, PlanningScene

__all__ = ["GantryScene", "TableBox"]


@dataclass(frozen=True)
class TableBox:
    """The table top: centre x, y and size x, y (metres) with its top face at world z ``height``."""

    center: tuple[float, float]
    size: tuple[float, float]
    height: float

    def gap(self, points: np.ndarray) -> np.ndarray:
        """``(n, m, 3)`` points -> ``(n,)`` least height (metres) above the table top of those over the table
        (``inf`` when none is over it); negative means inside the table."""
        over = np.all(np.abs(points[..., :2] - np.asarray(self.center)) <= 0.5 * np.asarray(self.size), axis=-1)
        z = np.where(over, points[..., 2] - self.height, np.inf)
        return z.min(axis=-1)


def _bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    m = fcl.BVHModel()
    m.beginModel(len(mesh.vertices), len(mesh.faces))
    m.addSubModel(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int32))
    m.endModel()
    return m


def _tf(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(np.asarray(T[:3, :3], float), np.asarray(T[:3, 3], float))


class _Geometry:
    """fcl objects shared by all scenes of one robot, built once per mesh (keyed by the mesh object)."""

    def __init__(self) -> None:
        self._bvh: dict[int, tuple[trimesh.Trimesh, fcl.BVHModel]] = {}

    def bvh(self, mesh: trimesh.Trimesh) -> fcl.BVHModel:
        key = id(mesh)
        if key not in self._bvh:  # the mesh is kept with its BVH, so its id is not reused meanwhile
            self._bvh[key] = (mesh, _bvh(mesh))
        return self._bvh[key][1]


class GantryScene(PlanningScene):
    """A :class:`PlanningScene` of the gantry; ``fk(arm, q) -> T_world_tcp`` comes from the robot model."""

    def __init__(
        self,
        fk: Callable[[str, np.ndarray], np.ndarray],
        hand: HandSpec,
        table: TableBox,
        configuration: Mapping[str, np.ndarray],
        obstacles: Sequence[Obstacle] = (),
        attached: Mapping[str, Attachment] | None = None,
        geometry: _Geometry | None = None,
    ) -> None:
        super().__init__(configuration, obstacles, attached)
        self._fk, self._hand, self._table = fk, hand, table
        self._geometry = geometry if geometry is not None else _Geometry()

    @property
    def table(self) -> Obstacle:
        t = self._table
        T = np.eye(4)
        T[:3, 3] = [t.center[0], t.center[1], t.height - 0.025]
        return Obstacle("table", trimesh.creation.box(extents=[t.size[0], t.size[1], 0.05]), T)

    def with_table(self, table: TableBox) -> GantryScene:
        """This scene on another table."""
        return GantryScene(
            self._fk, self._hand, table, self.configuration, self.obstacles, self.attached, self._geometry
        )

    # ------------------------------------------------------------ queries
    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: Sequence[str] = ()) -> np.ndarray:
        return np.array([bool(self._contacts(arm, q, ignore, first=True)) for q in np.atleast_2d(qs)], bool)

    def collision_reports(self, arm: str, qs: np.ndarray) -> list[list[tuple[str, str]]]:
        return [self._contacts(arm, q, (), first=False) for q in np.atleast_2d(qs)]

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        out = []
        for q in np.atleast_2d(qs):
            moving = self._moving(arm, q)
            corners = self._corners(arm, q).values()
            best = min([float(upto)] + [max(0.0, float(self._table.gap(p[None])[0])) for p in corners])
            for ob in self.obstacles:
                for _, obj, center, radius in moving:
                    if np.linalg.norm(center - ob.T_world[:3, 3]) - radius - _radius(ob.mesh) >= best:
                        continue  # the bounding spheres are already farther apart than the best so far
                    other = fcl.CollisionObject(self._geometry.bvh(ob.mesh), _tf(ob.T_world))
                    d = fcl.distance(obj, other, fcl.DistanceRequest(), fcl.DistanceResult())
                    best = min(best, max(0.0, float(d)))
            out.append(best)
        return np.asarray(out, float)

    # ------------------------------------------------------------ geometry
    def _moving(self, arm: str, q: np.ndarray) -> list[tuple[str, fcl.CollisionObject, np.ndarray, float]]:
        """``(name, fcl object, centre, bounding radius)`` of each hand box and the held part at ``q``."""
        T = self._fk(arm, np.asarray(q, float))
        held = self.attached.get(arm)
        width = self._hand.max_width if held is None or held.width is None else held.width
        out = []
        for box in hand_boxes(self._hand, width):
            T_box = T.copy()
            T_box[:3, 3] = T[:3, :3] @ box.center + T[:3, 3]
            out.append(
                (
                    f"hand:{box.name}",
                    fcl.CollisionObject(fcl.Box(*box.size), _tf(T_box)),
                    T_box[:3, 3],
                    0.5 * float(np.linalg.norm(box.size)),
                )
            )
        if held is not None:
            T_part = T @ held.T_tcp_part
            obj = fcl.CollisionObject(self._geometry.bvh(held.part.mesh), _tf(T_part))
            out.append((f"held:{held.part.name}", obj, T_part[:3, 3], _radius(held.part.mesh)))
        return out

    def _corners(self, arm: str, q: np.ndarray) -> dict[str, np.ndarray]:
        """World points whose lowest one decides contact with the table: box corners, the held part's hull."""
        T = self._fk(arm, np.asarray(q, float))
        held = self.attached.get(arm)
        width = self._hand.max_width if held is None or held.width is None else held.width
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        out = {}
        for box in hand_boxes(self._hand, width):
            local = box.center + 0.5 * signs * box.size
            out[f"hand:{box.name}"] = local @ T[:3, :3].T + T[:3, 3]
        if held is not None:
            T_part = T @ held.T_tcp_part
            hull = np.asarray(held.part.mesh.convex_hull.vertices, float)
            out[f"held:{held.part.name}"] = hull @ T_part[:3, :3].T + T_part[:3, 3]
        return out

    def _contacts(self, arm: str, q: np.ndarray, ignore: Sequence[str], *, first: bool) -> list[tuple[str, str]]:
        found: list[tuple[str, str]] = []
        for name, pts in self._corners(arm, q).items():
            if name.startswith("held:") and "table" in ignore:
                continue
            if self._table.gap(pts[None])[0] < -1e-6:
                found.append((name, "table"))
                if first:
                    return found
        for name, obj, center, radius in self._moving(arm, q):
            for ob in self.obstacles:
                if name.startswith("held:") and ob.name in ignore:
                    continue
                if np.linalg.norm(center - ob.T_world[:3, 3]) > radius + _radius(ob.mesh):
                    continue
                other = fcl.CollisionObject(self._geometry.bvh(ob.mesh), _tf(ob.T_world))
                if fcl.collide(obj, other, fcl.CollisionRequest(), fcl.CollisionResult()):
                    found.append((name, ob.name))
                    if first:
                        return found
        return found


def _radius(mesh: trimesh.Trimesh) -> float:
    """Bounding radius (metres) of a mesh about its mesh-frame origin."""
    return float(np.linalg.norm(np.asarray(mesh.vertices, float), axis=1).max())
