"""Part library: parametric solids and mesh files into :class:`PartModel`.

A part YAML holds one :class:`~asmteach.core.models.PartSpec`; a structure
YAML holds an :class:`~asmteach.core.models.AssemblyTask` whose ``part_a`` and
``part_b`` may be paths to part YAMLs (resolved relative to the structure
file). Solids are built with trimesh's boolean engine (manifold3d).
"""

from __future__ import annotations

import hashlib
import logging
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from pydantic import ValidationError

from asmteach.core.config import check_finite, format_validation_error
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.io import read_yaml
from asmteach.core.mesh_repair import repair_mesh
from asmteach.core.models import AssemblyTask, PartSpec, Primitive, SolidSpec, resolve_relative

__all__ = [
    "MESH_SUFFIXES",
    "build_cloud_part",
    "build_part",
    "build_solid",
    "is_cloud_file",
    "load_mesh_file",
    "load_part_spec",
    "load_parts",
    "load_structure",
    "mesh_hash",
]

log = logging.getLogger(__name__)

# Parts of this library are 10 mm to 1 m; a mesh whose largest extent is
# above this is almost surely written in millimetres.
MAX_EXTENT_M = 2.0
MIN_EXTENT_M = 0.002
MESH_SUFFIXES = frozenset({".stl", ".obj", ".ply", ".off", ".glb", ".gltf"})


def _primitive_mesh(p: Primitive) -> trimesh.Trimesh:
    if p.shape == "box":
        m = trimesh.creation.box(extents=p.size)
    else:
        m = trimesh.creation.cylinder(radius=p.radius, height=p.height, sections=64)
    m.apply_transform(p.pose)
    return m


def build_solid(solid: SolidSpec) -> trimesh.Trimesh:
    """Mesh of ``union(add) - union(subtract)`` (part frame, metres)."""
    add = [_primitive_mesh(p) for p in solid.add]
    mesh = add[0] if len(add) == 1 else trimesh.boolean.union(add, engine="manifold")
    if solid.subtract:
        cut = [_primitive_mesh(p) for p in solid.subtract]
        mesh = trimesh.boolean.difference([mesh, *cut], engine="manifold")
    mesh.merge_vertices()
    if not mesh.is_watertight or mesh.volume <= 0:
        raise UserError("the parametric solid is empty or not closed; check that subtract does not remove all of add")
    return mesh


def load_mesh_file(path: Path, units: str = "m") -> trimesh.Trimesh:
    """Load an STL/OBJ/PLY mesh in metres; refuses millimetres given as metres.

    Small defects (open edges, flipped faces, an inverted shell) are repaired
    by :func:`asmteach.core.mesh_repair.repair_mesh`, with a warning naming
    each change; a mesh whose holes cannot be closed is refused with where
    the hole is (mass, placements and collision pieces need a closed surface).
    """
    if not path.is_file():
        raise UserError(f"mesh file {path} does not exist")
    try:
        loaded = trimesh.load(path, force="mesh")
    except Exception as exc:  # noqa: BLE001 - any loader failure is a bad file
        raise UserError(f"{path}: cannot read the mesh ({type(exc).__name__}: {exc})") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise UserError(f"{path}: the file holds no triangles")
    mesh = loaded
    if units == "mm":
        mesh.apply_scale(0.001)
    ext = float(np.max(mesh.extents))
    if ext > MAX_EXTENT_M:
        raise UserError(
            f"{path}: the mesh is {ext:.0f} units across; it looks like millimetres. "
            "Set mesh_units: mm (or pass --units mm) so it is scaled to metres"
        )
    if ext < MIN_EXTENT_M:
        raise UserError(f"{path}: the mesh is only {ext * 1000:.3f} mm across; it is degenerate or in the wrong units")
    mesh, notes = repair_mesh(mesh, name=str(path))
    for note in notes:
        log.warning("%s: %s", path.name, note)
    return mesh


def _inside_hull(mesh: trimesh.Trimesh, point: np.ndarray, tol: float = 1e-9) -> bool:
    """Whether ``point`` (metres) lies in the mesh's convex hull: every hull facet's half-space holds it."""
    from scipy.spatial import ConvexHull

    eq = ConvexHull(np.asarray(mesh.vertices, dtype=float)).equations  # rows [n, d]: n . x + d <= 0 inside
    return bool(np.all(eq[:, :3] @ np.asarray(point, dtype=float) + eq[:, 3] <= tol))


