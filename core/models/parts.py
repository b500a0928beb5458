"""Parts: their geometry (a constructive solid or a mesh file), physical properties and markers (metres, kg)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from asmteach.core.models.base import Mat4, StrictModel, Unit, Vec3

__all__ = ["MarkerSpec", "PartSpec", "Primitive", "SolidSpec", "resolve_relative"]


class MarkerSpec(StrictModel):
    """An ArUco marker glued to a part face.

    The marker frame is OpenCV's: origin at the marker centre, z out of the
    printed face, x to the right and y up when the marker is read upright; the
    corners, in OpenCV's order, are ``(-s/2, s/2)``, ``(s/2, s/2)``,
    ``(s/2, -s/2)``, ``(-s/2, -s/2)`` with ``s`` the side length.
    """

    dictionary: str = Field("DICT_4X4_50", description="OpenCV predefined dictionary name, e.g. DICT_4X4_50")
    id: int = Field(ge=0, description="marker id within the dictionary")
    size: float = Field(gt=0.0, le=0.5, description="black-square side length in metres")
    T_part_marker: Mat4 = Field(description="pose of the marker frame in the part frame")


class Primitive(StrictModel):
    """A box or a cylinder, placed in the part frame (metres)."""

    shape: Literal["box", "cylinder"]
    size: Vec3 | None = Field(None, description="box extents x, y, z in metres")
    radius: float | None = Field(None, gt=0.0, description="cylinder radius in metres")
    height: float | None = Field(None, gt=0.0, description="cylinder height (along its z) in metres")
    pose: Mat4 = Field(default_factory=lambda: np.eye(4), description="pose of the primitive's centre")

    @model_validator(mode="after")
    def _check_dims(self) -> Primitive:
        if self.shape == "box" and (self.size is None or np.any(self.size <= 0)):
            raise ValueError("a box needs size: [x, y, z] with every extent > 0")
        if self.shape == "cylinder" and (self.radius is None or self.height is None):
            raise ValueError("a cylinder needs radius and height")
        return self


class SolidSpec(StrictModel):
    """Constructive solid: the union of ``add`` minus the union of ``subtract``."""

    add: list[Primitive] = Field(min_length=1)
    subtract: list[Primitive] = Field(default_factory=list)


class PartSpec(StrictModel):
    """A rigid part: its geometry, physical properties and markers.

    Exactly one of ``solid`` (parametric) and ``mesh`` (a file path, resolved
    relative to the YAML file that names it) is given.
    """

    name: str = Field(min_length=1)
    solid: SolidSpec | None = None
    mesh: str | None = Field(None, description="path to an STL/OBJ/PLY mesh")
    mesh_units: Literal["m", "mm"] = Field("m", description="units of the mesh file's coordinates")
    density: float = Field(700.0, gt=0.0, description="kg/m^3; 700 is a hardwood block")
    mass: float | None = Field(None, gt=0.0, description="kg; overrides density * volume")
    center_of_mass: Vec3 | None = Field(None, description="part frame, metres; defaults to the solid's")
    color: tuple[Unit, Unit, Unit] = Field((0.80, 0.62, 0.40), description="RGB, each 0..1")
    markers: list[MarkerSpec] = Field(default_factory=list)

    @model_validator(mode="after")
    def _one_geometry(self) -> PartSpec:
        if (self.solid is None) == (self.mesh is None):
            raise ValueError("give exactly one of solid (parametric) or mesh (a file)")
        ids = [m.id for m in self.markers]
        if len(ids) != len(set(ids)):
            raise ValueError(f"marker ids repeat within part {self.name!r}: {ids}")
        return self


def resolve_relative(path: str, base_dir: Path) -> Path:
    """Resolve a path written in a YAML file against that file's folder."""
    p = Path(path).expanduser()
    return p if p.is_absolute() else (base_dir / p).resolve()
