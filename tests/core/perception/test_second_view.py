"""A second depth view settles a D peg one view cannot: scenes rendered here with the Kinect model (noise on)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from asmteach.core import geometry
from asmteach.core.detect_correct import detect_and_correct
from asmteach.core.interfaces import Detector, PartModel
from asmteach.core.models import Detection, TablePlane
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.core.perception.second_view import DepthView, SecondViewSettings, judge_rivals
from asmteach.core.pose_error import pose_error
from asmteach.core.symmetry import part_symmetries

EYE_1 = np.array([-0.05, 0.0, 0.70])  # the robot's side of the table, as the scene Kinect
EYE_2 = np.array([0.98, 0.0, 0.53])  # across the table, 45 deg down
TARGET = np.array([0.45, 0.0, 0.0])


@pytest.fixture(scope="module")
def peg(d_peg_part: PartModel) -> PartModel:
    return d_peg_part


class _Ambiguous(Detector):
    """Says what a one-view detector says of this scene: the view is explained as well by two poses."""

    def __init__(self, poses: list[np.ndarray]) -> None:
        super().__init__()
        self.poses = poses

    def detect(
        self, cloud: np.ndarray, part: PartModel, table: TablePlane | None = None, viewpoint: np.ndarray | None = None
    ) -> Detection:
        return Detection(
            part=part.name,
            found=False,
            reason="ambiguous: a pose 0 mm and 35 deg away explains the view as well",
            timing_ms={"total": 1.0},
            details={
                "ambiguous": [{"T_world_part": T.tolist(), "score": 0.99} for T in self.poses],
                "ambiguous_kind": "near_twin",
                "viewpoint": EYE_1.tolist(),
            },
        )


def test_the_second_view_finds_the_d_peg_the_first_cannot_tell(peg: PartModel, d_peg_poses, table_kinect_view) -> None:
    T_true, rival = d_peg_poses  # the rival: the flat turned down, out of camera 1's sight
    first = table_kinect_view(peg.mesh, T_true, EYE_1, seed=1)
    second = table_kinect_view(peg.mesh, T_true, EYE_2, seed=2)
    # the rival listed first: the second view, not the order, must decide
    det = detect_and_correct(_Ambiguous([rival, T_true]), None, first.cloud, peg, TablePlane(), views=[second])
    assert det.found and det.reason is None
    err = pose_error(det.rough, T_true, right=part_symmetries(peg.mesh, peg.center_of_mass))  # end over end: the same
    assert err.within(2.0, 3.0), err
    judged = det.details["resolved_by_view"]
    assert judged["winner"] == 1 and judged["views"] == 2 and judged["kind"] == "near_twin"
    assert judged["closest_rival_gain"] >= 50.0 and judged["closest_rival_z"] >= 5.0
    assert det.details["first_view_reason"].startswith("ambiguous")
    # without the second view the detection is as the detector left it
    alone = detect_and_correct(_Ambiguous([rival, T_true]), None, first.cloud, peg, TablePlane())
    assert not alone.found and "resolved_by_view" not in alone.details
    # and a second camera beside the first sees no more than it
    beside = table_kinect_view(peg.mesh, T_true, EYE_1 + np.array([0.0, 0.05, 0.0]), seed=3)
    det = detect_and_correct(_Ambiguous([rival, T_true]), None, first.cloud, peg, TablePlane(), views=[beside])
    assert not det.found and det.reason.startswith("still ambiguous after 2 views: no pose is clearly preferred")


def test_a_flat_that_neither_camera_sees_stays_ambiguous(peg: PartModel, table_kinect_view) -> None:
    """Resting on its flat, the peg turned a little about its round axis differs only underneath."""
    R = geometry.from_rotvec([0.0, np.pi / 2, 0.0])[:3, :3]  # the flat (normal +x) faces down
    T_true = geometry.from_rotation(R, [0.45, 0.0, 0.0])
    T_true[2, 3] -= geometry.transform_points(T_true, peg.mesh.vertices)[:, 2].min()
    centre = geometry.transform_points(T_true, [[0.0, 0.0, 0.0]])[0]  # on the round axis
    turn = geometry.from_rotvec([0.0, np.radians(15.0), 0.0])
    rival = geometry.from_rotation(turn[:3, :3], centre - turn[:3, :3] @ centre) @ T_true
    first = table_kinect_view(peg.mesh, T_true, EYE_1, seed=1)
    second = table_kinect_view(peg.mesh, T_true, EYE_2, seed=2)
    det = detect_and_correct(_Ambiguous([T_true, rival]), None, first.cloud, peg, TablePlane(), views=[second])
    assert not det.found
    assert det.reason.startswith("still ambiguous after 2 views: no pose is clearly preferred")
    assert det.details["second_view"]["winner"] is None and det.details["second_view"]["views"] == 2


def test_a_view_weighs_its_rays_by_its_own_sensor(peg: PartModel, d_peg_poses, table_kinect_view) -> None:
    """A close, low-noise camera's view: the same residuals cost more sigmas than the Kinect's would."""
    from asmteach.core.perception.registration import model_cloud
    from asmteach.core.perception.second_view import ray_costs

    T_true, rival = d_peg_poses
    view = table_kinect_view(peg.mesh, T_true, EYE_2, seed=2)
    quiet = KinectSettings(axial_a=0.0002, axial_b=0.0, quantize=False)
    model = model_cloud(peg.mesh, 4000)
    kinect, _ = ray_costs(model, [T_true, rival], view, TablePlane())
    own, _ = ray_costs(model, [T_true, rival], DepthView(view.cloud, view.viewpoint, quiet), TablePlane())
    passed, _ = ray_costs(model, [T_true, rival], view, TablePlane(), sensor=quiet)
    assert np.array_equal(own, passed)  # the view's sensor is the one a caller could pass
    assert own[1].sum() - own[0].sum() > kinect[1].sum() - kinect[0].sum()


def test_a_close_look_never_settles_a_twin_it_cannot_tell_from_the_truth(table_kinect_view, holed_block) -> None:
    """The hole faces the table: no camera sees it, so the block and its twin turned 180 deg about the normal
    explain every view alike. The listed rivals are the twin and the block on its side; the grid's cheapest
    candidate (one refined: ``refine_top=1``) is not in the truth's basin. The twin must not win for want of the
    truth in the comparison (d_peg 1 seed 9: a close look settled such a block 180 deg off, gain 12649)."""
    mesh = holed_block
    T_true = geometry.from_rotation(np.eye(3), [0.45, 0.0, 0.02])
    twin = T_true @ geometry.from_rotvec([0.0, 0.0, np.pi])
    side = T_true @ geometry.from_rotvec([np.pi / 2, 0.0, 0.0])
    side[2, 3] = 0.018
    first = table_kinect_view(mesh, T_true, EYE_1, seed=1)
    close = KinectSettings.wrist_stereo()
    eye = TARGET + 0.15 * np.array([np.cos(np.radians(200.0)), np.sin(np.radians(200.0)), 1.0]) / np.sqrt(2.0)
    table = trimesh.creation.box(extents=[0.8, 1.2, 0.02])
    T_table = geometry.from_rotation(np.eye(3), [0.45, 0.0, -0.01])
    frame = DepthCamera(close, seed=2).render([(table, T_table), (mesh, T_true)], look_at(eye, TARGET))
    views = [first, DepthView(frame.points_world, eye, close)]
    syms = part_symmetries(mesh, np.asarray(mesh.center_mass))
    verdict = judge_rivals(mesh, [twin, side], views, TablePlane(), syms, settings=SecondViewSettings(refine_top=1))
    assert verdict.winner is None and verdict.why.startswith("no pose is clearly preferred")
    # the two compared were the truth and its twin, both refined onto the views
    assert min(pose_error(verdict.pose, T, right=syms).angle_deg for T in (T_true, twin)) < 1.0


def test_rays_that_misfit_together_count_as_fewer_independent_rays() -> None:
    from asmteach.core.perception.second_view import ray_inflation

    rng = np.random.default_rng(3)
    blocks = np.repeat(np.arange(500), 16)  # 500 blocks of 16 rays
    alone = rng.normal(size=blocks.size) ** 2  # each ray its own noise
    assert ray_inflation(alone, blocks) == pytest.approx(1.0, abs=0.25)
    together = np.repeat(rng.normal(size=500) ** 2, 16)  # a block's rays misfit as one
    assert ray_inflation(together, blocks) == pytest.approx(16.0, rel=1e-6)
    half = np.repeat(rng.normal(size=1000) ** 2, 8)  # in pairs of 8 within each block of 16
    assert 6.0 < ray_inflation(half, blocks) < 10.0
    assert ray_inflation(together, np.arange(blocks.size)) == 1.0  # each ray its own block: nothing to inflate


def test_rays_are_blocked_by_where_they_cross_the_part() -> None:
    from asmteach.core.perception.second_view import _ray_blocks

    # a grid of points 1 mm apart on a plane 0.2 m in front of the camera: 2 mm squares hold 2 x 2 of them
    xs = (np.arange(20) - 9.5) * 0.001
    gx, gy = np.meshgrid(xs, xs)
    cloud = np.c_[gx.ravel(), gy.ravel(), np.full(gx.size, 0.2)]
    view = DepthView(cloud, np.zeros(3))
    blocks = _ray_blocks(view, np.array([[0.0, 0.0, 0.2]]), 0.05, 0.002)
    assert len(blocks) == len(cloud)
    assert np.bincount(blocks).max() <= 4 and len(np.unique(blocks)) >= 100
    # the same rays on a plane 0.4 m away cross it twice as far apart: one a square
    far = _ray_blocks(DepthView(2.0 * cloud, np.zeros(3)), np.array([[0.0, 0.0, 0.4]]), 0.05, 0.002)
    assert len(np.unique(far)) == len(cloud)


def _slab() -> trimesh.Trimesh:
    """A 43 mm square slab whose sides slope in to a smaller, off-centre face (ff_stone's shape, metres); it rests
    on the smaller face, so from above every camera sees the square and only the outline pins its turn."""
    top = [[-0.0133, -0.0155], [0.0133, -0.0155], [0.0133, 0.0112], [-0.0133, 0.0112]]
    big = [[-0.0216, -0.0216], [0.0216, -0.0216], [0.0216, 0.0216], [-0.0216, 0.0216]]
    points = np.array([[x, y, -0.0076] for x, y in big] + [[x, y, 0.0076] for x, y in top])
    return trimesh.convex.convex_hull(points)


def _slab_views(mesh: trimesh.Trimesh, T_true: np.ndarray, table_kinect_view) -> list[DepthView]:
    """The scene Kinect and a wrist look 0.16 m away, 75 deg above the table."""
    close = KinectSettings.wrist_stereo()
    target = T_true[:3, 3]
    a, e = np.radians(120.0), np.radians(75.0)
    eye = target + 0.16 * np.array([np.cos(a) * np.cos(e), np.sin(a) * np.cos(e), np.sin(e)])
    table = trimesh.creation.box(extents=[0.8, 1.2, 0.02])
    T_table = geometry.from_rotation(np.eye(3), [0.45, 0.0, -0.01])
    frame = DepthCamera(close, seed=2).render([(table, T_table), (mesh, T_true)], look_at(eye, target))
    return [table_kinect_view(mesh, T_true, EYE_1, seed=1), DepthView(frame.points_world, eye, close)]


def _slab_on_its_small_face(mesh: trimesh.Trimesh) -> np.ndarray:
    T = geometry.from_rotation(geometry.from_rpy(np.pi, 0.0, np.radians(-12.8))[:3, :3], [0.34, 0.13, 0.0])
    T[2, 3] -= geometry.transform_points(T, mesh.vertices)[:, 2].min()
    return T


def test_polish_moves_a_pose_to_its_least_ray_cost_by_the_outline(table_kinect_view) -> None:
    """Seen from above the slab is a flat square: ICP on its points cannot pin the shift and turn, the rays that
    meet the table or the part at its outline can."""
    from asmteach.core.perception.registration import model_cloud
    from asmteach.core.perception.second_view import _polish, _rays, ray_costs

    mesh = _slab()
    T_true = _slab_on_its_small_face(mesh)
    views = _slab_views(mesh, T_true, table_kinect_view)
    model, s = model_cloud(mesh, 4000), SecondViewSettings()
    start = geometry.from_rotvec([0.0, 0.0, np.radians(1.0)], [0.0008, -0.0003, 0.0]) @ T_true
    rays = [_rays(model, v, [T_true], None, s) for v in views]
    polished = _polish(model, start, rays, TablePlane(), s)
    err = pose_error(polished, T_true)
    assert err.within(0.25, 0.3), err

    def total(T: np.ndarray) -> float:
        return sum(float(ray_costs(model, [T], v, TablePlane(), settings=s, around=[T_true])[0].sum()) for v in views)

    assert total(polished) < total(start) - 100.0
    # from the truth it stays put
    assert pose_error(_polish(model, T_true, rays, TablePlane(), s), T_true).within(0.15, 0.2)


def test_a_slab_seen_only_from_above_is_never_settled_turned(table_kinect_view) -> None:
    """ff_stone scene 1 (four Kinect frames and a wrist look): ICP left the truth's candidate 0.9 mm / 0.9 deg off,
    2900 sigma^2 above its basin's floor, and the slab turned 90 deg won at z 12.6. Every candidate compared is
    polished on the ray cost: the turn and the truth are then a few tens of sigma^2 apart, no winner."""
    mesh = _slab()
    T_true = _slab_on_its_small_face(mesh)
    views = _slab_views(mesh, T_true, table_kinect_view)
    centre = geometry.transform_points(T_true, [mesh.bounds.mean(axis=0)])[0]
    turn = geometry.from_rotvec([0.0, 0.0, np.pi / 2])[:3, :3]
    rival = geometry.from_rotation(turn, centre - turn @ centre) @ T_true
    near = geometry.from_rotvec([0.0, 0.0, np.radians(0.9)], [0.0008, 0.0003, 0.0]) @ T_true
    syms = part_symmetries(mesh, np.asarray(mesh.center_mass))
    verdict = judge_rivals(mesh, [rival, near], views, TablePlane(), syms)
    if verdict.winner is not None:  # a winner, if any, is the truth
        assert pose_error(verdict.pose, T_true, right=syms).within(5.0, 5.0)
    else:
        assert verdict.why.startswith("no pose is clearly preferred")
