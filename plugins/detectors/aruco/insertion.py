"""The insertion direction ``v_a``: from the demonstrated approach, checked with python-fcl, or geometric.

``v_a`` is a unit vector in A's frame along which B moves *into* its
assembled pose ``T_A_B``; retreating means moving B by ``-s * v_a``.
Contact in the assembled pose is normal (B rests on A), and a taught pose is
off by a fraction of a millimetre, so collision checks use both meshes shrunk
by ``tolerance`` along their vertex normals.
"""

from __future__ import annotations

from dataclasses import dataclass

import fcl
import numpy as np
import trimesh

from asmteach.core import geometry

__all__ = [
    "RetreatCheck",
    "check_retreat",
    "direction_from_approach",
    "free_cone_centre",
    "separation_direction",
]


def _bvh(mesh: trimesh.Trimesh, tolerance: float) -> fcl.BVHModel:
    verts = np.asarray(mesh.vertices, dtype=float) - tolerance * np.asarray(mesh.vertex_normals, dtype=float)
    model = fcl.BVHModel()
    model.beginModel(len(verts), len(mesh.faces))
    model.addSubModel(verts, np.asarray(mesh.faces, dtype=np.int64))
    model.endModel()
    return model


class _Pair:
    """A fixed at the origin of its frame, B movable; both as fcl BVH models."""

    def __init__(self, mesh_a: trimesh.Trimesh, mesh_b: trimesh.Trimesh, tolerance: float) -> None:
        self.a = fcl.CollisionObject(_bvh(mesh_a, tolerance), fcl.Transform())
        self.b_model = _bvh(mesh_b, tolerance)
        self.b = fcl.CollisionObject(self.b_model, fcl.Transform())

    def place(self, T_A_B: np.ndarray) -> None:
        self.b.setTransform(fcl.Transform(T_A_B[:3, :3], T_A_B[:3, 3]))

    def collides(self, T_A_B: np.ndarray) -> bool:
        self.place(T_A_B)
        return fcl.collide(self.a, self.b, fcl.CollisionRequest(), fcl.CollisionResult()) > 0

    def distance(self, T_A_B: np.ndarray) -> float:
        self.place(T_A_B)
        return float(fcl.distance(self.a, self.b, fcl.DistanceRequest(), fcl.DistanceResult()))


def _moved(T_A_B: np.ndarray, offset: np.ndarray) -> np.ndarray:
    T = T_A_B.copy()
    T[:3, 3] = T[:3, 3] + offset
    return T


@dataclass
class RetreatCheck:
    """Outcome of :func:`check_retreat`."""

    ok: bool
    end_free: bool
    """B moved back by ``retract * v_a`` does not collide with A."""
    path_free: bool
    """Every sampled pose of the straight retreat is free (within the tolerance)."""
    first_collision: float | None = None
    """Retreat distance (metres) of the first colliding sample, if any."""


def check_retreat(
    mesh_a: trimesh.Trimesh,
    mesh_b: trimesh.Trimesh,
    T_A_B: np.ndarray,
    v_a: np.ndarray,
    *,
    retract: float = 0.5,
    step: float = 0.001,
    tolerance: float = 5e-4,
) -> RetreatCheck:
    """Is retreating B from ``T_A_B`` by ``s * v_a``, ``s`` in ``(0, retract]``, free of A?

    The path is sampled every ``step`` metres over the first 0.15 m (where the
    parts can still touch), then coarser up to ``retract``.
    """
    v = np.asarray(v_a, float) / np.linalg.norm(v_a)
    pair = _Pair(mesh_a, mesh_b, tolerance)
    near = np.arange(2.0 * step, min(retract, 0.15) + 1e-12, step)
    far = np.linspace(min(retract, 0.15), retract, 20)[1:] if retract > 0.15 else np.empty(0)
    first = None
    for s in np.concatenate([near, far, [retract]]):
        if pair.collides(_moved(T_A_B, -s * v)):
            first = float(s)
            break
    end_free = not pair.collides(_moved(T_A_B, -retract * v))
    return RetreatCheck(
        ok=end_free and first is None, end_free=end_free, path_free=first is None, first_collision=first
    )


def _path_free(pair: _Pair, T_A_B: np.ndarray, v: np.ndarray, retract: float, step: float) -> bool:
    near = np.arange(2.0 * step, min(retract, 0.15) + 1e-12, step)
    for s in np.concatenate([near, [retract]]):
        if pair.collides(_moved(T_A_B, -s * v)):
            return False
    return True


