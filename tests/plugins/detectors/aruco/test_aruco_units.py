"""Unit tests of the ArUco teaching modules: markers, fusion, insertion direction."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.errors import UserError
from asmteach.core.models import MarkerSpec, PartSpec
from asmteach.core.parts import build_part, load_structure
from asmteach.plugins.detectors.aruco.fusion import fuse_poses
from asmteach.plugins.detectors.aruco.insertion import check_retreat, direction_from_approach, separation_direction
from asmteach.plugins.detectors.aruco.markers import get_dictionary, marker_bits, marker_corners_part, marker_table

ROOT = Path(__file__).resolve().parents[4]
PEG = ROOT / "configs/parts/set1/peg_in_hole.yaml"


def _part(name: str, ids: list[int], dictionary: str = "DICT_4X4_50") -> PartSpec:
    return PartSpec(
        name=name,
        solid={"add": [{"shape": "box", "size": [0.04, 0.04, 0.04]}]},
        markers=[MarkerSpec(dictionary=dictionary, id=i, size=0.02, T_part_marker=np.eye(4)) for i in ids],
    )


def test_marker_corners_follow_opencv_order_in_part_frame() -> None:
    m = MarkerSpec(id=0, size=0.02, T_part_marker={"xyz": [0, -0.03, 0.02], "rpy_deg": [90, 0, 0]})
    c = marker_corners_part(m)
    # Marker x -> part x, marker y -> part z (rotated 90 deg about x): top-left is (-x, +z).
    np.testing.assert_allclose(c[0], [-0.01, -0.03, 0.03], atol=1e-12)
    np.testing.assert_allclose(c[2], [0.01, -0.03, 0.01], atol=1e-12)


def test_marker_bits_have_black_border() -> None:
    bits = marker_bits(MarkerSpec(id=3, size=0.02, T_part_marker=np.eye(4)))
    assert bits.shape == (6, 6)
    assert bits[0].all() and bits[-1].all() and bits[:, 0].all() and bits[:, -1].all()
    assert not bits[1:-1, 1:-1].all()


def test_unknown_dictionary_and_shared_id_are_user_errors() -> None:
    with pytest.raises(UserError, match="unknown ArUco dictionary 'DICT_9X9_1'"):
        get_dictionary("DICT_9X9_1")
    with pytest.raises(UserError, match=r"marker id 2 .* used on both 'a' and 'b'"):
        marker_table(_part("a", [1, 2]), _part("b", [2, 5]))


def test_fusion_rejects_flipped_outliers() -> None:
    rng = np.random.default_rng(0)
    truth = geometry.from_rpy(0.2, -0.1, 0.4, [0.01, 0.02, 0.03])
    Ts = [truth @ geometry.from_rotvec(rng.normal(0, 0.002, 3), rng.normal(0, 2e-4, 3)) for _ in range(25)]
    Ts += [truth @ geometry.from_rpy(0.5, 0, 0, [0, 0, 0.01]) for _ in range(5)]  # flipped minority
    fused = fuse_poses(np.array(Ts))
    assert fused.inliers[:25].sum() >= 23 and not fused.inliers[25:].any()
    assert geometry.translation_distance(fused.T, truth) < 2.5e-4
    assert geometry.rotation_distance(fused.T, truth) < np.radians(0.1)
    assert 0.0 < fused.spread_m < 1e-3


def test_direction_from_approach_is_robust_to_an_outlier() -> None:
    rng = np.random.default_rng(1)
    v = np.array([0.0, 0.6, -0.8])
    end = np.array([0.0, 0.0, 0.015])
    s = np.linspace(0.06, 0.01, 10)
    pos = end - s[:, None] * v + rng.normal(0, 3e-4, (10, 3))
    pos[3] += [0.01, 0, 0]  # one badly estimated frame
    est, lateral, kept = direction_from_approach(pos, end)
    assert np.degrees(np.arccos(est @ v)) < 1.0
    assert kept == 9 and lateral < 1e-3


def test_retreat_check_and_geometric_direction_for_peg_in_hole() -> None:
    task = load_structure(PEG)
    a, b = build_part(task.part_a).mesh, build_part(task.part_b).mesh
    assert check_retreat(a, b, task.T_A_B, task.v_a).ok
    sideways = check_retreat(a, b, task.T_A_B, np.array([1.0, 0.0, 0.0]))
    assert not sideways.path_free and sideways.first_collision is not None
    v, travel = separation_direction(a, b, task.T_A_B, directions=60)
    assert np.degrees(np.arccos(v @ task.v_a)) < 2.0
    assert 0.025 <= travel <= 0.04
