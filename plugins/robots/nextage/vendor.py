"""The vendor's NEXTAGE OPEN URDF (``NextageOpen.urdf`` of ``nextage_description``) with this project's gripper.

The vendor's file has no hand joints: the wrist roll, the tool changer and the
stock chuck hand are one mesh on ``*ARM_JOINT5_Link``. The demo needs a hand
that opens and closes, so the vendor option keeps the vendor's kinematics and
meshes for every link and mounts this project's two-finger gripper
(:func:`~asmteach.plugins.robots.nextage.build_urdf.gripper_xml`) at the hand
interface, ``(GRIPPER.mount_x, 0, 0) = (-0.065, 0, 0)`` of ``*ARM_JOINT5_Link``,
exactly where our own model mounts it. The part of the wrist mesh beyond that
flange (the chuck hand, x < -0.065 in the link frame) is cut away by that
plane, so the vendor's hand does not sit inside ours; the wrist roll
housing and the tool changer stay. The result: the vendor's links, limits and
collision meshes, and a TCP that is placed as in our model relative to the
flange (same ``*ARM_TCP_Link`` name, so everything downstream is unchanged).

Frames: link frames of the URDF, metres. The output is written next to the
resolved URDF (:func:`asmteach.core.urdf.resolve_urdf`, a content-keyed cache).
"""

from __future__ import annotations

import hashlib
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.urdf import resolve_urdf, write_urdf
from asmteach.plugins.robots.nextage.build_urdf import GRIPPER, MATERIALS, gripper_xml

__all__ = ["ARM_PREFIXES", "cut_at_flange", "vendor_urdf"]

ARM_PREFIXES = ("LARM", "RARM")


def _origin(elem: ET.Element) -> np.ndarray:
    o = elem.find("origin")
    if o is None:
        return np.eye(4)
    xyz = [float(v) for v in o.get("xyz", "0 0 0").split()]
    rpy = [float(v) for v in o.get("rpy", "0 0 0").split()]
    return geometry.from_rpy(rpy[0], rpy[1], rpy[2], xyz)


def cut_at_flange(mesh: trimesh.Trimesh, T_link_mesh: np.ndarray, flange_x: float = GRIPPER.mount_x) -> trimesh.Trimesh:
    """The part of a wrist mesh on the arm's side of the hand interface, in the link frame.

    ``T_link_mesh`` places the mesh in ``*ARM_JOINT5_Link`` (its URDF origin); the
    plane ``x = flange_x`` (metres, link frame) cuts it. The cut is left open: the
    vendor's meshes are open surfaces already (none is watertight), python-fcl
    tests surfaces and PyBullet takes each link's convex hull, so a cap adds nothing
    (and trimesh's capping needs shapely, not a dependency).
    """
    m = mesh.copy()
    m.apply_transform(T_link_mesh)
    # slice_faces_plane, not Trimesh.slice_plane: the latter imports shapely even without a cap
    out = trimesh.intersections.slice_faces_plane(
        m.vertices, m.faces, plane_normal=[1.0, 0.0, 0.0], plane_origin=[flange_x, 0.0, 0.0]
    )
    cut = trimesh.Trimesh(out[0], out[1], process=True)
    if len(cut.faces) == 0:
        raise UserError(f"the wrist mesh has nothing on the arm side of x = {flange_x} m (is it the wrist link?)")
    return cut


def vendor_urdf(urdf: str | Path, package_paths: Sequence[str | Path] = ()) -> Path:
    """Path of a URDF with the vendor's Nextage (``urdf``) and this project's grippers on both wrists.

    ``package://`` URIs are resolved from ``package_paths`` (and the URDF's own
    folders), the xacro lines are dropped and the COLLADA meshes converted (see
    :func:`asmteach.core.urdf.resolve_urdf`). :class:`UserError` when the file is
    not a Nextage (no ``LARM_JOINT5_Link``/``RARM_JOINT5_Link``) or already has a gripper.
    """
    res = resolve_urdf(urdf, package_paths)
    tree = ET.parse(res.path)
    root = tree.getroot()
    links = {e.get("name"): e for e in root.findall("link")}
    for pre in ARM_PREFIXES:
        if f"{pre}_JOINT5_Link" not in links:
            raise UserError(
                f"{res.source.name}: no link {pre}_JOINT5_Link; the vendor option needs the Nextage's "
                "link names (NextageOpen.urdf of nextage_description)"
            )
        if f"{pre}_GRIPPER_Link" in links:
            raise UserError(
                f"{res.source.name}: {pre}_GRIPPER_Link already exists; give the vendor's file, not our nextage.urdf"
            )
    out_dir = res.path.parent
    for pre in ARM_PREFIXES:
        link = links[f"{pre}_JOINT5_Link"]
        for tag in ("collision", "visual"):
            for elem in link.findall(tag):
                mesh_e = elem.find("geometry/mesh")
                if mesh_e is None:
                    continue
                src = Path(mesh_e.get("filename", ""))
                scale = np.array([float(v) for v in mesh_e.get("scale", "1 1 1").split()])
                key = hashlib.sha256(f"{src}|{scale}|{GRIPPER.mount_x}".encode()).hexdigest()[:8]
                dst = out_dir / "meshes" / f"{src.stem}_arm_side_{key}.stl"
                if not dst.is_file():
                    mesh = trimesh.load(src, force="mesh")
                    mesh.apply_scale(scale)
                    cut = cut_at_flange(mesh, _origin(elem))
                    dst.parent.mkdir(parents=True, exist_ok=True)
                    tmp = dst.with_suffix(".tmp.stl")
                    cut.export(tmp)
                    tmp.replace(dst)
                mesh_e.set("filename", str(dst))
                mesh_e.set("scale", "1 1 1")
                o = elem.find("origin")
                if o is not None:  # the cut mesh is already in the link frame
                    o.set("xyz", "0 0 0")
                    o.set("rpy", "0 0 0")
    # our gripper's links name materials "gripper" and "finger"
    extra = "\n".join([*MATERIALS, *(x for pre in ARM_PREFIXES for x in gripper_xml(pre, f"{pre}_JOINT5_Link"))])
    for elem in ET.fromstring(f"<robot>{extra}</robot>"):
        root.append(elem)
    return write_urdf(root, out_dir / f"{res.source.stem}.with_gripper.urdf")
