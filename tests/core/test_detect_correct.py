"""The one detect-then-correct path, with a detector and a corrector made here."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from asmteach.core import geometry
from asmteach.core.detect_correct import detect_and_correct, part_segment, provisional_detection
from asmteach.core.errors import UserError
from asmteach.core.interfaces import Corrector, Detector, PartModel
from asmteach.core.models import Correction, Detection, TablePlane
from asmteach.core.parts import build_part, load_structure

STRUCTURE = Path(__file__).resolve().parents[2] / "configs/parts/set1/peg_in_hole.yaml"
EYE = np.array([0.5, 0.0, 1.0])


class _Found(Detector):
    """Finds the part at a fixed pose and says which viewpoint it used."""

    def __init__(self, T: np.ndarray) -> None:
        super().__init__()
        self.T = T

    def detect(
        self, cloud: np.ndarray, part: PartModel, table: TablePlane | None = None, viewpoint: np.ndarray | None = None
    ) -> Detection:
        return Detection(
            part=part.name, found=True, rough=self.T, timing_ms={"total": 5.0}, details={"viewpoint": EYE.tolist()}
        )


class _Snap(Corrector):
    """Records what it was given; lifts the pose 1 mm, or refuses."""

    def __init__(self, refuse: bool = False) -> None:
        super().__init__()
        self.refuse, self.seen = refuse, {}

    def correct(
        self,
        T_world_part: np.ndarray,
        part: PartModel,
        table: TablePlane,
        cloud: np.ndarray | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Correction:
        self.seen: dict[str, Any] = {"cloud": cloud, "viewpoint": viewpoint, "table": table}
        if self.refuse:
            raise UserError("no placement near the rough pose")
        return Correction(T_world_part=geometry.from_rotation(np.eye(3), (0, 0, 0.001)) @ T_world_part, placement_id=3)


@pytest.fixture(scope="module")
def part() -> PartModel:
    return build_part(load_structure(STRUCTURE).part_b)


def _cloud(part: PartModel, T: np.ndarray) -> np.ndarray:
    on_part = geometry.transform_points(T, np.asarray(part.mesh.sample(400, seed=1)))
    far = np.array([[2.0, 2.0, 0.0], [np.nan, 0.0, 0.0]])
    return np.vstack([on_part, far])


def test_segment_keeps_the_points_on_the_part_only(part: PartModel) -> None:
    T = geometry.from_rpy(0.0, 0.0, 0.3, (0.4, 0.1, 0.05))
    seg = part_segment(_cloud(part, T), part, T)
    assert len(seg) == 400 and np.all(np.isfinite(seg))


def test_corrects_with_the_detectors_viewpoint_and_the_segment(part: PartModel) -> None:
    T = geometry.from_rpy(0.0, 0.0, 0.3, (0.4, 0.1, 0.05))
    corrector = _Snap()
    det = detect_and_correct(_Found(T), corrector, _cloud(part, T), part, TablePlane(), viewpoint=None)
    assert det.corrected is not None and det.corrected[2, 3] == pytest.approx(T[2, 3] + 0.001)
    assert det.details["placement_id"] == 3
    assert np.allclose(corrector.seen["viewpoint"], EYE) and len(corrector.seen["cloud"]) == 400
    assert det.timing_ms["detect"] == 5.0 and det.timing_ms["total"] >= 5.0


def test_a_refused_correction_keeps_the_rough_pose_and_says_why(part: PartModel) -> None:
    T = np.eye(4)
    det = detect_and_correct(_Found(T), _Snap(refuse=True), _cloud(part, T), part)
    assert det.found and det.corrected is None
    assert "no placement" in det.details["correction_error"]


def _ambiguous(kind: str) -> Detection:
    twins = [geometry.from_rotation(np.eye(3), (0.4, 0.0, 0.02)), geometry.from_rpy(np.pi, 0.0, 0.0, (0.4, 0.0, 0.02))]
    return Detection(
        part="p",
        found=False,
        reason="ambiguous: twins",
        details={"ambiguous": [{"T_world_part": T.tolist(), "fitness": 0.97} for T in twins], "ambiguous_kind": kind},
    )


def test_only_hull_twins_go_on_provisionally_with_the_first_pose() -> None:
    det = provisional_detection(_ambiguous("hull_twin"))
    assert det.found and det.reason is None and det.details["provisional"]
    assert np.allclose(det.rough, np.asarray(_ambiguous("hull_twin").details["ambiguous"][0]["T_world_part"]))
    assert len(det.details["ambiguous"]) == 2 and det.details["provisional_reason"] == "ambiguous: twins"
    near = _ambiguous("near_twin")
    assert provisional_detection(near) is near  # a near twin changes the grasp: no guess


class _Ambiguous(Detector):
    def detect(
        self, cloud: np.ndarray, part: PartModel, table: TablePlane | None = None, viewpoint: np.ndarray | None = None
    ) -> Detection:
        return _ambiguous("hull_twin")


def test_a_hull_twin_ambiguity_is_found_only_for_a_caller_that_looks_again(part: PartModel) -> None:
    cloud = np.zeros((10, 3))
    assert not detect_and_correct(_Ambiguous(), None, cloud, part).found
    assert detect_and_correct(_Ambiguous(), None, cloud, part, provisional=True).found


def test_a_closer_look_comes_before_going_on_provisionally(part: PartModel) -> None:
    cloud = np.zeros((10, 3))
    asked: list[Detection] = []

    def settles(det: Detection) -> Detection:
        asked.append(det)
        rival = np.asarray(det.details["ambiguous"][1]["T_world_part"])
        return det.model_copy(update={"found": True, "reason": None, "rough": rival})

    det = detect_and_correct(_Ambiguous(), None, cloud, part, provisional=True, closer=settles)
    assert len(asked) == 1 and not asked[0].found  # asked before the provisional guess
    assert det.found and "provisional" not in det.details
    assert np.allclose(det.rough, np.asarray(_ambiguous("hull_twin").details["ambiguous"][1]["T_world_part"]))
    # what the look leaves ambiguous still goes on provisionally; a found part is never looked at
    assert detect_and_correct(_Ambiguous(), None, cloud, part, provisional=True, closer=lambda d: d).details[
        "provisional"
    ]
    T = np.eye(4)
    detect_and_correct(_Found(T), None, _cloud(part, T), part, closer=settles)
    assert len(asked) == 1


class _TurnsOnTheSegment(Corrector):
    """Snaps (lifts 1 mm) without a cloud; with one, its refinement turns the part 26 deg about z, as a planar ICP on
    a view that cannot tell the turns apart may."""

    def __init__(self) -> None:
        super().__init__()
        self.clouds: list[np.ndarray | None] = []

    def correct(
        self,
        T_world_part: np.ndarray,
        part: PartModel,
        table: TablePlane,
        cloud: np.ndarray | None = None,
        viewpoint: np.ndarray | None = None,
    ) -> Correction:
        self.clouds.append(cloud)
        lift = geometry.from_rotation(np.eye(3), (0, 0, 0.001)) @ T_world_part
        turn = geometry.from_rpy(0.0, 0.0, np.radians(26.0)) if cloud is not None else np.eye(4)
        return Correction(T_world_part=lift @ turn, placement_id=1)


def test_a_correction_may_not_undo_what_other_views_settled(part: PartModel) -> None:
    T = np.eye(4)

    def settles(det: Detection) -> Detection:
        rival = np.asarray(det.details["ambiguous"][1]["T_world_part"])
        return det.model_copy(
            update={"found": True, "reason": None, "rough": rival, "details": {**det.details, "resolved_by_view": {}}}
        )

    corrector = _TurnsOnTheSegment()
    det = detect_and_correct(
        _Ambiguous(), corrector, _cloud(part, T), part, TablePlane(), closer=settles, symmetries=[]
    )
    settled = np.asarray(_ambiguous("hull_twin").details["ambiguous"][1]["T_world_part"])
    assert corrector.clouds[0] is not None and corrector.clouds[1] is None  # refined, then the snap alone
    assert np.allclose(det.corrected, geometry.from_rotation(np.eye(3), (0, 0, 0.001)) @ settled)
    over = det.details["correction_overruled"]
    assert over["refined_vs_settled"]["angle_deg"] > 25.0 and over["snap_vs_settled"]["angle_deg"] < 1e-6
    # a detection no other view settled keeps the corrector's refinement, turn and all
    plain = detect_and_correct(_Found(T), _TurnsOnTheSegment(), _cloud(part, T), part, TablePlane())
    assert "correction_overruled" not in plain.details
    assert np.degrees(geometry.rotation_distance(plain.corrected, T)) > 25.0