def mesh_hash(mesh: trimesh.Trimesh) -> str:
    """Stable hash of a mesh's geometry (vertices to 0.1 um, faces), for caches."""
    h = hashlib.sha256()
    h.update(np.round(np.asarray(mesh.vertices), 7).astype("<f8").tobytes())
    h.update(np.asarray(mesh.faces).astype("<i8").tobytes())
    return h.hexdigest()[:16]


def is_cloud_file(path: Path) -> bool:
    """Whether ``path`` is a point cloud (PCD, XYZ, a PLY without faces), not a mesh."""
    from asmteach.core.clouds import CLOUD_SUFFIXES

    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        return False
    if suffix != ".ply":
        return True
    try:
        with path.open("rb") as fh:
            head = fh.read(65536)
    except OSError:
        return False
    for raw in head.split(b"\n"):
        words = raw.decode("ascii", errors="replace").split()
        if words[:2] == ["element", "face"]:
            return len(words) > 2 and words[2] == "0"
        if words[:1] == ["end_header"]:
            break
    return True


def build_cloud_part(spec: PartSpec, path: Path) -> PartModel:
    """A part given as a scan: its points (the file's frame is the part frame, metres) and their convex hull.

    The hull stands in for the mesh (size, bounds, a nominal mass); the points are what a detector that
    takes cloud models matches. The scanner's centre comes from the file (a PCD ``VIEWPOINT``, a PLY
    ``comment viewpoint``) or, for a cloud in a camera's frame (every point at z > 0), the origin.
    """
    from scipy.spatial import QhullError

    from asmteach.core.clouds import read_cloud

    cloud = read_cloud(path, units=spec.mesh_units, kind="part", what=f"part {spec.name!r}")
    pts = cloud.valid_points()
    if len(pts) < 100:
        raise UserError(f"{path}: a part's scan needs at least 100 valid points, it has {len(pts)}")
    eye = cloud.viewpoint
    if eye is None and np.all(pts[:, 2] > 0):
        eye = np.zeros(3)  # a sensor's own frame: the scanner is at the origin
    # Thickness across the points' best plane: a scan of one flat face holds no shape to match.
    centred = pts - pts.mean(axis=0)
    thickness = float(np.ptp(centred @ np.linalg.svd(centred, full_matrices=False)[2][2]))
    try:
        if thickness < MIN_EXTENT_M:
            raise QhullError
        hull = trimesh.convex.convex_hull(pts)
    except QhullError:
        raise UserError(
            f"{path}: the scan is flat (within {MIN_EXTENT_M * 1000:.0f} mm of a plane); a part's scan must show its "
            "shape"
        ) from None
    ext = float(np.max(hull.extents))
    if ext < MIN_EXTENT_M:
        raise UserError(f"{path}: the scan is only {ext * 1000:.3f} mm across; it is degenerate or in the wrong units")
    h = hashlib.sha256(np.round(pts, 7).astype("<f8").tobytes()).hexdigest()[:16]
    mass = spec.mass if spec.mass is not None else spec.density * float(hull.volume)
    com = np.asarray(spec.center_of_mass if spec.center_of_mass is not None else hull.center_mass, dtype=float)
    for note in cloud.notes:
        log.warning("%s: %s", path.name, note)
    return PartModel(
        spec=spec,
        mesh=hull,
        mass=float(mass),
        center_of_mass=com,
        source_hash=f"scan-{h}",
        points=pts,
        scan_viewpoint=eye,
    )


def build_part(spec: PartSpec, base_dir: Path | None = None, *, scans: bool = False) -> PartModel:
    """Mesh, mass and centre of mass of a part spec.

    A ``mesh`` that is a point cloud is a part given as a scan (:func:`build_cloud_part`): taken only with
    ``scans`` (``asmteach detect``); everything else (placements, grasps, planning) needs a closed mesh and
    gets a one-line :class:`UserError` saying so.
    """
    if spec.mesh is not None and is_cloud_file(resolve_relative(spec.mesh, base_dir or Path.cwd())):
        path = resolve_relative(spec.mesh, base_dir or Path.cwd())
        if not scans:
            raise UserError(
                f"part {spec.name!r}: {path.name} is a point cloud (a scan); only `asmteach detect` takes a part "
                "given as a scan (placements, grasps and planning need a closed mesh): give the part's mesh"
            )
        return build_cloud_part(spec, path)
    if spec.solid is not None:
        mesh = build_solid(spec.solid)
    else:
        mesh = load_mesh_file(resolve_relative(spec.mesh or "", base_dir or Path.cwd()), spec.mesh_units)
    volume = float(mesh.volume)
    mass = spec.mass if spec.mass is not None else spec.density * volume
    if spec.center_of_mass is not None:
        com = np.asarray(spec.center_of_mass, dtype=float)
        if not _inside_hull(mesh, com):
            raise UserError(
                f"part {spec.name!r}: center_of_mass {com.tolist()} m lies outside the part's convex hull; "
                "give it in the part frame in metres"
            )
    else:
        com = np.asarray(mesh.center_mass, dtype=float)
    return PartModel(spec=spec, mesh=mesh, mass=float(mass), center_of_mass=com, source_hash=mesh_hash(mesh))


