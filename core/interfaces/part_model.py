"""A part ready for computation (:class:`PartModel`): its spec, mesh (part frame, metres) and mass properties."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from asmteach.core.models import PartSpec

__all__ = ["PartModel"]


@dataclass
class PartModel:
    """A part ready for computation: its spec, mesh and mass properties.

    ``mesh`` is a watertight ``trimesh.Trimesh`` in the part frame (metres);
    ``center_of_mass`` is in the part frame; ``mass`` in kg.

    A part given as a scan (a PCD/PLY point cloud, :func:`asmteach.core.parts.build_cloud_part`) has
    ``points`` ((n, 3), part frame = the file's frame, metres) and ``scan_viewpoint`` (the scanner's centre
    in the part frame, metres, or ``None`` when unknown; it orients the scan's normals). Its ``mesh`` is
    then only the points' convex hull, a stand-in for size and bounds: a detector that needs the surface
    (rendered views, ray casting) cannot use such a part; one that can says so with ``takes_cloud_models``.
    """

    spec: PartSpec
    mesh: trimesh.Trimesh
    mass: float
    center_of_mass: np.ndarray
    source_hash: str = ""
    points: np.ndarray | None = None
    scan_viewpoint: np.ndarray | None = None

    @property
    def name(self) -> str:
        return self.spec.name
