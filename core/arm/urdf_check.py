"""Checks a URDF before pinocchio or PyBullet see it, so a bad file gets a clear message.

Both libraries either crash or print C++ errors on malformed files; here every
problem becomes one :class:`UserError` naming the file, the element and the
fix (``"arm.urdf: <joint name='j2'> <limit>: lower 1.0 > upper 0.5"``).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

from asmteach.core.errors import UserError

__all__ = ["UrdfInfo", "check_urdf", "resolve_mesh"]

JOINT_TYPES = {"revolute", "continuous", "prismatic", "fixed", "floating", "planar"}


@dataclass
class UrdfInfo:
    """What the rest of the robot code needs from a URDF's text."""

    path: Path
    name: str
    links: list[str]
    joints: dict[str, dict[str, str]]  # name -> {type, parent, child}
    root: str
    adjacent: set[frozenset[str]] = field(default_factory=set)
    """Link pairs joined by a joint (parent, child): never checked against each other."""


def _numbers(text: str | None, n: int, where: str) -> list[float]:
    parts = (text or "").split()
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise UserError(f"{where}: {text!r} is not a list of numbers") from None
    if len(vals) != n:
        raise UserError(f"{where}: expected {n} numbers, got {len(vals)} ({text!r})")
    return vals


def resolve_mesh(filename: str, urdf_dir: Path) -> Path:
    """Path of a mesh named in a URDF (``package://`` resolved against the URDF's folder and its parents)."""
    if filename.startswith("package://"):
        rel = filename[len("package://") :]
        for base in (urdf_dir, *urdf_dir.parents):
            cand = base / rel
            if cand.is_file():
                return cand
            cand = base / rel.split("/", 1)[-1]
            if cand.is_file():
                return cand
        return urdf_dir / rel
    if filename.startswith("file://"):
        filename = filename[len("file://") :]
    p = Path(filename)
    return p if p.is_absolute() else urdf_dir / p


def _check_geometry(elem: ET.Element, where: str, urdf_dir: Path) -> None:
    geom = elem.find("geometry")
    if geom is None or len(geom) != 1:
        raise UserError(f"{where}: needs one <geometry> with exactly one shape (box, cylinder, sphere or mesh)")
    shape = geom[0]
    if shape.tag == "box":
        size = _numbers(shape.get("size"), 3, f"{where} <box size>")
        if min(size) <= 0:
            raise UserError(f"{where} <box>: every size must be > 0, got {size}")
    elif shape.tag == "cylinder":
        r = _numbers(shape.get("radius"), 1, f"{where} <cylinder radius>")[0]
        ln = _numbers(shape.get("length"), 1, f"{where} <cylinder length>")[0]
        if r <= 0 or ln <= 0:
            raise UserError(f"{where} <cylinder>: radius and length must be > 0")
    elif shape.tag == "sphere":
        _numbers(shape.get("radius"), 1, f"{where} <sphere radius>")
    elif shape.tag == "mesh":
        fn = shape.get("filename")
        if not fn:
            raise UserError(f"{where} <mesh>: the filename attribute is missing")
        if not resolve_mesh(fn, urdf_dir).is_file():
            raise UserError(f"{where} <mesh filename={fn!r}>: no such file next to the URDF")
    else:
        raise UserError(f"{where}: unknown geometry <{shape.tag}>; use box, cylinder, sphere or mesh")
    origin = elem.find("origin")
    if origin is not None:
        _numbers(origin.get("xyz", "0 0 0"), 3, f"{where} <origin xyz>")
        _numbers(origin.get("rpy", "0 0 0"), 3, f"{where} <origin rpy>")


