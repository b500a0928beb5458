"""cvfh_icp end to end on synthetic Kinect scenes, its view database, and every kind of bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from asmteach.core import geometry, registry
from asmteach.core.interfaces import PartModel
from asmteach.core.models import Placement, TablePlane
from asmteach.core.parts import build_part, load_structure
from asmteach.core.perception.depth_camera import DepthCamera, KinectSettings, look_at
from asmteach.plugins.detectors.cvfh.detector import CvfhIcpDetector
from asmteach.plugins.detectors.cvfh.scenes import DEFAULT_EYE, TableScene, place_on_table, render_table_scene
from asmteach.plugins.detectors.cvfh.views import (
    DescriptorSettings,
    ViewSettings,
    align_to_z,
    database_key,
    describe_cloud,
    load_or_build,
)

REPO = Path(__file__).resolve().parents[4]


@pytest.fixture(scope="module")
def l_block() -> PartModel:
    return build_part(load_structure(REPO / "configs/parts/set1/l_corner.yaml").part_a)


@pytest.fixture(scope="module")
def placements(l_block: PartModel) -> list[Placement]:
    from asmteach.core.rests.placements import compute_placements

    return compute_placements(l_block)


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("views")


@pytest.fixture(scope="module")
def detector(cache: Path, l_block: PartModel) -> CvfhIcpDetector:
    # The scenes are rendered from the renderer's default eye (table top at z = 0): the detector is told so.
    det = CvfhIcpDetector({"views": {"cache_dir": str(cache)}, "viewpoint": DEFAULT_EYE.tolist()}, seed=0)
    det.prepare(l_block)
    return det


def _scene(part: PartModel, T_table_part: np.ndarray, yaw: float, xy: tuple[float, float], seed: int) -> TableScene:
    T = place_on_table(part.mesh, T_table_part, yaw, xy)
    return render_table_scene(DepthCamera(KinectSettings(), seed=seed), part.mesh, T)


def test_registered_under_its_entry_point() -> None:
    assert registry.get_class("detectors", "cvfh_icp") is CvfhIcpDetector


@pytest.mark.parametrize(
    ("placement", "yaw_deg", "xy"),
    [(0, 35.0, (0.38, 0.10)), (1, -120.0, (0.52, -0.08)), (3, 170.0, (0.45, 0.0))],
)
def test_finds_the_part_on_the_table(
    detector: CvfhIcpDetector, l_block: PartModel, placements: list[Placement], placement: int, yaw_deg: float, xy
) -> None:
    scene = _scene(l_block, placements[placement].T_table_part, np.radians(yaw_deg), xy, seed=placement)
    det = detector.detect(scene.cloud, l_block)
    assert det.found, det.reason
    assert geometry.translation_distance(det.rough, scene.T_world_part) < 0.003
    assert np.degrees(geometry.rotation_distance(det.rough, scene.T_world_part)) < 3.0
    assert det.fitness > 0.9 and det.inlier_rmse < 0.0025
    assert set(det.timing_ms) >= {"segment", "cluster", "descriptors", "matching", "icp", "verify", "total"}
    # The fitted table is the true one (z = 0) to well under a millimetre.
    assert abs(det.details["table"]["height"]) < 0.0005


def test_view_database_is_42_icosphere_views_cached_on_disk(cache: Path, l_block: PartModel) -> None:
    views, desc, cam = ViewSettings(cache_dir=str(cache)), DescriptorSettings(), KinectSettings()
    db, built = load_or_build(l_block.mesh, l_block.source_hash, views, desc, cam)
    assert not built  # the detector fixture built it already
    assert db.T_acam_part.shape == (42, 4, 4) and db.view_dirs.shape == (42, 3)
    center = l_block.mesh.bounds.mean(axis=0)
    for i in range(42):
        # Camera centre of view i, in the part frame, sits on the icosphere vertex 0.8 m out.
        eye = geometry.invert(db.T_acam_part[i])[:3, 3]
        assert np.allclose(eye, center + 0.8 * db.view_dirs[i], atol=1e-9)
    # Aligned frames: the raw view centroid is on +z; the voxel-reduced one stays within half a degree.
    off_axis = np.degrees(np.arctan2(np.linalg.norm(db.centroids[:, :2], axis=1), db.centroids[:, 2]))
    assert np.all(off_axis < 0.5)
    assert len(db.hists) >= 42 and np.allclose(db.hists[:, :45].sum(axis=1), 1.0)
    # Another setting is another key; a damaged file is rebuilt.
    other = database_key(l_block.source_hash, ViewSettings(distance=0.9), desc, cam)
    assert other != db.key
    path = cache / f"{db.key}.npz"
    path.write_bytes(b"not a numpy file")
    db2, built2 = load_or_build(l_block.mesh, l_block.source_hash, views, desc, cam)
    assert built2 and np.allclose(db2.hists, db.hists)


def test_crh_roll_alignment_recovers_a_rolled_view(l_block: PartModel) -> None:
    """A view rolled about its axis is matched to the unrolled one with the right roll (before ICP)."""
    from asmteach.plugins.detectors.cvfh.descriptors import crh_roll_candidates

    cam = DepthCamera(KinectSettings.ideal())
    center = l_block.mesh.bounds.mean(axis=0)
    T_part_cam = look_at(center + 0.8 * np.array([0.5, -0.6, 0.62]), center)
    roll = np.radians(50.0)
    T_rolled = T_part_cam @ geometry.rot_z(roll)  # the camera turned about its optical axis
    clouds = []
    for T in (T_part_cam, T_rolled):
        pts = cam.render([(l_block.mesh, np.eye(4))], T).points_cam
        clouds.append(pts @ align_to_z(pts.mean(axis=0)).T)
    a, b = (describe_cloud(c, DescriptorSettings()) for c in clouds)
    assert a is not None and b is not None and a.crh is not None and b.crh is not None
    rolls = np.degrees(crh_roll_candidates(a.crh, b.crh))
    # Rolling the camera by +50 deg turns the image (and the normals' azimuths) by -50 deg.
    assert np.min(np.abs((rolls + 50.0 + 180.0) % 360.0 - 180.0)) < 5.0


def test_wrong_part_is_not_reported_found(detector: CvfhIcpDetector, l_block: PartModel) -> None:
    """A cube where the L-block should be: rejected, never a pose."""
    cube = build_part(load_structure(REPO / "configs/parts/set1/l_corner.yaml").part_b)
    scene = _scene(cube, np.eye(4), 0.4, (0.45, 0.05), seed=3)
    det = detector.detect(scene.cloud, l_block)
    assert not det.found and det.rough is None
    assert "not found" in det.reason or "no cluster" in det.reason


def test_bad_clouds_give_found_false_with_a_reason(
    detector: CvfhIcpDetector, l_block: PartModel, placements: list[Placement]
) -> None:
    scene = _scene(l_block, placements[0].T_table_part, 0.3, (0.45, 0.0), seed=9)
    rng = np.random.default_rng(0)
    table_only = scene.cloud[scene.frame.labels == 0]
    cases = {
        "empty": (np.zeros((0, 3)), "empty"),
        "all NaN": (np.full((500, 3), np.nan), "NaN"),
        "millimetres": (scene.cloud * 1000.0, "millimetres"),
        "no plane": (rng.normal(0.0, 0.3, (5000, 3)), "no table plane"),
        "tilted plane": (geometry.transform_points(geometry.from_rpy(1.2, 0, 0), table_only), "tilted"),
        "nothing above": (table_only, "nothing stands on the table"),
    }
    for name, (cloud, words) in cases.items():
        det = detector.detect(cloud, l_block)
        assert not det.found, name
        assert det.rough is None and det.corrected is None, name
        assert words in det.reason, (name, det.reason)


def test_known_table_is_used_and_nan_rows_ignored(
    detector: CvfhIcpDetector, l_block: PartModel, placements: list[Placement]
) -> None:
    scene = _scene(l_block, placements[2].T_table_part, 1.0, (0.40, -0.05), seed=4)
    cloud = np.vstack([scene.cloud, np.full((1000, 3), np.nan)])
    det = detector.detect(cloud, l_block, table=TablePlane(height=0.0))
    assert det.found, det.reason
    assert geometry.translation_distance(det.rough, scene.T_world_part) < 0.003
    assert det.details["table"]["height"] == 0.0


@pytest.mark.parametrize("yaw_deg", [0.0, 17.0, 38.0, 45.0, 71.0])
def test_cluster_width_is_the_tightest_box_at_any_yaw(yaw_deg: float) -> None:
    """A near-square footprint (54 x 52 mm, 24 mm high) measures its own diagonal at every yaw: its principal
    axes are undefined, and a box on them measured up to the footprint's diagonal on each side (110 mm, beyond
    the size check of the 79 mm part), so the block's cluster was never tried."""
    from asmteach.plugins.detectors.cvfh.detector import _width

    rng = np.random.default_rng(3)
    box = rng.uniform([-0.027, -0.026, 0.0], [0.027, 0.026, 0.024], (3000, 3))
    box[:, :2] += rng.normal(0.0, 0.0005, (3000, 2))  # a Kinect's edge noise
    c, s = np.cos(np.radians(yaw_deg)), np.sin(np.radians(yaw_deg))
    turned = box @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) + [0.4, -0.2, 0.0]
    assert _width(turned) == pytest.approx(np.linalg.norm([0.054, 0.052, 0.024]), abs=0.004)


