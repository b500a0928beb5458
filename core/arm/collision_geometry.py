"""The collision objects of an arm's world: robot links from the URDF, the table, obstacles and held parts.

Each :class:`Geom` carries its oriented bounding box (for the vectorised prune) and its python-fcl
geometry (for the exact narrow phase), and says how it is posed: on a joint of the pinocchio model
(``joint >= 0``) or fixed in the world (``joint == -1``). Frames: world, z up, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import fcl
import numpy as np
import pinocchio as pin
import trimesh

from asmteach.core.arm.urdf_check import resolve_mesh
from asmteach.core.errors import UserError

if TYPE_CHECKING:
    from asmteach.core.arm.kinematics import Kinematics

__all__ = ["Geom", "box_geom", "bvh", "fcl_transform", "mesh_geom", "robot_geoms"]


@dataclass
class Geom:
    """One collision object: OBB in its own frame, fcl geometry, how it is posed."""

    name: str
    link: str
    joint: int  # parent joint id (-1: world-fixed obstacle)
    placement: np.ndarray  # (4, 4) geometry frame in the parent joint frame (or world)
    obb: np.ndarray  # (4, 4) OBB frame in the geometry frame
    half: np.ndarray  # (3,) OBB half extents
    exact: bool  # True when the OBB is the geometry (a box)
    fcl_geom: object = None
    fcl_obj: object = None
    tags: set[str] = field(default_factory=set)
    kind: str = "box"  # box, cylinder, sphere or mesh
    mesh: trimesh.Trimesh | None = None  # the mesh of a mesh geometry, in its geometry frame

    @property
    def radius(self) -> float:
        return float(np.linalg.norm(self.half))


def bvh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    """python-fcl's bounding-volume hierarchy of a triangle mesh (its own frame)."""
    m = fcl.BVHModel()
    v = np.asarray(mesh.vertices, dtype=float)
    f = np.asarray(mesh.faces, dtype=int)
    m.beginModel(len(v), len(f))
    m.addSubModel(v, f)
    m.endModel()
    return m


def mesh_geom(name: str, link: str, joint: int, placement: np.ndarray, mesh: trimesh.Trimesh) -> Geom:
    """A mesh object (``mesh`` in its geometry frame, metres) with its minimum-volume OBB; not exact."""
    obb = mesh.bounding_box_oriented
    return Geom(
        name,
        link,
        joint,
        placement,
        np.asarray(obb.primitive.transform, dtype=float),
        0.5 * np.asarray(obb.primitive.extents, dtype=float),
        False,
        bvh(mesh),
        kind="mesh",
        mesh=mesh,
    )


def box_geom(name: str, link: str, joint: int, placement: np.ndarray, size: np.ndarray) -> Geom:
    """A box of full extents ``size`` (metres), centred on its geometry frame: its own OBB, so exact."""
    size = np.asarray(size, dtype=float)
    return Geom(name, link, joint, placement, np.eye(4), 0.5 * size, True, fcl.Box(*size))


def fcl_transform(T: np.ndarray) -> fcl.Transform:
    """The python-fcl transform of a ``(4, 4)`` pose."""
    return fcl.Transform(np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]))


def robot_geoms(kin: Kinematics) -> list[Geom]:
    """The collision geometry of ``kin``'s URDF, one :class:`Geom` per collision element, on its parent joint."""
    try:
        gm = pin.buildGeomFromUrdf(kin.model, str(kin.urdf), pin.COLLISION, package_dirs=[str(kin.urdf.parent)])
    except Exception as exc:  # noqa: BLE001 - pinocchio raises plain RuntimeErrors
        raise UserError(f"{kin.urdf}: cannot read the collision geometry ({exc})") from None
    out: list[Geom] = []
    for go in gm.geometryObjects:
        link = kin.model.frames[go.parentFrame].name
        P = go.placement.homogeneous
        g = go.geometry
        kind = type(g).__name__
        name = f"{link}/{go.name}"
        if kind == "Box":
            geom = box_geom(name, link, go.parentJoint, P, 2.0 * np.asarray(g.halfSide))
        elif kind == "Cylinder":
            r, h = float(g.radius), 2.0 * float(g.halfLength)
            geom = Geom(
                name,
                link,
                go.parentJoint,
                P,
                np.eye(4),
                np.array([r, r, 0.5 * h]),
                False,
                fcl.Cylinder(r, h),
                kind="cylinder",
            )
        elif kind == "Sphere":
            r = float(g.radius)
            geom = Geom(name, link, go.parentJoint, P, np.eye(4), np.full(3, r), False, fcl.Sphere(r), kind="sphere")
        else:  # a mesh: load it with trimesh (pinocchio resolved the path) and scale it
            path = resolve_mesh(go.meshPath, kin.urdf.parent)
            mesh = trimesh.load(path, force="mesh")
            mesh.apply_scale(np.asarray(go.meshScale, dtype=float))
            geom = mesh_geom(name, link, go.parentJoint, P, mesh)
        geom.fcl_obj = fcl.CollisionObject(geom.fcl_geom, fcl.Transform())
        out.append(geom)
    return out
