"""Poses a part may be in when one view cannot tell: turns of a pose about a screw axis or the part's own axes,
and the part-frame turns that leave its surface nearly in place (near twins).

The rival poses a depth view judges (:mod:`asmteach.core.perception.second_view`) and the viewpoints ranked to
tell them apart (:mod:`asmteach.core.perception.view_choice`) are these turns of the detector's rivals.

Frames: poses ``T_world_part`` and turns in the part frame, metres, radians (``step_deg`` in degrees).
"""

from __future__ import annotations

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

import asmteach.core  # noqa: F401  (loads libusb before open3d)
from asmteach.core import geometry
from asmteach.core.perception.registration import model_cloud

import open3d as o3d  # isort: skip  (after asmteach.core)

__all__ = ["axis_turns", "near_twins", "own_symmetries", "screw_turns"]


def screw_turns(T_a: np.ndarray, T_b: np.ndarray, step_deg: float) -> list[np.ndarray]:
    """``T_a`` turned about the screw axis that takes it to ``T_b`` (world frame), every ``step_deg`` all round.

    Two poses one view cannot tell apart are usually the part turned about one of its near-symmetry axes (a D
    peg about its own): the truth may lie anywhere on that turn, not only at the two poses listed.
    """
    T_rel = np.asarray(T_b, float) @ geometry.invert(T_a)
    rotvec = Rotation.from_matrix(T_rel[:3, :3]).as_rotvec()
    angle = float(np.linalg.norm(rotvec))
    if angle < np.radians(step_deg) / 2:
        return []
    axis = rotvec / angle
    t = T_rel[:3, 3]
    # a point on the axis: (I - R) p = t less its slide along the axis (least squares: I - R is singular along it)
    p = np.linalg.lstsq(np.eye(3) - T_rel[:3, :3], t - (t @ axis) * axis, rcond=None)[0]
    out = []
    for phi in np.radians(np.arange(step_deg, 360.0 - step_deg / 2, step_deg)):
        R = Rotation.from_rotvec(axis * phi).as_matrix()
        out.append(geometry.from_rotation(R, p - R @ p) @ T_a)
    return out


def axis_turns(mesh: trimesh.Trimesh, T: np.ndarray, step_deg: float) -> list[np.ndarray]:
    """``T`` turned about each principal axis of ``mesh`` through its centre of mass (part frame), every
    ``step_deg`` all round: the turns that keep a nearly symmetric part nearly in place (a keyed peg about its
    axis, a near-square block about its normal) are among them."""
    from asmteach.core.symmetry import principal_frame

    com = np.asarray(mesh.center_mass, float)
    out = []
    for axis in principal_frame(mesh).T:
        for phi in np.radians(np.arange(step_deg, 360.0 - step_deg / 2, step_deg)):
            R = Rotation.from_rotvec(axis * phi).as_matrix()
            out.append(np.asarray(T, float) @ geometry.from_rotation(R, com - R @ com))
    return out


_OWN: dict[int, tuple[trimesh.Trimesh, np.ndarray]] = {}


def own_symmetries(mesh: trimesh.Trimesh) -> np.ndarray:
    """The part's own symmetries (part frame, about its centre of mass), computed once per mesh."""
    from asmteach.core.symmetry import part_symmetries

    hit = _OWN.get(id(mesh))
    if hit is None or hit[0] is not mesh:
        hit = (mesh, np.asarray(part_symmetries(mesh, np.asarray(mesh.center_mass, float))))
        _OWN[id(mesh)] = hit
    return hit[1]


_TWINS: dict[tuple[int, float, float], tuple[trimesh.Trimesh, np.ndarray]] = {}


def near_twins(mesh: trimesh.Trimesh, step_deg: float, twin_mm: float, most: int = 8) -> np.ndarray:
    """Part-frame turns ``(k, 4, 4)`` (about each principal axis through the centre of mass, every ``step_deg``)
    that leave the part's surface nearly in place: the local minima, identity excluded, of the mean distance
    (metres) of the turned surface from the surface, each at most ``twin_mm`` mm, the ``most`` nearest. A block
    turned 180 deg about its normal (a blind hole moved, the outside the same) or onto a side of nearly the
    same size; computed once per mesh."""
    key = (id(mesh), float(step_deg), float(twin_mm))
    hit = _TWINS.get(key)
    if hit is not None and hit[0] is mesh:
        return hit[1]
    model = model_cloud(mesh, 1000)
    turns = np.array(axis_turns(mesh, np.eye(4), step_deg))
    pts = np.vstack([geometry.transform_points(S, model.points) for S in turns]).astype(np.float32)
    gap = model.scene.compute_distance(o3d.core.Tensor(pts)).numpy().reshape(len(turns), -1).mean(axis=1)
    picked = []
    per_axis = len(turns) // 3
    for a in range(3):
        g = np.concatenate([[0.0], gap[a * per_axis : (a + 1) * per_axis], [0.0]])  # the identity at both ends
        for i in range(1, len(g) - 1):
            if g[i] < g[i - 1] and g[i] <= g[i + 1] and g[i] <= twin_mm / 1000.0:
                picked.append((g[i], a * per_axis + i - 1))
    out = np.array([turns[i] for _, i in sorted(picked)[:most]]).reshape(-1, 4, 4)
    _TWINS[key] = (mesh, out)
    return out
