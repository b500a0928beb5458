"""fpfh_ransac: finds a part on the table, repeats with its seed, and reports bad input as not found."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asmteach.core import geometry, registry
from asmteach.core.errors import UserError
from asmteach.core.interfaces import PartModel
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.plugins.detectors.cvfh.scenes import DEFAULT_EYE, place_on_table, render_table_scene
from asmteach.plugins.detectors.fpfh.detector import FpfhRansacDetector

REPO = Path(__file__).resolve().parents[4]


@pytest.fixture(scope="module")
def stepped_block() -> PartModel:
    return build_part(load_structure(REPO / "configs/parts/set1/notched_block.yaml").part_a)


def test_registered_and_finds_the_part(stepped_block: PartModel) -> None:
    assert registry.get_class("detectors", "fpfh_ransac") is FpfhRansacDetector
    # A view FPFH handles; it misses about half of this part's views (see the detection_precision experiment),
    # and then says so instead of giving a wrong pose.
    T = place_on_table(stepped_block.mesh, np.eye(4), 2.0, (0.5, -0.1))
    scene = render_table_scene(DepthCamera(KinectSettings(), seed=3), stepped_block.mesh, T)
    det = FpfhRansacDetector(seed=1)
    det.prepare(stepped_block)
    a = det.detect(scene.cloud, stepped_block, viewpoint=DEFAULT_EYE)
    assert a.found, a.reason
    assert geometry.translation_distance(a.rough, T) < 0.003
    assert np.degrees(geometry.rotation_distance(a.rough, T)) < 3.0
    assert a.timing_ms["total"] > 0 and "matching" in a.timing_ms
    # Same seed, same answer.
    b = FpfhRansacDetector(seed=1).detect(scene.cloud, stepped_block, viewpoint=DEFAULT_EYE)
    assert np.allclose(a.rough, b.rough, atol=1e-9)


def test_bad_input_is_not_found(stepped_block: PartModel) -> None:
    det = FpfhRansacDetector(seed=0)
    for cloud, words in (
        (np.zeros((0, 3)), "empty"),
        (np.full((10, 3), np.nan), "NaN"),
        (np.random.default_rng(0).uniform(0, 900, (3000, 3)), "millimetres"),
    ):
        d = det.detect(cloud, stepped_block, viewpoint=DEFAULT_EYE)
        assert not d.found and d.rough is None and words in d.reason


def test_no_viewpoint_is_one_clear_error(stepped_block: PartModel) -> None:
    """No built-in camera: a cloud seen from elsewhere would have every pose rejected as hiding seen points."""
    with pytest.raises(UserError, match="no camera position"):
        FpfhRansacDetector(seed=0).detect(np.zeros((10, 3)), stepped_block)
