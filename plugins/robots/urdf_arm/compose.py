"""One URDF for the robot cell a config describes: vendor URDFs, a generated gripper, a TCP frame.

A vendor's arm rarely comes exactly as the planners need it: its meshes are
named by ``package://`` URIs, it may have no gripper that opens and closes, its
tool frame may not follow :class:`HandSpec`'s convention, and a cell can hold
several arms. The source URDFs are never edited: :func:`compose_urdf` resolves
each (:func:`asmteach.core.urdf.resolve_urdf`, a content-keyed cache folder)
and writes the cell's URDF next to the first one, named by a hash of
everything that went into it. Additions, all in that written copy:

- an arm with its own ``urdf`` is copied in with every link, joint and material
  name prefixed ``<arm>_``, fixed to a root link ``cell_base`` at its ``base``
  pose (several UR5s in one cell);
- ``gripper``: a two-finger parallel gripper generated from
  :class:`GripperConfig` on a link of the arm (:mod:`.gripper`);
- ``tcp_offset``: a link ``<arm>_tcp`` fixed to ``tcp_link`` at that offset,
  for a tool frame that is not the HandSpec TCP.

Frames: URDF link frames; metres, radians.
"""

from __future__ import annotations

import hashlib
import json
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asmteach.core.errors import UserError
from asmteach.core.io import write_text
from asmteach.core.urdf import resolve_urdf as resolve_packages
from asmteach.core.urdf import write_urdf
from asmteach.plugins.robots.urdf_arm.gripper import GripperConfig, frame_link, gripper_elements, origin_xml

__all__ = ["CELL_ROOT", "ArmSource", "compose_urdf", "package_paths", "readable_source", "source_path"]

CELL_ROOT = "cell_base"
"""Root link of a composed cell (arms with their own URDF hang from it)."""

SCHEMES = ("pybullet_data:", "example-robot-data:", "erd:")


def _erd_share() -> Path:
    """``.../cmeel.prefix/share/example-robot-data`` of the installed ``example-robot-data`` wheel."""
    from importlib import metadata

    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise UserError("example-robot-data is not installed (pip install example-robot-data)") from None
    share = Path(str(dist.locate_file("cmeel.prefix/share/example-robot-data")))
    if not share.is_dir():
        raise UserError(f"example-robot-data is installed but {share} is missing")
    return share


def source_path(spec: str) -> Path:
    """The URDF file ``spec`` names: a path, ``pybullet_data:<rel>`` (PyBullet's data folder) or
    ``example-robot-data:<rel>`` / ``erd:<rel>`` (the ``robots`` folder of the example-robot-data wheel)."""
    if spec.startswith("pybullet_data:"):
        import pybullet_data

        return Path(pybullet_data.getDataPath()) / spec.split(":", 1)[1]
    if spec.startswith(("example-robot-data:", "erd:")):
        return _erd_share() / "robots" / spec.split(":", 1)[1]
    return Path(spec).expanduser()


def readable_source(spec: str) -> Path:
    """``source_path(spec)``, except that example-robot-data's URDFs get a copy whose
    ``package://example-robot-data/`` URIs are absolute paths: the wheel's ``package.xml`` names the
    package ``example_robot_descriptions``, so no ROS package lookup finds the name the URDFs use.
    The copy goes to the system temp folder, named by a hash of its text."""
    src = source_path(spec)
    if not spec.startswith(("example-robot-data:", "erd:")) or not src.is_file():
        return src
    prefix = "package://example-robot-data/"
    text = src.read_text(encoding="utf-8").replace(prefix, f"{_erd_share().as_posix()}/")
    out = (
        Path(tempfile.gettempdir())
        / "asmteach_erd"
        / f"{src.stem}_{hashlib.sha256(text.encode()).hexdigest()[:16]}.urdf"
    )
    if not out.is_file():
        write_text(out, text)
    return out


def package_paths(spec: str) -> list[Path]:
    """Where ``package://NAME/...`` URIs of ``spec`` are looked up: the wheel's share folder for
    example-robot-data, then the URDF's own folder (PyBullet's own lookup: pybullet_data's Panda names
    ``package://meshes/...``, its sibling folder)."""
    erd = [_erd_share().parent] if spec.startswith(("example-robot-data:", "erd:")) else []
    return [*erd, source_path(spec).parent]


@dataclass(frozen=True)
class ArmSource:
    """What :func:`compose_urdf` needs of one arm (names as in the arm's own URDF)."""

    name: str
    urdf: str | None  # this arm's own URDF (prefixed into the cell), or None: the arm is in the main URDF
    base: np.ndarray  # T_cell_root of the arm's own URDF (4x4, metres)
    tcp_link: str | None
    tcp_offset: np.ndarray | None  # T_tcplink_tcp (4x4, metres)
    gripper: GripperConfig | None


def _prefix_tree(root: ET.Element, prefix: str) -> list[ET.Element]:
    """The URDF's top-level elements with every link, joint and material name prefixed."""
    out = []
    for e in root:
        if e.tag in ("link", "joint", "material"):
            e.set("name", prefix + e.get("name", ""))
        if e.tag == "joint":
            for tag in ("parent", "child"):
                ref = e.find(tag)
                if ref is not None:
                    ref.set("link", prefix + ref.get("link", ""))
            mimic = e.find("mimic")
            if mimic is not None:
                mimic.set("joint", prefix + mimic.get("joint", ""))
        if e.tag == "link":
            for m in e.iter("material"):
                if m.get("name"):
                    m.set("name", prefix + m.get("name", ""))
        if e.tag in ("link", "joint", "material"):
            out.append(e)
    return out


