"""The parallel-jaw hand as boxes, meshes and python-fcl objects at a grasp.

Shared by the grasp planner, the grasp filter and the regrasp planner. All
boxes are in the TCP frame of :class:`~asmteach.core.models.HandSpec` (z
approach, out of the palm toward the object; y jaw axis, finger 0 on -y). A
finger is a box of ``finger_size`` hanging from the palm's front face
(``palm_center.z + palm_size.z / 2``) along +z; its inner face lies at
``y = -+width / 2`` and carries the pad, a ``pad_size`` rectangle centred on
the TCP (x, z). Units: metres.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import fcl
import numpy as np
import trimesh

from asmteach.core.models import HandSpec

__all__ = [
    "HandBox",
    "MeshCollider",
    "hand_boxes",
    "hand_mesh",
    "pad_grid",
]


@dataclass(frozen=True)
class HandBox:
    """A named box of the hand: centre and full extents in the TCP frame (metres)."""

    name: str
    center: np.ndarray
    size: np.ndarray


def hand_boxes(hand: HandSpec, width: float, *, sweep: float = 0.0) -> list[HandBox]:
    """Palm and finger boxes with the jaw open to ``width`` (metres).

    ``sweep`` extends every box backward along -z by that many metres: the
    volume the hand passes through while approaching along +z over the last
    ``sweep`` metres.
    """
    palm_front = float(hand.palm_center[2] + 0.5 * hand.palm_size[2])
    t, depth, length = (float(v) for v in hand.finger_size)
    z_mid = palm_front + 0.5 * length
    boxes = [HandBox("palm", np.asarray(hand.palm_center, dtype=float), np.asarray(hand.palm_size, dtype=float))]
    for name, sign in (("finger0", -1.0), ("finger1", 1.0)):
        boxes.append(
            HandBox(name, np.array([0.0, sign * (0.5 * width + 0.5 * t), z_mid]), np.array([depth, t, length]))
        )
    if sweep > 0.0:
        boxes = [
            HandBox(b.name, b.center - np.array([0.0, 0.0, 0.5 * sweep]), b.size + np.array([0.0, 0.0, sweep]))
            for b in boxes
        ]
    return boxes


def hand_mesh(hand: HandSpec, width: float, T: np.ndarray | None = None) -> trimesh.Trimesh:
    """One mesh of the hand's boxes at opening ``width``, moved by ``T`` (4x4, e.g. ``T_part_tcp``)."""
    parts = []
    for b in hand_boxes(hand, width):
        m = trimesh.creation.box(extents=b.size)
        m.apply_translation(b.center)
        parts.append(m)
    mesh = trimesh.util.concatenate(parts)
    if T is not None:
        mesh.apply_transform(T)
    return mesh


def pad_grid(hand: HandSpec, nx: int, nz: int, *, inset: float = 0.0, grow: float = 0.0) -> np.ndarray:
    """``(nx * nz, 2)`` points ``(x, z)`` on a pad (TCP frame, metres).

    The rectangle is ``pad_size`` shrunk by ``inset`` (so edge points lie just
    inside a face that the pad exactly covers) or grown by ``grow`` on each side.
    """
    hx = 0.5 * hand.pad_size[0] - inset + grow
    hz = 0.5 * hand.pad_size[1] - inset + grow
    xs = np.linspace(-hx, hx, nx) if nx > 1 else np.zeros(1)
    zs = np.linspace(-hz, hz, nz) if nz > 1 else np.zeros(1)
    gx, gz = np.meshgrid(xs, zs, indexing="ij")
    return np.stack([gx.ravel(), gz.ravel()], axis=1)


def _fcl_mesh(mesh: trimesh.Trimesh) -> fcl.BVHModel:
    bvh = fcl.BVHModel()
    bvh.beginModel(len(mesh.vertices), len(mesh.faces))
    bvh.addSubModel(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int32))
    bvh.endModel()
    return bvh


def _fcl_transform(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(np.asarray(T[:3, :3], dtype=float), np.asarray(T[:3, 3], dtype=float))


class MeshCollider:
    """Hand-against-meshes collision with python-fcl.

    ``meshes`` are named static objects (``name -> (mesh, T_frame_mesh)``); the
    hand is placed with ``T_frame_tcp`` in the same frame (part frame while
    planning, world frame while filtering).
    """

    def __init__(self, meshes: dict[str, tuple[trimesh.Trimesh, np.ndarray]]) -> None:
        self.objects: dict[str, fcl.CollisionObject] = {}
        for name, (mesh, T) in meshes.items():
            self.objects[name] = fcl.CollisionObject(_fcl_mesh(mesh), _fcl_transform(T))
        self._request = fcl.CollisionRequest()

    def first_contact(self, boxes: Sequence[HandBox], T_frame_tcp: np.ndarray) -> tuple[str, str] | None:
        """The first ``(hand box, object)`` pair in contact, or ``None`` when free."""
        for box in boxes:
            T_box = T_frame_tcp.copy()
            T_box[:3, 3] = T_frame_tcp[:3, :3] @ box.center + T_frame_tcp[:3, 3]
            obj = fcl.CollisionObject(fcl.Box(*box.size), _fcl_transform(T_box))
            for name, other in self.objects.items():
                if fcl.collide(obj, other, self._request, fcl.CollisionResult()):
                    return box.name, name
        return None

    def collides(self, boxes: Sequence[HandBox], T_frame_tcp: np.ndarray) -> bool:
        """True when any hand box touches any object."""
        return self.first_contact(boxes, T_frame_tcp) is not None

    def distance(self, mesh: trimesh.Trimesh, T_frame_mesh: np.ndarray, skip: Sequence[str] = ()) -> float:
        """Least distance (metres) from ``mesh`` at ``T_frame_mesh`` to the objects not named in ``skip``;
        0 when they touch, ``inf`` when there is no other object."""
        obj = fcl.CollisionObject(_fcl_mesh(mesh), _fcl_transform(T_frame_mesh))
        best = np.inf
        for name, other in self.objects.items():
            if name not in skip:
                best = min(best, max(0.0, fcl.distance(obj, other, fcl.DistanceRequest(), fcl.DistanceResult())))
        return float(best)
