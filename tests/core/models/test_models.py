"""Every contract model survives a JSON round trip, and rejects what it must."""

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from asmteach.core import geometry as g
from asmteach.core import models as m
from asmteach.core.parts import load_structure


def _round_trip(model: BaseModel) -> BaseModel:
    again = type(model).model_validate_json(model.model_dump_json())
    assert again.model_dump(mode="json") == model.model_dump(mode="json")
    return again


@pytest.fixture
def task(repo_root) -> m.AssemblyTask:
    return load_structure(repo_root / "configs/parts/set1/peg_in_hole.yaml")


@pytest.fixture
def repo_root():
    from pathlib import Path

    return Path(__file__).resolve().parents[3]


def test_assembly_task_round_trip_keeps_poses(task):
    again = _round_trip(task)
    np.testing.assert_allclose(again.T_A_B, task.T_A_B)
    np.testing.assert_allclose(again.v_a, [0, 0, -1])
    assert again.part_a.markers[1].T_part_marker.shape == (4, 4)


def test_pose_mapping_form_is_metres_and_degrees():
    marker = m.MarkerSpec(id=1, size=0.02, T_part_marker={"xyz": [0.01, 0, 0], "rpy_deg": [90, 0, 0]})
    np.testing.assert_allclose(marker.T_part_marker[:3, 3], [0.01, 0, 0])
    np.testing.assert_allclose(g.rpy(marker.T_part_marker), [np.pi / 2, 0, 0], atol=1e-12)


def test_every_model_round_trips(task):
    poly = np.array([[0, 0], [0.1, 0], [0, 0.1]])
    samples = [
        m.CameraIntrinsics(K=np.diag([900.0, 900.0, 1.0]), width=1280, height=720),
        m.TeachingEvidence(frames_total=3, frames_used=[0, 2], residuals_px=[0.2, 0.3], spread_mm=0.05),
        m.Detection(part="a", found=True, rough=np.eye(4), corrected=np.eye(4), fitness=0.9, timing_ms={"total": 3}),
        m.Detection(part="a", found=False, reason="no plane"),
        m.Correction(T_world_part=np.eye(4), placement_id=2),
        m.Placement(id=0, T_table_part=np.eye(4), probability=0.4, margin=0.3, support_polygon=poly),
        m.Grasp(id=3, p0=[0, -0.01, 0], p1=[0, 0.01, 0], R=np.eye(3), width=0.02, score=0.5),
        m.Trajectory(arm="left", joint_names=["a", "b"], times=[0, 1], positions=[[0, 0], [1, 1]]),
        m.Plan(segments=[m.PlanSegment(label="close", gripper=m.GripperEvent(arm="left", action="close"))]),
        m.RunReport(config={"a": 1}, seed=0, stages=[m.StageOutcome(stage="teach", ok=True)], task=task),
        m.HandSpec(
            name="h",
            max_width=0.085,
            finger_size=[0.01, 0.02, 0.045],
            pad_size=(0.02, 0.03),
            palm_center=[0, 0, -0.07],
            palm_size=[0.1, 0.04, 0.04],
        ),
        task,
    ]
    for sample in samples:
        _round_trip(sample)


def test_grasp_tcp_is_between_contacts():
    grasp = m.Grasp(id=0, p0=[0, -0.01, 0.02], p1=[0, 0.01, 0.02], R=np.eye(3), width=0.02)
    np.testing.assert_allclose(grasp.T_part_tcp[:3, 3], [0, 0, 0.02])


def test_v_a_is_normalised_and_marker_ids_unique(task):
    raw = task.model_dump(mode="json")
    raw["v_a"] = [0, 0, -5]
    assert np.allclose(m.AssemblyTask.model_validate(raw).v_a, [0, 0, -1])
    raw["part_b"]["markers"][0]["id"] = raw["part_a"]["markers"][0]["id"]
    with pytest.raises(ValidationError, match="used on both"):
        m.AssemblyTask.model_validate(raw)


@pytest.mark.parametrize(
    "change, msg",
    [
        ({"extra_key": 1}, "Extra inputs"),
        ({"solid": None}, "exactly one of solid"),
        ({"density": -1}, "greater than 0"),
    ],
)
def test_part_spec_rejects(task, change, msg):
    raw = task.part_a.model_dump(mode="json") | change
    with pytest.raises(ValidationError, match=msg):
        m.PartSpec.model_validate(raw)


def test_trajectory_shape_checked():
    with pytest.raises(ValidationError, match="positions shape"):
        m.Trajectory(arm="l", joint_names=["a"], times=[0, 1], positions=[[0, 0], [1, 1]])
