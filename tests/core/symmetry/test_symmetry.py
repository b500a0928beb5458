"""The one symmetry module: part groups, axis orders, the principal frame, over the whole corpus."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.corpus import corpus_part, part_corpus
from asmteach.core.symmetry import SymmetryFinder, part_symmetries, principal_frame


def test_a_left_handed_principal_frame_is_flipped_on_a_copy_not_in_trimesh_s_array() -> None:
    mesh = corpus_part("prism_hole_1").mesh  # trimesh's principal axes come out left-handed here
    raw = mesh.principal_inertia_vectors
    assert np.linalg.det(raw) < 0 and not raw.flags.writeable
    F = principal_frame(mesh)
    assert np.isclose(np.linalg.det(F), 1.0)
    assert np.allclose(F.T @ F, np.eye(3), atol=1e-9)
    assert np.array_equal(mesh.principal_inertia_vectors, raw)  # untouched


@pytest.mark.parametrize(
    ("name", "size"),
    [("hex_peg_0", 12), ("d_peg_0", 2), ("prism_slot_0", 2), ("l_bracket_1", 1), ("ff_bunny", 1)],
)
def test_group_sizes_of_known_shapes(name: str, size: int) -> None:
    part = corpus_part(name)
    assert len(part_symmetries(part.mesh, part.mesh.center_mass)) == size


def test_a_wheel_has_the_dihedral_group_of_its_spokes_although_its_rim_has_64_sides() -> None:
    # 3 spokes on a 64-gon rim: no vertex lands on a vertex under a 120 deg turn, the surface does
    wheel = trimesh.creation.cylinder(radius=0.03, height=0.01, sections=64)
    windows = []
    for k in range(3):
        a = 2 * np.pi * k / 3
        box = trimesh.creation.box(extents=(0.012, 0.008, 0.02))
        box.apply_translation((0.017, 0.0, 0.0))
        box.apply_transform(trimesh.transformations.rotation_matrix(a, [0, 0, 1]))
        windows.append(box)
    mesh = trimesh.boolean.difference([wheel, *windows], engine="manifold")
    syms = part_symmetries(mesh, mesh.center_mass)
    assert len(syms) == 6
    exact = SymmetryFinder(mesh, mesh.convex_hull.vertices, mesh.center_mass)  # placement use: exact, 5 um
    assert exact.order(np.array([0.0, 0.0, 1.0])) == 1  # a 64-gon is not 3-fold symmetric to 5 um


@pytest.mark.slow
def test_every_corpus_part_gets_a_group_that_maps_its_surface_onto_itself() -> None:
    """Regression over the whole corpus: no crash, identity first, every element a true symmetry."""
    import open3d as o3d

    for part in part_corpus(seed=0):
        mesh, com = part.mesh, part.mesh.center_mass
        syms = part_symmetries(mesh, com)
        assert np.allclose(syms[0], np.eye(4)), part.name
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)), o3d.core.Tensor(np.asarray(mesh.faces, np.uint32))
        )
        pts, _ = trimesh.sample.sample_surface(mesh, 400, seed=1)
        for S in syms[1:]:
            assert np.isclose(np.linalg.det(S[:3, :3]), 1.0), part.name
            moved = geometry.transform_points(S, pts).astype(np.float32)
            assert float(scene.compute_distance(o3d.core.Tensor(moved)).numpy().max()) < 0.0006, part.name


def test_a_tube_is_equivalent_under_every_turn_about_its_axis_and_errors_see_it() -> None:
    from asmteach.core.pose_error import pose_error
    from asmteach.core.symmetry import equivalent_transforms

    tube = corpus_part("tube_2").mesh
    com = tube.center_mass
    eq = equivalent_transforms(tube, com)
    assert len(eq) >= 360
    turned = geometry.from_rotation(
        geometry.rot_z(np.radians(13.0))[:3, :3], com - geometry.rot_z(np.radians(13.0))[:3, :3] @ com
    )
    err = pose_error(turned, np.eye(4), right=eq)  # 13 deg about the axis: the same tube
    assert err.position_mm < 0.01 and err.angle_deg < 0.6
    assert pose_error(geometry.from_rpy(0.2, 0, 0), np.eye(4), right=eq).angle_deg > 5.0  # tilted: not the same