def free_cone_centre(
    mesh_a: trimesh.Trimesh,
    mesh_b: trimesh.Trimesh,
    T_A_B: np.ndarray,
    v_a: np.ndarray,
    *,
    cone_deg: float = 6.0,
    rings: int = 12,
    per_ring: int = 16,
    retract: float = 0.5,
    step: float = 0.001,
    tolerance: float = 5e-4,
) -> tuple[np.ndarray, int] | None:
    """The demonstrated ``v_a`` corrected by geometry: the mean of the free retreat directions near it.

    A tight fit (a peg in its hole, a slide in a slot) admits only a narrow
    cone of straight retreats; a demonstrated direction a degree off can fall
    just outside it. Directions within ``cone_deg`` of ``v_a`` (``rings``
    rings of ``per_ring``) whose straight retreat is free are averaged: the
    centre of the free cone seen from the demonstration. Returns ``(v_a,
    number of free directions)`` or ``None`` when none near ``v_a`` is free
    (the demonstration and the geometry disagree).
    """
    v = np.asarray(v_a, float) / np.linalg.norm(v_a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(v, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(v, e1)
    ang = np.radians(np.linspace(cone_deg / rings, cone_deg, rings))
    az = np.linspace(0.0, 2 * np.pi, per_ring, endpoint=False)
    dirs = [v] + [np.cos(a) * v + np.sin(a) * (np.cos(b) * e1 + np.sin(b) * e2) for a in ang for b in az]
    pair = _Pair(mesh_a, mesh_b, tolerance)
    free = [d for d in dirs if _path_free(pair, T_A_B, d, retract, step)]
    if not free:
        return None
    c = np.mean(free, axis=0)
    return c / np.linalg.norm(c), len(free)


def separation_direction(
    mesh_a: trimesh.Trimesh,
    mesh_b: trimesh.Trimesh,
    T_A_B: np.ndarray,
    *,
    directions: int = 160,
    clearance: float = 0.005,
    max_travel: float = 0.2,
    step: float = 0.002,
    tolerance: float = 5e-4,
) -> tuple[np.ndarray, float]:
    """Geometric ``v_a``: minus the collision-free straight retreat direction of least travel.

    For each candidate direction ``d`` (A's axes and a Fibonacci sphere),
    B is moved by ``s * d`` until it is ``clearance`` away from A; a
    collision on the way rules ``d`` out. Ties (within one step) are resolved
    by averaging the tied directions, the centre of the free cone. Returns
    ``(v_a, travel in metres)``; raises ``ValueError`` if no direction is free.
    """
    pair = _Pair(mesh_a, mesh_b, tolerance)
    i = np.arange(directions) + 0.5
    phi = np.arccos(1 - 2 * i / directions)
    theta = np.pi * (1 + 5**0.5) * i
    cand = np.vstack(
        [
            np.eye(3),
            -np.eye(3),
            np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)]),
        ]
    )
    travel = np.full(len(cand), np.inf)
    for k, d in enumerate(cand):
        for s in np.arange(step, max_travel + 1e-12, step):
            T = _moved(T_A_B, s * d)
            if pair.collides(T):
                break
            if pair.distance(T) >= clearance:
                travel[k] = s
                break
    best = float(travel.min())
    if not np.isfinite(best):
        raise ValueError("B cannot be moved out of A along any straight line")
    tied = cand[travel <= best + step + 1e-12]
    d = tied.mean(axis=0)
    if np.linalg.norm(d) < 1e-6:
        d = cand[int(np.argmin(travel))]
    d = d / np.linalg.norm(d)
    return -d, best


def direction_from_approach(
    positions: np.ndarray, assembled: np.ndarray, *, k: float = 3.0, min_lateral: float = 0.001
) -> tuple[np.ndarray, float, int]:
    """``v_a`` from B's origins ``(n, 3)`` in A's frame during the approach.

    A line through the assembled position (known far better than any single
    approach frame) is fitted to the approach positions: the direction is the
    principal axis of the offsets ``assembled - p_i`` (least squares on the
    lateral distances, so far frames weigh more, as they should for a
    direction). Frames whose lateral distance exceeds ``k`` robust standard
    deviations (at least ``min_lateral`` metres) are dropped and the line is
    refitted. Returns ``(v_a, rms lateral deviation of the kept frames in
    metres, number of frames kept)``.
    """
    D = np.asarray(assembled, float)[None, :] - np.asarray(positions, float)
    keep = np.linalg.norm(D, axis=1) > 1e-9
    d = np.zeros(3)
    for _ in range(5):
        _, _, vt = np.linalg.svd(D[keep], full_matrices=False)
        d = vt[0] if np.dot(vt[0], D[keep].sum(axis=0)) >= 0 else -vt[0]
        lateral = np.linalg.norm(D - np.outer(D @ d, d), axis=1)
        thr = max(k * 1.4826 * float(np.median(lateral[keep])), min_lateral)
        new = (lateral <= thr) & (D @ d > 0)
        if new.sum() < 2 or np.array_equal(new, keep):
            break
        keep = new
    lateral = np.linalg.norm(D - np.outer(D @ d, d), axis=1)
    return d / np.linalg.norm(d), float(np.sqrt(np.mean(lateral[keep] ** 2))), int(keep.sum())


def retracted_pose(T_A_B: np.ndarray, v_a: np.ndarray, retract: float) -> np.ndarray:
    """Pre-assembly pose of B in A: ``T_A_B`` translated by ``-retract * v_a``."""
    return geometry.compose(geometry.from_rotation(np.eye(3), -retract * np.asarray(v_a, float)), T_A_B)