def _validate(model: type, data: Any, path: Path) -> Any:
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        raise UserError(f"{path}: {format_validation_error(exc)}") from None


def load_part_spec(path: str | Path) -> PartSpec:
    """Read a part YAML; a ``mesh`` path in it is made absolute (relative to the part file's folder)."""
    p = Path(path)
    raw = read_yaml(p)
    check_finite(raw, str(p))
    spec = _validate(PartSpec, raw, p)
    if spec.mesh is not None:
        spec.mesh = str(resolve_relative(spec.mesh, p.resolve().parent))
    return spec


def load_structure(path: str | Path) -> AssemblyTask:
    """Read a structure YAML (an assembly task with ground truth).

    Path rule, the same for every command (``run``, ``validate``, ``teach``,
    ``render-demo``, ``placements``, ``detect``): a path is resolved against
    the folder of the file that names it. ``part_a: parts/a.yaml`` is relative
    to the structure file; a ``mesh`` inside that part file is relative to the
    part file; a ``mesh`` of a part written inline is relative to the
    structure file. The returned specs hold absolute mesh paths, so no later
    step depends on the working directory.
    """
    p = Path(path)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: a structure must be a YAML mapping")
    check_finite(raw, str(p))
    base = p.resolve().parent
    for key in ("part_a", "part_b"):
        if isinstance(raw.get(key), str):
            raw[key] = load_part_spec(resolve_relative(raw[key], base)).model_dump()
        elif isinstance(raw.get(key), dict) and isinstance(raw[key].get("mesh"), str):
            raw[key] = {**raw[key], "mesh": str(resolve_relative(raw[key]["mesh"], base))}
    return _validate(AssemblyTask, raw, p)


def load_parts(
    source: str | Path,
    *,
    units: str = "m",
    select: str | None = None,
    center_of_mass: np.ndarray | None = None,
    scans: bool = False,
) -> list[PartModel]:
    """Parts named on a command line: a mesh file, a part YAML or a structure YAML.

    A structure gives its two parts, or only ``select`` (``"a"``, ``"b"`` or a
    part name). ``units`` applies to mesh files; ``center_of_mass`` (part
    frame, metres) overrides the solid's, for a single part only. ``scans``
    lets a point cloud stand for a part (:func:`build_part`).
    """
    path = Path(source)
    if not path.is_file():
        raise UserError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix in MESH_SUFFIXES or is_cloud_file(path):
        try:
            spec = PartSpec(name=path.stem, mesh=str(path.resolve()), mesh_units=units, center_of_mass=center_of_mass)
        except ValidationError as exc:
            raise UserError(f"--com: {format_validation_error(exc)}") from None
        return [build_part(spec, scans=scans)]
    if suffix not in (".yaml", ".yml"):
        raise UserError(
            f"{path}: not a mesh ({', '.join(sorted(MESH_SUFFIXES))}), a point cloud (.pcd, .xyz) nor a part/structure "
            "YAML"
        )
    raw = read_yaml(path)
    base = path.resolve().parent
    if isinstance(raw, dict) and "part_a" in raw:
        if center_of_mass is not None:
            raise UserError("a centre of mass applies to one part; a structure file has two (set it in its YAML)")
        task = load_structure(path)
        specs = {"a": task.part_a, "b": task.part_b}
        if select is not None:
            specs = {k: s for k, s in specs.items() if select in (k, s.name)}
            if not specs:
                names = f"a ({task.part_a.name}), b ({task.part_b.name})"
                raise UserError(f"{select!r} is not a part of {path.name}; choose one of {names}")
        return [build_part(s, base, scans=scans) for s in specs.values()]
    spec = load_part_spec(path)
    if center_of_mass is not None:
        spec = spec.model_copy(update={"center_of_mass": np.asarray(center_of_mass, dtype=float)})
    return [build_part(spec, base, scans=scans)]
