"""URDFs as robot vendors ship them: ``package://`` mesh URIs, stray xacro lines, COLLADA meshes.

A vendor's ROS package (e.g. ``nextage_description``) names its meshes
``package://nextage_description/urdf/meshes/X.dae``, may keep an
``<xacro:include .../>`` line and xacro macro calls in a file that is otherwise
plain URDF, and ships COLLADA meshes that neither pinocchio (without assimp)
nor PyBullet's collision loader reads reliably. :func:`resolve_urdf` does the
work once and writes a *resolved* URDF that both read:

1. every element in the xacro namespace is removed, with one warning naming
   how many and which (a plain URDF reader cannot expand them; a file whose
   links or joints come from a macro is refused by the URDF check later);
2. each ``package://NAME/rel`` is looked up: ``NAME`` is the folder holding a
   ``package.xml`` whose ``<name>`` is NAME, searched in the given package
   paths (each may be a package folder itself or a folder of packages, two
   levels deep) and then in the URDF's own folder and its parents; a folder
   simply called NAME also counts (ROS's own convention). A missing package is
   a :class:`UserError` naming it and the folders searched;
3. each mesh that is not STL or OBJ (COLLADA ``.dae``, PLY, ...) is loaded with
   trimesh (COLLADA needs ``pycollada``) and written as binary STL next to the
   resolved URDF; mesh ``filename`` attributes become absolute paths.

The output goes to a cache folder keyed by the content of the URDF and of
every mesh it names, so a second call is a file lookup. Units are untouched
(COLLADA ``<unit>`` is applied by trimesh's loader; URDF ``scale`` stays).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from asmteach.core.errors import UserError
from asmteach.core.io import write_text

__all__ = ["ResolvedUrdf", "find_package", "package_name", "resolve_urdf", "resolve_uri", "strip_xacro", "write_urdf"]

XACRO_NS = "http://www.ros.org/wiki/xacro"
NATIVE_MESHES = {".stl", ".obj"}
"""Mesh formats that pinocchio and PyBullet both read as they are."""


@dataclass
class ResolvedUrdf:
    """A URDF whose mesh paths are absolute files that pinocchio and PyBullet read.

    ``path`` is the resolved URDF; ``meshes`` maps each original ``filename``
    attribute to the file it now names; ``packages`` the package folders used;
    ``stripped`` the xacro tags removed.
    """

    source: Path
    path: Path
    meshes: dict[str, Path] = field(default_factory=dict)
    packages: dict[str, Path] = field(default_factory=dict)
    stripped: list[str] = field(default_factory=list)


def package_name(folder: Path) -> str | None:
    """The ``<name>`` in ``folder/package.xml``, or None when there is none (or it is unreadable)."""
    px = Path(folder) / "package.xml"
    if not px.is_file():
        return None
    try:
        name = ET.parse(px).getroot().findtext("name")
    except ET.ParseError:
        return None
    return name.strip() if name else None


def _candidates(base: Path, depth: int) -> list[Path]:
    out = [base]
    level = [base]
    for _ in range(depth):
        nxt: list[Path] = []
        for d in level:
            try:
                nxt += sorted(c for c in d.iterdir() if c.is_dir() and not c.name.startswith("."))
            except OSError:
                continue
        out += nxt
        level = nxt
    return out


def find_package(name: str, package_paths: Sequence[str | Path] = (), start: Path | None = None) -> Path:
    """Folder of ROS package ``name``.

    Searched, in order: each of ``package_paths`` and its sub-folders two levels
    deep, then ``start`` and its parents (the URDF's folder: a package usually
    holds its own URDF). A folder matches when its ``package.xml`` names ``name``,
    or, without a ``package.xml``, when the folder itself is called ``name``.
    """
    tried: list[str] = []
    for raw in package_paths:
        base = Path(raw).expanduser()
        tried.append(str(base))
        if not base.is_dir():
            continue
        for cand in _candidates(base, 2):
            pn = package_name(cand)
            if pn == name or (pn is None and cand.name == name):
                return cand
    if start is not None:
        for cand in (start, *start.parents):
            tried.append(str(cand))
            if package_name(cand) == name:
                return cand
    raise UserError(
        f"package {name!r} not found (no package.xml naming it in {', '.join(tried) or 'nothing'}); "
        "add its folder to package_paths"
    )


def resolve_uri(
    uri: str, base_dir: Path, package_paths: Sequence[str | Path] = (), packages: dict[str, Path] | None = None
) -> Path:
    """File named by a URDF ``filename``: ``package://NAME/rel``, ``file://abs`` or a path relative to ``base_dir``."""
    if uri.startswith("package://"):
        rest = uri[len("package://") :]
        name, _, rel = rest.partition("/")
        cache = packages if packages is not None else {}
        if name not in cache:
            cache[name] = find_package(name, package_paths, base_dir)
        return cache[name] / rel
    if uri.startswith("file://"):
        uri = uri[len("file://") :]
    p = Path(uri).expanduser()
    return p if p.is_absolute() else base_dir / p


