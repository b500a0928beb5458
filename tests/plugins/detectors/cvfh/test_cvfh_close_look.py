"""Close looks of a free wrist camera at a corpus scene: a D peg with its flat away from the Kinect, listed with a
rival turned 20 deg, is settled from a ranked viewpoint inside the reach region; no look for a found detection."""

from __future__ import annotations

import numpy as np
import pytest

from asmteach.core.config import TableSettings
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Detection, TablePlane
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings
from asmteach.core.perception.second_view import DepthView
from asmteach.core.pose_error import pose_error
from asmteach.core.symmetry import part_symmetries
from asmteach.plugins.detectors.cvfh.close_look import REACH_REGION, free_looks
from asmteach.plugins.detectors.cvfh.scenes import default_camera_pose, render_table_scene


def _ambiguous(poses: list[np.ndarray]) -> Detection:
    return Detection(
        part="d_peg",
        found=False,
        reason="ambiguous: a pose 0 mm and 20 deg away explains the view as well",
        details={"ambiguous": [{"T_world_part": T.tolist()} for T in poses], "ambiguous_kind": "near_twin"},
    )


@pytest.fixture(scope="module")
def case(d_peg_part: PartModel, d_peg_poses) -> tuple[PartModel, np.ndarray, np.ndarray, DepthView]:
    T_true, rival = d_peg_poses  # the flat faces +x: away from the Kinect
    T_cam = default_camera_pose(TableSettings())
    scene = render_table_scene(DepthCamera(KinectSettings(), seed=1), d_peg_part.mesh, T_true, T_world_cam=T_cam)
    return d_peg_part, T_true, rival, DepthView(scene.cloud, T_cam[:3, 3])


def test_a_look_from_the_reach_region_settles_the_d_peg(case) -> None:
    part, T_true, rival, first = case
    syms = part_symmetries(part.mesh, part.center_of_mass)
    out = free_looks(
        _ambiguous([rival, T_true]),
        part,
        (part.mesh, T_true),
        [first],
        TablePlane(),
        looks=2,
        seed=3,
        symmetries=syms,
        settings=REACH_REGION,
    )
    det = out.detection
    assert det.found, out.looks
    assert pose_error(det.rough, T_true, right=syms).within(2.0, 3.0)
    look = det.details["resolved_by_look"]
    assert look["winner"] == 1 and look["predicted_separation"] > 0
    assert look["distance_m"] >= 0.16 and look["elevation_deg"] >= 55.0  # inside the region
    assert 1 <= len(out.views) <= 2 and out.views[0].sensor is not None  # the wrist sensor's own noise
    assert out.looks[0]["ranked_viewpoints"] > 0


def test_no_look_for_a_found_detection_or_a_single_pose(case) -> None:
    part, T_true, _, first = case
    found = Detection(part="d_peg", found=True, rough=T_true.tolist())
    lone = _ambiguous([T_true])
    for det in (found, lone):
        out = free_looks(det, part, (part.mesh, T_true), [first], TablePlane(), looks=2, seed=0)
        assert out.detection is det and not out.looks and not out.views


def test_a_look_that_settles_nothing_ranks_again_for_the_pair_it_leaves(case, monkeypatch) -> None:
    """As the pipeline's look_closer: the second look is ranked for the views' best pose and its closest rival,
    not taken from the first ranking (which was for the fixed view's rivals)."""
    import asmteach.plugins.detectors.cvfh.close_look as close_look

    part, T_true, rival, first = case
    pair = [T_true.copy(), rival.copy()]
    pair[1][:3, 3] += 0.003  # a rival the fixed view did not list
    ranked_for: list[list[np.ndarray]] = []
    real_rank = close_look.rank_viewpoints

    def rank(mesh, poses, *args, **kwargs):
        ranked_for.append([np.asarray(T, float) for T in poses])
        return real_rank(mesh, poses, *args, **kwargs)

    def undecided(det, part, views, table, symmetries):
        verdict = {"best_T_world_part": pair[0].tolist(), "closest_rival_T_world_part": pair[1].tolist()}
        return Detection(part=det.part, found=False, reason="still ambiguous", details={"second_view": verdict})

    monkeypatch.setattr(close_look, "rank_viewpoints", rank)
    monkeypatch.setattr(close_look, "resolve_by_views", undecided)
    out = free_looks(
        _ambiguous([rival, T_true]),
        part,
        (part.mesh, T_true),
        [first],
        TablePlane(),
        looks=2,
        seed=3,
        settings=REACH_REGION,
    )
    assert len(out.views) == 2 and not out.detection.found
    assert len(ranked_for) == 2  # once for the listed rivals, once for the pair the first look left
    assert np.allclose(ranked_for[0][0], rival) and np.allclose(ranked_for[1][1], pair[1])
    eyes = [v.viewpoint for v in out.views]
    assert np.linalg.norm(eyes[0] - eyes[1]) >= 0.01  # never the same viewpoint twice
