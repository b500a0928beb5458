"""Marker layouts of the part library (issue 3): every marker, with its one-cell white quiet zone, lies flat on
one face of its part and is not covered by the mating part at ``T_A_B``.

A quiet zone that runs over a face edge (onto a slot, a rib's side) or under the mating part biases the
sub-pixel edge refinement by a fraction of a pixel; with small markers that became about 1 mm / 1 deg in the
teaching table (set1_t_slot, set2_cap_over_block, set2_ring_on_post). The checks are volumetric (manifold
booleans): a 0.2 mm slab under the printed area must lie inside the part, one above it outside both parts.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.parts import build_part, load_structure
from asmteach.plugins.detectors.aruco.markers import marker_bits, marker_table

ROOT = Path(__file__).resolve().parents[4]
STRUCTURES = sorted((ROOT / "configs/parts").rglob("*.yaml"))
SLAB_M = 2e-4
EDGE_SLACK_M = 1e-4  # the paper may end exactly at a face edge


def _slab(T_part_marker: np.ndarray, side: float, offset: float) -> trimesh.Trimesh:
    """A ``side x side x SLAB_M`` box in the marker plane, its centre ``offset`` metres along the marker normal."""
    box = trimesh.creation.box(extents=[side, side, SLAB_M])
    box.apply_transform(T_part_marker @ geometry.from_rotation(np.eye(3), [0.0, 0.0, offset]))
    return box


def _overlap(slab: trimesh.Trimesh, solid: trimesh.Trimesh) -> float:
    """Fraction of ``slab``'s volume inside ``solid``."""
    inter = trimesh.boolean.intersection([slab, solid], engine="manifold")
    return float(inter.volume) / float(slab.volume) if len(inter.faces) else 0.0


@pytest.mark.parametrize("path", STRUCTURES, ids=lambda p: p.stem)
def test_markers_and_quiet_zones_lie_on_a_free_face(path: Path) -> None:
    task = load_structure(path)
    marker_table(task.part_a, task.part_b)  # unique ids, known dictionaries
    a, b = build_part(task.part_a), build_part(task.part_b)
    for part, other, T_part_other in ((a, b, task.T_A_B), (b, a, geometry.invert(task.T_A_B))):
        other_mesh = other.mesh.copy()
        other_mesh.apply_transform(T_part_other)
        for m in part.spec.markers:
            cells = marker_bits(m).shape[0]  # black border included
            side = m.size * (cells + 2) / cells - 2 * EDGE_SLACK_M  # one white cell on each side
            under = _slab(m.T_part_marker, side, -0.5 * SLAB_M)
            above = _slab(m.T_part_marker, side, 0.5 * SLAB_M)
            where = f"{task.name} {part.spec.name} marker {m.id}"
            # 1e-4 of the area is a 0.002 mm strip along one side: far below any overrun that matters.
            assert _overlap(under, part.mesh) > 1.0 - 1e-4, f"{where} overruns its face"
            assert _overlap(above, part.mesh) < 1e-4, f"{where} is buried in its part"
            assert _overlap(above, other_mesh) < 1e-4, f"{where} is covered by the mating part"


def test_slab_check_catches_a_quiet_zone_over_an_edge() -> None:
    """The check itself: a 16 mm marker centred on a 20 mm tall face overruns it; a 14 mm one does not."""
    box = trimesh.creation.box(extents=[0.06, 0.04, 0.02])
    T = geometry.from_rpy(np.pi / 2, 0.0, 0.0, [0.0, -0.02, 0.0])  # on the -y face, normal -y
    for size, fits in ((0.016, False), (0.014, True)):
        side = size * 8 / 6 - 2 * EDGE_SLACK_M
        under = _slab(T, side, -0.5 * SLAB_M)
        assert (_overlap(under, box) > 1.0 - 1e-4) == fits
        # The 16 mm marker's paper covers 21.1 mm of the 20 mm tall face.
        assert fits or _overlap(under, box) == pytest.approx(0.020 / side, rel=1e-5)