def test_cluster_width_of_degenerate_clusters() -> None:
    from asmteach.plugins.detectors.cvfh.detector import _width

    line = np.column_stack([np.linspace(0.0, 0.03, 5), np.linspace(0.0, 0.04, 5), np.zeros(5)])
    assert _width(line) == pytest.approx(0.05, abs=1e-9)
    assert _width(line[:2]) == pytest.approx(0.0125, abs=1e-9)


def test_a_database_with_views_left_out_loads_from_its_cache(tmp_path: Path) -> None:
    """A view too small to describe has a NaN centroid and no region: its database is read back, not rebuilt
    on every load; a NaN in a described view still makes it unreadable."""
    from dataclasses import replace

    from asmteach.plugins.detectors.cvfh.views import ViewDatabase

    hists = np.full((3, 308), 1.0 / 308)
    db = ViewDatabase(
        key="k",
        T_acam_part=np.tile(np.eye(4), (3, 1, 1)),
        centroids=np.array([[0.0, 0.0, 0.8], [np.nan] * 3, [0.0, 0.0, 0.8]]),
        crh=np.zeros((3, 90)),
        hists=hists,
        region_view=np.array([0, 2, 2]),
        region_centroids=np.zeros((3, 3)),
        view_dirs=np.tile([0.0, 0.0, 1.0], (3, 1)),
    )
    back = ViewDatabase.load(db.save(tmp_path / "k.npz"))
    assert np.isnan(back.centroids[1]).all() and np.array_equal(back.region_view, [0, 2, 2])
    bad = replace(db, centroids=np.array([[np.nan] * 3, [np.nan] * 3, [0.0, 0.0, 0.8]]))
    with pytest.raises(ValueError, match="NaN"):
        ViewDatabase.load(bad.save(tmp_path / "bad.npz"))