def check_urdf(path: str | Path) -> UrdfInfo:
    """Parse and validate ``path``; :class:`UserError` names the file and the faulty element."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{p}: no such URDF file")
    try:
        root = ET.parse(p).getroot()
    except ET.ParseError as exc:
        line, col = exc.position
        raise UserError(f"{p}: not well-formed XML at line {line}, column {col + 1}: {exc.msg}") from None
    if root.tag != "robot":
        raise UserError(f"{p}: the root element is <{root.tag}>, a URDF needs <robot>")
    name = root.get("name") or p.stem
    links: list[str] = []
    for k, link in enumerate(root.findall("link")):
        ln = link.get("name")
        if not ln:
            raise UserError(f"{p}: <link> number {k + 1} has no name attribute")
        if ln in links:
            raise UserError(f"{p}: <link name={ln!r}> is defined twice")
        links.append(ln)
        for tag in ("visual", "collision"):
            for elem in link.findall(tag):
                _check_geometry(elem, f"{p.name}: <link name={ln!r}> <{tag}>", p.parent)
        inertial = link.find("inertial")
        if inertial is not None:
            mass = inertial.find("mass")
            if mass is None or mass.get("value") is None:
                raise UserError(f"{p.name}: <link name={ln!r}> <inertial>: <mass value=...> is missing")
            _numbers(mass.get("value"), 1, f"{p.name}: <link name={ln!r}> <mass value>")
    if not links:
        raise UserError(f"{p}: the URDF has no <link>")
    joints: dict[str, dict[str, str]] = {}
    children: set[str] = set()
    adjacent: set[frozenset[str]] = set()
    for k, joint in enumerate(root.findall("joint")):
        jn = joint.get("name")
        where = f"{p.name}: <joint name={jn!r}>"
        if not jn:
            raise UserError(f"{p}: <joint> number {k + 1} has no name attribute")
        if jn in joints:
            raise UserError(f"{where} is defined twice")
        jt = joint.get("type")
        if jt not in JOINT_TYPES:
            raise UserError(f"{where}: type {jt!r} is not one of {sorted(JOINT_TYPES)}")
        ends = {}
        for tag in ("parent", "child"):
            e = joint.find(tag)
            lk = e.get("link") if e is not None else None
            if not lk:
                raise UserError(f"{where}: <{tag} link=...> is missing")
            if lk not in links:
                raise UserError(f"{where} <{tag} link={lk!r}>: no such link in the file")
            ends[tag] = lk
        if ends["child"] in children:
            raise UserError(f"{where}: link {ends['child']!r} already has a parent joint")
        children.add(ends["child"])
        origin = joint.find("origin")
        if origin is not None:
            _numbers(origin.get("xyz", "0 0 0"), 3, f"{where} <origin xyz>")
            _numbers(origin.get("rpy", "0 0 0"), 3, f"{where} <origin rpy>")
        if jt in ("revolute", "prismatic"):
            lim = joint.find("limit")
            if lim is None or lim.get("lower") is None or lim.get("upper") is None:
                raise UserError(f"{where}: a {jt} joint needs <limit lower=... upper=...>")
            lo = _numbers(lim.get("lower"), 1, f"{where} <limit lower>")[0]
            hi = _numbers(lim.get("upper"), 1, f"{where} <limit upper>")[0]
            if lo > hi:
                raise UserError(f"{where} <limit>: lower {lo} > upper {hi}")
        axis = joint.find("axis")
        if axis is not None and jt in ("revolute", "prismatic", "continuous"):
            ax = _numbers(axis.get("xyz"), 3, f"{where} <axis xyz>")
            if sum(a * a for a in ax) < 1e-12:
                raise UserError(f"{where} <axis>: the axis is zero")
        joints[jn] = {"type": jt, **ends}
        adjacent.add(frozenset((ends["parent"], ends["child"])))
    roots = [ln for ln in links if ln not in children]
    if len(roots) != 1:
        raise UserError(f"{p}: the links must form one tree; found {len(roots)} roots {roots[:5]}")
    return UrdfInfo(path=p, name=name, links=links, joints=joints, root=roots[0], adjacent=adjacent)