def strip_xacro(root: ET.Element) -> list[str]:
    """Remove every element in the xacro namespace (at any depth); returns their tags (``xacro:include``...)."""
    removed: list[str] = []
    prefix = "{" + XACRO_NS + "}"
    for parent in root.iter():
        for child in list(parent):
            if isinstance(child.tag, str) and child.tag.startswith(prefix):
                parent.remove(child)
                removed.append("xacro:" + child.tag[len(prefix) :])
    return removed


def _cache_root() -> Path:
    return Path(os.environ.get("ASMTEACH_URDF_CACHE", Path(tempfile.gettempdir()) / "asmteach_urdf"))


def _digest(h: hashlib._Hash, path: Path) -> None:
    h.update(str(path).encode())
    h.update(path.read_bytes())


def _convert_mesh(src: Path, dst: Path) -> None:
    import trimesh  # local: the core imports trimesh lazily elsewhere too

    try:
        mesh = trimesh.load(src, force="mesh")
    except Exception as exc:  # noqa: BLE001 - trimesh raises many kinds (pycollada missing, bad XML)
        hint = " (COLLADA needs the pycollada package: pip install pycollada)" if src.suffix.lower() == ".dae" else ""
        raise UserError(f"{src}: cannot load the mesh{hint}: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise UserError(f"{src}: the mesh has no triangles")
    tmp = dst.with_suffix(".tmp.stl")
    mesh.export(tmp)
    tmp.replace(dst)  # atomic: two processes converting the same file do not see half a file


def resolve_urdf(
    urdf: str | Path, package_paths: Sequence[str | Path] = (), *, out_dir: str | Path | None = None
) -> ResolvedUrdf:
    """Write a resolved copy of ``urdf`` (see the module doc) and return where it is.

    ``out_dir`` defaults to a cache folder (``$ASMTEACH_URDF_CACHE`` or the
    system temp folder) keyed by the URDF's and its meshes' content.
    """
    src = Path(urdf).expanduser().resolve()
    if not src.is_file():
        raise UserError(f"{src}: no such URDF file")
    try:
        tree = ET.parse(src)
    except ET.ParseError as exc:
        line, col = exc.position
        raise UserError(f"{src}: not well-formed XML at line {line}, column {col + 1}: {exc.msg}") from None
    root = tree.getroot()
    stripped = strip_xacro(root)
    if stripped:
        kinds = sorted(set(stripped))
        warnings.warn(
            f"{src.name}: removed {len(stripped)} xacro element(s) ({', '.join(kinds)}); a URDF reader "
            "cannot expand them (run xacro first if links or joints come from macros)",
            stacklevel=2,
        )
    packages: dict[str, Path] = {}
    mesh_elems = [e for e in root.iter("mesh") if e.get("filename")]
    sources: dict[str, Path] = {}
    for e in mesh_elems:
        uri = e.get("filename", "")
        if uri not in sources:
            p = resolve_uri(uri, src.parent, package_paths, packages)
            if not p.is_file():
                raise UserError(f"{src.name}: mesh {uri!r} resolves to {p}, which does not exist")
            sources[uri] = p.resolve()
    h = hashlib.sha256()
    _digest(h, src)
    for p in sorted(set(sources.values())):
        _digest(h, p)
    out = Path(out_dir) if out_dir is not None else _cache_root() / h.hexdigest()[:16]
    out.mkdir(parents=True, exist_ok=True)
    meshes: dict[str, Path] = {}
    for uri, p in sources.items():
        if p.suffix.lower() in NATIVE_MESHES:
            meshes[uri] = p
            continue
        # one STL per source file; the name keeps a short hash so equal stems from two packages do not clash
        tag = hashlib.sha256(str(p).encode()).hexdigest()[:8]
        dst = out / "meshes" / f"{p.stem}_{tag}.stl"
        if not dst.is_file():
            dst.parent.mkdir(parents=True, exist_ok=True)
            _convert_mesh(p, dst)
        meshes[uri] = dst
    for e in mesh_elems:
        e.set("filename", str(meshes[e.get("filename", "")]))
    ET.register_namespace("xacro", XACRO_NS)
    dst_urdf = write_urdf(root, out / f"{src.stem}.resolved.urdf")
    return ResolvedUrdf(source=src, path=dst_urdf, meshes=meshes, packages=packages, stripped=stripped)


def write_urdf(root: ET.Element, path: Path) -> Path:
    """Write the URDF tree ``root`` to ``path`` atomically, unless the file already holds the same text.

    Unchanged files are left alone, so pinocchio and PyBullet in other processes never see one half-written.
    """
    text = ET.tostring(root, encoding="unicode")
    if not path.is_file() or path.read_text(encoding="utf-8") != text:
        write_text(path, text)
    return path
