"""A closer look by a wrist camera settles a D peg that the fixed Kinect cannot: a small fake world (a flying
camera arm whose joints are the TCP's position and rotation vector) rendered with the depth camera model."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from asmteach.core import geometry
from asmteach.core.interfaces import MotionResult, PartModel
from asmteach.core.interfaces.robot import IKResult
from asmteach.core.models import Detection, TablePlane, Trajectory
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.core.perception.second_view import DepthView
from asmteach.core.pipeline.active_look import look_closer, seen_heightmap
from asmteach.core.pose_error import pose_error
from asmteach.core.robot import PlanningScene, WristCamera
from asmteach.core.symmetry import part_symmetries

EYE = np.array([-0.05, 0.0, 0.70])  # the fixed Kinect, on the robot's side of the table
TARGET = np.array([0.45, 0.0, 0.0])
TABLE = trimesh.creation.box(extents=[0.8, 1.2, 0.02])
T_TABLE = geometry.from_rotation(np.eye(3), [0.45, 0.0, -0.01])


def _q(T: np.ndarray) -> np.ndarray:
    return np.r_[T[:3, 3], Rotation.from_matrix(T[:3, :3]).as_rotvec()]


def _T(q: np.ndarray) -> np.ndarray:
    return geometry.from_rotation(Rotation.from_rotvec(q[3:]).as_matrix(), q[:3])


class _Scene(PlanningScene):
    """The TCP collides below ``floor`` metres (the table and what stands on it, crudely)."""

    floor = 0.05

    def in_collision(self, arm: str, qs: np.ndarray, *, ignore: tuple = ()) -> np.ndarray:
        return np.atleast_2d(qs)[:, 2] < self.floor

    def clearance(self, arm: str, qs: np.ndarray, upto: float = np.inf) -> np.ndarray:
        return np.minimum(np.atleast_2d(qs)[:, 2] - self.floor, upto)


class _FlyingCamera:
    """One arm, ``"main"``, with a wrist camera 5 cm along the TCP's y; the D peg lies at ``T_part``."""

    arms = ("main",)

    def __init__(self, mesh: trimesh.Trimesh, T_part: np.ndarray) -> None:
        self.mesh, self.T_part = mesh, T_part
        self.q = _q(look_at([0.3, 0.0, 0.5], TARGET))
        self.scene = _Scene({"main": self.q})
        self.cam = WristCamera(
            T_tcp_cam=geometry.from_rotation(np.eye(3), [0.0, 0.05, 0.0]), sensor=KinectSettings.wrist_stereo()
        )
        self.renderer = DepthCamera(self.cam.sensor, seed=5)
        self.executed: list[Trajectory] = []

    def wrist_cameras(self) -> list[str]:
        return ["main"]

    def wrist_camera(self, arm: str) -> WristCamera:
        return self.cam

    def current(self, arm: str) -> np.ndarray:
        return self.q.copy()

    def joint_names(self, arm: str) -> list[str]:
        return ["x", "y", "z", "rx", "ry", "rz"]

    def joint_limits(self, arm: str) -> tuple[np.ndarray, np.ndarray]:
        return np.full(6, -10.0), np.full(6, 10.0)

    def speed_limits(self, arm: str) -> np.ndarray:
        return np.ones(6)

    def acceleration_limits(self, arm: str) -> None:
        return None

    def ik_many(self, arm: str, T: np.ndarray, q_seed: np.ndarray | None = None) -> list[IKResult]:
        return [IKResult(True, _q(t), 0.0, 0.0) for t in np.asarray(T).reshape(-1, 4, 4)]

    def execute(self, traj: Trajectory) -> None:
        assert np.allclose(traj.positions[0], self.q, atol=1e-6), "a trajectory must start where the arm is"
        self.executed.append(traj)
        self.q = np.asarray(traj.positions[-1], float)

    def sense_wrist(self, arm: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        T_world_cam = _T(self.q) @ self.cam.T_tcp_cam
        frame = self.renderer.render([(TABLE, T_TABLE), (self.mesh, self.T_part)], T_world_cam)
        return frame.depth, frame.points_world, T_world_cam


class _Straight:
    """A motion planner that tries the straight line only."""

    def plan(self, start: np.ndarray, goal: np.ndarray, *, lower, upper, is_valid, cost=None, time_limit=5.0):
        path = np.linspace(start, goal, 20)
        if not np.all(is_valid.batch(path)):
            return MotionResult(False, None, "the straight line collides")
        return MotionResult(True, path)


@pytest.fixture(scope="module")
def case(d_peg_part: PartModel, d_peg_poses) -> tuple[PartModel, np.ndarray, np.ndarray, DepthView]:
    T_true, rival = d_peg_poses  # the flat faces +x: away from the Kinect
    cam = DepthCamera(KinectSettings(), seed=1)
    frame = cam.render([(TABLE, T_TABLE), (d_peg_part.mesh, T_true)], look_at(EYE, TARGET))
    return d_peg_part, T_true, rival, DepthView(frame.points_world, EYE)


def _ambiguous(part: PartModel, poses: list[np.ndarray]) -> Detection:
    return Detection(
        part=part.name,
        found=False,
        reason="ambiguous: a pose 0 mm and 20 deg away explains the view as well",
        details={"ambiguous": [{"T_world_part": T.tolist()} for T in poses], "ambiguous_kind": "near_twin"},
    )


def test_a_close_look_settles_the_d_peg_and_the_arm_comes_back(case) -> None:
    part, T_true, rival, first = case
    robot = _FlyingCamera(part.mesh, T_true)
    start = robot.current("main")
    syms = part_symmetries(part.mesh, part.center_of_mass)
    out = look_closer(
        robot,
        _ambiguous(part, [rival, T_true]),
        part,
        [first],
        TablePlane(),
        _Straight(),
        looks=2,
        frames=2,
        symmetries=syms,
    )
    det = out.detection
    assert det.found, out.looks
    assert pose_error(det.rough, T_true, right=syms).within(2.0, 3.0)
    look = det.details["resolved_by_look"]
    assert look["made"] and look["winner"] == 1 and look["predicted_separation"] > 0
    assert look["camera_xyz_mm"][0] > 450.0  # it looked from the flat's side
    assert len(robot.executed) == 2 and np.allclose(robot.current("main"), start)
    assert out.robot_seconds == pytest.approx(sum(t.times[-1] for t in robot.executed))
    # what the fixed view alone says: still ambiguous (the look, not the order of the rivals, decided)
    assert not look_closer(
        robot, _ambiguous(part, [rival, T_true]), part, [first], TablePlane(), _Straight(), looks=0
    ).detection.found


def test_a_look_that_cannot_be_made_says_why(case) -> None:
    part, T_true, rival, first = case
    robot = _FlyingCamera(part.mesh, T_true)
    robot.scene.floor = 10.0  # every configuration collides
    det = _ambiguous(part, [rival, T_true])
    out = look_closer(robot, det, part, [first], TablePlane(), _Straight(), looks=2, max_tries=3)
    assert out.detection is det and not robot.executed and out.robot_seconds == 0.0
    assert len(out.looks) == 1  # no viewpoint reached: only the counts
    reach = out.looks[0]["reach"]
    assert (reach["checked"], reach["tries"], reach["collide"], reach["no_ik"], reach["no_path"]) == (3, 3, 3, 0, 0)


def test_the_best_reachable_viewpoint_is_taken_when_the_best_are_not(case) -> None:
    part, T_true, rival, first = case
    robot = _FlyingCamera(part.mesh, T_true)
    robot.scene.floor = 0.2  # the TCP collides below 0.2 m: the close, low viewpoints are out of reach
    syms = part_symmetries(part.mesh, part.center_of_mass)
    out = look_closer(
        robot, _ambiguous(part, [rival, T_true]), part, [first], TablePlane(), _Straight(), looks=1, symmetries=syms
    )
    reach = out.looks[0]["reach"]
    made = [rec for rec in out.looks[1:] if rec.get("made")]
    assert len(made) == 1 and made[0]["rank"] > 0  # the best-ranked one could not be reached, a later one was
    assert reach["collide"] == made[0]["rank"] and reach["checked"] == made[0]["rank"] + 1
    assert made[0]["camera_xyz_mm"][2] > 150.0


def test_no_wrist_camera_no_look(case) -> None:
    part, T_true, rival, first = case
    robot = _FlyingCamera(part.mesh, T_true)
    robot.wrist_cameras = lambda: []  # type: ignore[method-assign]
    det = _ambiguous(part, [rival, T_true])
    out = look_closer(robot, det, part, [first], TablePlane(), _Straight())
    assert out.detection is det and out.looks == []


def test_the_heightmap_fills_under_what_was_seen() -> None:
    pts = np.array([[0.405, 0.005, 0.03], [0.407, 0.006, 0.05], [0.6, 0.2, 0.001], [0.305, 0.0, 0.04]])
    mesh = seen_heightmap([DepthView(pts, None)], TablePlane(), skip=[(np.array([0.3, 0.0, 0.04]), 0.02)])
    assert mesh is not None
    assert np.allclose(mesh.bounds, [[0.40, 0.0, 0.0], [0.41, 0.01, 0.05]])  # one column to the highest point


def test_the_runs_look_records_and_counts_robot_seconds(case, tmp_path) -> None:
    from types import SimpleNamespace

    from asmteach.core.pipeline.active_look import closer_for

    part, T_true, rival, first = case
    robot = _FlyingCamera(part.mesh, T_true)
    syms = part_symmetries(part.mesh, part.center_of_mass)
    run = SimpleNamespace(
        execution=SimpleNamespace(look_closer=2, depth_frames=4),
        plugin=lambda role: _Straight(),
        symmetries=lambda p: syms,
        report=SimpleNamespace(robot_seconds={"total": 1.0}, artefacts={}),
        out=tmp_path,
    )
    run.artefact = lambda name, path, kind: run.report.artefacts.__setitem__(name, str(path))
    details: dict = {}
    look = closer_for(run, robot, part, [first], TablePlane(), details)
    assert look is not None
    det = look(_ambiguous(part, [rival, T_true]))
    assert det.found and details["looks"]["d_peg"][-1]["made"]
    seconds = sum(t.times[-1] for t in robot.executed)
    assert run.report.robot_seconds["look"] == pytest.approx(seconds, abs=1e-3)
    assert run.report.robot_seconds["total"] == pytest.approx(1.0 + seconds, abs=1e-3)
    # what the judge saw is beside the report: the fixed view and each look, camera centre in the header
    made = [rec for rec in details["looks"]["d_peg"] if rec.get("made")]
    assert sorted(run.report.artefacts) == sorted(["view_0"] + [f"look_{i + 1}_d_peg" for i in range(len(made))])
    ply = tmp_path / "look_1_d_peg.ply"
    header = ply.read_bytes().split(b"end_header")[0].decode()
    eye = [float(v) for v in header.split("comment viewpoint ")[1].split()[:3]]
    assert np.allclose(eye, np.array(made[0]["T_world_cam_mm"]) / 1000.0, atol=1e-4)
    import open3d as o3d

    assert len(o3d.io.read_point_cloud(str(ply)).points) == made[0]["points"]
    assert len(o3d.io.read_point_cloud(str(tmp_path / "view_0.ply")).points) == len(first.cloud)
    run.execution.look_closer = 0  # switched off: no look at all
    assert closer_for(run, robot, part, [first], TablePlane(), details) is None


def test_a_look_that_settles_nothing_ranks_the_viewpoints_again_for_the_pair_it_leaves(case, monkeypatch) -> None:
    import asmteach.core.pipeline.active_look as al

    part, T_true, rival, first = case
    robot = _FlyingCamera(part.mesh, T_true)
    left = [T_true, T_true @ geometry.from_rotvec([0.0, 0.0, np.radians(90.0)])]  # what the first look leaves
    ranked_for: list[list[np.ndarray]] = []
    rank = al.rank_viewpoints

    def recording_rank(mesh, poses, *args, **kwargs):
        ranked_for.append([np.asarray(T, float) for T in poses])
        return rank(mesh, poses, *args, **kwargs)

    def judged_ambiguous(det, *args, **kwargs):
        verdict = {
            "winner": None,
            "best_T_world_part": left[0].tolist(),
            "closest_rival_T_world_part": left[1].tolist(),
        }
        details = {**det.details, "second_view": verdict}
        return det.model_copy(update={"reason": "still ambiguous", "details": details})

    monkeypatch.setattr(al, "rank_viewpoints", recording_rank)
    monkeypatch.setattr(al, "resolve_by_views", judged_ambiguous)
    out = look_closer(robot, _ambiguous(part, [rival, T_true]), part, [first], TablePlane(), _Straight(), looks=2)
    made = [rec for rec in out.looks[1:] if rec.get("made")]
    assert len(made) == 2 and [rec["ranking"] for rec in made] == [1, 2]
    assert len(ranked_for) == 2  # once for the fixed view's rivals, once for the pair the first look left
    assert np.allclose(ranked_for[0][0], rival) and np.allclose(ranked_for[1], left)
    assert made[0]["camera_xyz_mm"] != made[1]["camera_xyz_mm"]
    assert "rank_again_seconds" in made[0] and "rank_again_seconds" not in made[1]
