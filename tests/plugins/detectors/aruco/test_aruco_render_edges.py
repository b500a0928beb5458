"""Supersampling only the pixels a colour boundary may cross gives the image of supersampling them all (issue 27).

The renderer casts one ray through every pixel centre, then ``S x S`` jittered
rays only through pixels that a visible crease or silhouette, a marker's
ink/paper boundary or a colour change between neighbouring centres touches.
Everywhere else a pixel lies inside one flat-shaded colour, so its centre is
its average. These tests render small scenes both ways and compare.
"""

from __future__ import annotations

import numpy as np
import trimesh

from asmteach.core import geometry
from asmteach.core.models import MarkerSpec
from asmteach.plugins.detectors.aruco.camera import c615_like
from asmteach.plugins.detectors.aruco.render import Rendered, RenderObject, render_scene


def _both_ways(objects: list[RenderObject], supersample: int = 4) -> tuple[Rendered, Rendered]:
    cam = c615_like()
    yy, xx = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float32)
    # A backdrop that varies from pixel to pixel: the filtered background must match too.
    bg = np.stack([0.3 + 0.2 * np.sin(xx / 7.0), 0.4 + 0.1 * np.cos(yy / 5.0), 0.5 + 0 * xx], axis=2)
    args = (objects, cam.K, cam.width, cam.height)
    fast = render_scene(*args, background=bg, supersample=supersample)
    full = render_scene(*args, background=bg, supersample=supersample, edges_only=False)
    return fast, full


def _slab_with_marker(T: np.ndarray, marker_id: int = 3) -> RenderObject:
    marker = MarkerSpec(dictionary="DICT_4X4_50", id=marker_id, size=0.02, T_part_marker=np.eye(4))
    slab = trimesh.creation.box(extents=(0.032, 0.032, 0.006))
    slab.apply_translation((0.0, 0.0, -0.003))  # top face at z = 0, where the marker lies
    return RenderObject(slab, (0.6, 0.55, 0.5), [marker], T)


def test_edge_pixels_only_equal_every_pixel_supersampled() -> None:
    # A tilted marked slab, half hidden behind a rotated cylinder (silhouettes, creases, facets, ink edges).
    T_slab = geometry.from_rotvec(np.radians([200.0, 15.0, 7.0]), np.array([0.004, 0.002, 0.42]))
    cyl = trimesh.creation.cylinder(radius=0.006, height=0.05, sections=24)
    T_cyl = geometry.from_rotvec(np.radians([80.0, 10.0, 30.0]), np.array([0.0, 0.004, 0.40]))
    fast, full = _both_ways([_slab_with_marker(T_slab), RenderObject(cyl, (0.3, 0.5, 0.8), [], T_cyl)])
    x0, y0, x1, y1 = fast.roi
    assert np.abs(fast.image - full.image).max() < 1e-5
    # Most of the region is plain colour: a mask that marks everything would pass the equality for nothing.
    assert 0 < fast.supersampled_pixels < 0.6 * (x1 - x0) * (y1 - y0)
    assert full.supersampled_pixels == (x1 - x0) * (y1 - y0)
    # Marker bookkeeping agrees to the supersampling's resolution.
    assert set(fast.marker_pixels) == set(full.marker_pixels) == {3}
    assert abs(fast.marker_pixels[3] - full.marker_pixels[3]) < 1e-6
    assert 0 < fast.marker_pixels[3] < 0.9 * fast.marker_area[3]  # partly hidden by the cylinder


def test_parts_cutting_through_each_other_mid_face() -> None:
    # Two boxes interpenetrating: their intersection lines lie on no triangle edge; only the colour change
    # between neighbouring pixel centres marks them.
    a = trimesh.creation.box(extents=(0.03, 0.03, 0.03))
    b = trimesh.creation.box(extents=(0.02, 0.04, 0.02))
    T_a = geometry.from_rotvec(np.radians([30.0, 40.0, 0.0]), np.array([0.0, 0.0, 0.4]))
    T_b = T_a @ geometry.from_rotvec(np.radians([0.0, 20.0, 35.0]), np.array([0.005, 0.0, 0.006]))
    fast, full = _both_ways([RenderObject(a, (0.8, 0.6, 0.4), [], T_a), RenderObject(b, (0.4, 0.6, 0.8), [], T_b)])
    assert np.abs(fast.image - full.image).max() < 1e-5


def test_one_sample_per_pixel_is_the_pixel_centre() -> None:
    T_slab = geometry.from_rotvec(np.radians([180.0, 0.0, 0.0]), np.array([0.0, 0.0, 0.45]))
    cam = c615_like()
    r = render_scene(
        [_slab_with_marker(T_slab)],
        cam.K,
        cam.width,
        cam.height,
        background=np.zeros((cam.height, cam.width, 3), np.float32),
        supersample=1,
    )
    # Square-on at the optical axis: the pixel at the principal point sees the slab, one 60 px away does not.
    cx, cy = int(cam.K[0, 2] + 0.5), int(cam.K[1, 2] + 0.5)
    assert r.supersampled_pixels == 0
    assert r.image[cy, cx].sum() > 0
    assert r.image[cy, cx + 60].sum() == 0
    assert r.marker_mask is not None and r.marker_mask[cy, cx] in (-1, 3)


def test_faces_of_one_part_hiding_each_other() -> None:
    # One part made of two blocks, the far one partly behind the near one: front faces of the same part
    # overlap on the image (a cap's outer wall over its inner one), and both must be drawn where seen.
    near = trimesh.creation.box(extents=(0.02, 0.02, 0.01))
    far = trimesh.creation.box(extents=(0.03, 0.015, 0.01))
    far.apply_translation((0.008, 0.004, 0.03))
    part = trimesh.util.concatenate([near, far])
    T = geometry.from_rotvec(np.radians([10.0, 15.0, 5.0]), np.array([0.0, 0.0, 0.4]))
    marker = MarkerSpec(dictionary="DICT_4X4_50", id=5, size=0.012, T_part_marker=np.eye(4))
    marker.T_part_marker[2, 3] = -0.005  # on the near block's face toward the camera, printed side toward it
    marker.T_part_marker[:3, :3] = np.diag([1.0, -1.0, -1.0])
    fast, full = _both_ways([RenderObject(part, (0.7, 0.5, 0.3), [marker], T)])
    assert np.abs(fast.image - full.image).max() < 1e-5
    assert fast.marker_pixels[5] > 0.98 * fast.marker_area[5]