def _root_link(root: ET.Element, source: str) -> str:
    links = [e.get("name", "") for e in root.findall("link")]
    children = {c.get("link") for c in root.iter("child")}
    roots = [n for n in links if n not in children]
    if len(roots) != 1:
        raise UserError(f"{source}: expected one root link, found {roots or 'none'}")
    return roots[0]


def _fixed_joint(name: str, parent: str, child: str, T: np.ndarray) -> ET.Element:
    return ET.fromstring(
        f'<joint name="{name}" type="fixed">{origin_xml(T)}<parent link="{parent}"/><child link="{child}"/></joint>'
    )


def _hull_collision_meshes(root: ET.Element, out_dir: Path) -> None:
    """Point every STL collision mesh at its convex hull (written once into ``out_dir/meshes``).

    PyBullet collides a moving link's STL mesh as its convex hull; the planner's fcl checks the mesh
    itself. With a vendor's concave links (a UR5's upper arm) the two disagree by centimetres, and a plan
    the planner finds free runs one arm into the other in the simulator. With the hull in the URDF both
    see the same solid (the planner errs on the safe side, as the simulator does)."""
    import trimesh

    for col in root.iter("collision"):
        mesh_e = col.find("geometry/mesh")
        if mesh_e is None or not mesh_e.get("filename", "").lower().endswith(".stl"):
            continue
        src = Path(mesh_e.get("filename", ""))
        dst = out_dir / "meshes" / f"{src.stem}_hull_{hashlib.sha256(src.read_bytes()).hexdigest()[:12]}.stl"
        if not dst.is_file():
            dst.parent.mkdir(parents=True, exist_ok=True)
            tmp = dst.with_suffix(".tmp.stl")
            trimesh.load(src, force="mesh").convex_hull.export(tmp)
            tmp.replace(dst)  # atomic: another process may be writing the same hull
        mesh_e.set("filename", str(dst))


def compose_urdf(urdf: str, arms: list[ArmSource], *, convex_collision: bool = False) -> Path:
    """Path of the URDF of the cell: ``urdf`` (may be empty when every arm has its own) plus the arms'
    own URDFs, generated grippers and TCP frames. Written once into the URDF cache, keyed by its inputs.

    Link names afterwards: an arm's own URDF is prefixed ``<arm>_``; a generated gripper adds
    ``<arm>_gripper``, ``<arm>_finger0/1`` and the TCP ``<arm>_gripper_tcp``; a TCP offset adds ``<arm>_tcp``.
    ``convex_collision``: STL collision meshes become their convex hulls (:func:`_hull_collision_meshes`).
    """
    key = hashlib.sha256()
    resolved: dict[str, Path] = {}
    for spec in [urdf, *(a.urdf for a in arms if a.urdf)]:
        if spec and spec not in resolved:
            src = readable_source(spec)
            if not src.is_file():
                raise UserError(f"{src}: no such URDF file")
            resolved[spec] = resolve_packages(src, package_paths(spec)).path
            key.update(resolved[spec].read_bytes())
    if not resolved:
        raise UserError("no URDF: give urdf, or a urdf for every arm")
    key.update(json.dumps([[_describe(a) for a in arms], convex_collision], sort_keys=True).encode())
    if urdf:
        root = ET.parse(resolved[urdf]).getroot()
    else:
        root = ET.Element("robot", name="cell")
    own = [a for a in arms if a.urdf]
    if own:
        main_root = _root_link(root, urdf) if urdf else None
        root.append(frame_link(CELL_ROOT))
        if main_root is not None:
            root.append(_fixed_joint(f"{CELL_ROOT}_to_{main_root}", CELL_ROOT, main_root, np.eye(4)))
        for a in own:
            sub = ET.parse(resolved[a.urdf]).getroot()
            sub_root = _root_link(sub, a.urdf or "")
            for e in _prefix_tree(sub, f"{a.name}_"):
                root.append(e)
            root.append(_fixed_joint(f"{CELL_ROOT}_to_{a.name}", CELL_ROOT, f"{a.name}_{sub_root}", a.base))
    links = {e.get("name") for e in root.findall("link")}
    for a in arms:
        pre = f"{a.name}_" if a.urdf else ""
        if a.gripper is not None:
            parent = pre + a.gripper.parent
            if parent not in links:
                raise UserError(f"arm {a.name!r}: gripper.parent {a.gripper.parent!r} is not a link of the URDF")
            for e in gripper_elements(a.name, parent, a.gripper):
                root.append(e)
        if a.tcp_offset is not None:
            if pre + (a.tcp_link or "") not in links:
                raise UserError(f"arm {a.name!r}: tcp_link {a.tcp_link!r} is not a link of the URDF")
            root.append(frame_link(f"{a.name}_tcp"))
            root.append(_fixed_joint(f"{a.name}_tcp_joint", pre + (a.tcp_link or ""), f"{a.name}_tcp", a.tcp_offset))
    plain = not own and all(a.gripper is None and a.tcp_offset is None for a in arms)
    if plain and urdf and not convex_collision:
        return resolved[urdf]
    out_dir = next(iter(resolved.values())).parent
    if convex_collision:
        _hull_collision_meshes(root, out_dir)
    out = out_dir / f"cell_{key.hexdigest()[:16]}.urdf"
    return write_urdf(root, out)


def _describe(a: ArmSource) -> dict:
    return {
        "name": a.name,
        "urdf": a.urdf,
        "base": np.round(a.base, 9).tolist(),
        "tcp_link": a.tcp_link,
        "tcp_offset": None if a.tcp_offset is None else np.round(a.tcp_offset, 9).tolist(),
        "gripper": None if a.gripper is None else a.gripper.model_dump(mode="json"),
        "v": 1,
    }
