"""fpfh_ransac with a part given as a scan: the real Kinect milk carton found in its scene at the identity."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from asmteach.core import clouds, geometry
from asmteach.core.cli import main
from asmteach.core.interfaces import PartModel
from asmteach.core.models import TablePlane
from asmteach.core.parts import load_parts
from asmteach.plugins.detectors.fpfh.detector import FpfhRansacDetector

MAX_MM, MAX_DEG = 2.0, 2.0


def _error(T: np.ndarray) -> tuple[float, float]:
    """Distance of ``T`` from the identity: millimetres and degrees."""
    eye = np.eye(4)
    return 1000.0 * geometry.translation_distance(T, eye), float(np.degrees(geometry.rotation_distance(T, eye)))


@pytest.fixture(scope="module")
def milk(real_data: Path) -> tuple[PartModel, clouds.WorldCloud, Path]:
    kinect = real_data / "real/kinect"
    part = load_parts(kinect / "milk.pcd", scans=True)[0]
    scene = clouds.read_cloud(kinect / "milk_cartoon_all_small_clorox.pcd")
    # The scene is in the Kinect's frame and has no table truth: the table plane found in it gives the world.
    return part, clouds.to_world(scene, seed=0), kinect


def test_scan_part(milk: tuple[PartModel, clouds.WorldCloud, Path]) -> None:
    part, _, _ = milk
    assert part.points is not None and part.points.shape == (13704, 3)
    assert np.array_equal(part.scan_viewpoint, np.zeros(3))  # a camera-frame scan: the sensor at the origin
    assert part.mesh.is_watertight and 0.2 < float(np.max(part.mesh.extents)) < 0.3  # the hull, for size only


def test_milk_found_at_identity(milk: tuple[PartModel, clouds.WorldCloud, Path]) -> None:
    part, wc, _ = milk
    det = FpfhRansacDetector(seed=0)
    a = det.detect(wc.points, part, TablePlane(height=0.0), viewpoint=wc.viewpoint)
    assert a.found, a.reason
    mm, deg = _error(geometry.invert(wc.T_world_cam) @ a.rough)  # the pose in the camera frame: truth = identity
    assert mm < MAX_MM and deg < MAX_DEG, (mm, deg)
    assert a.details["model"] == "scan" and a.details["coverage"] > 0.9 and a.details["contradicted"] < 0.05
    assert a.fitness > 0.95
    b = FpfhRansacDetector(seed=0).detect(wc.points, part, TablePlane(height=0.0), viewpoint=wc.viewpoint)
    assert np.allclose(a.rough, b.rough, atol=1e-6)  # seeded: the same pose again


def test_wrong_size_scan_is_not_found(milk: tuple[PartModel, clouds.WorldCloud, Path]) -> None:
    """A carton 30% larger or smaller is not in the scene: the verification says so instead of a pose."""
    part, wc, _ = milk
    c = part.points.mean(axis=0)
    for k in (1.3, 0.7):
        other = dataclasses.replace(part, points=(part.points - c) * k + c, source_hash=f"scaled-{k}")
        d = FpfhRansacDetector(seed=0).detect(wc.points, other, TablePlane(height=0.0), viewpoint=wc.viewpoint)
        assert not d.found and d.rough is None and "rejected" in d.reason, k


def test_detect_command_with_a_scan(
    milk: tuple[PartModel, clouds.WorldCloud, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, _, kinect = milk
    model, scene = str(kinect / "milk.pcd"), str(kinect / "milk_cartoon_all_small_clorox.pcd")
    out = tmp_path / "det.json"
    assert main(["detect", model, "--cloud", scene, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "table_plane" in printed
    doc = json.loads(out.read_text())
    assert doc["found"] and doc["frame_source"] == "table_plane" and doc["detector"] == "fpfh_ransac"
    assert doc["model"] == "scan" and doc["corrector"] is None and doc["corrected"] is None
    mm, deg = _error(np.asarray(doc["camera_frame"]["rough"]["T_cam_part"]))
    assert mm < MAX_MM and deg < MAX_DEG, (mm, deg)
    # The same with the camera pose from a file (here: the one the table plane gave, as a calibration writes it).
    flat = ", ".join(f"{v:.12g}" for v in np.ravel(doc["T_world_cam"]))
    ext = tmp_path / "extrinsics.yaml"
    ext.write_text(f"T_world_cam: {{rows: 4, cols: 4, data: [{flat}]}}\n")
    out2 = tmp_path / "det2.json"
    assert main(["detect", model, "--cloud", scene, "--out", str(out2), "--extrinsics", str(ext)]) == 0
    doc2 = json.loads(out2.read_text())
    assert doc2["frame_source"] == "extrinsics"
    mm2, deg2 = _error(np.asarray(doc2["camera_frame"]["rough"]["T_cam_part"]))
    assert mm2 < MAX_MM and deg2 < MAX_DEG
    capsys.readouterr()
    # What a scan cannot do, and options that contradict each other: one line, exit 2, nothing written.
    bad = tmp_path / "bad.json"
    for extra, words in (
        (["--detector", "cvfh_icp"], "needs a mesh"),
        (["--corrector", "stable_placements"], "closed surface"),
        (["--viewpoint", "0", "0", "1"], "--viewpoint is for a world-frame cloud"),
        (["--frame", "world", "--extrinsics", str(ext)], "drop it or --frame world"),
        (["--extrinsics", str(tmp_path / "none.yaml")], "no such file"),
    ):
        assert main(["detect", model, "--cloud", scene, "--out", str(bad), *extra]) == 2, extra
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0] and not bad.exists(), (extra, err)


def test_scan_as_a_part_file(tmp_path: Path) -> None:
    """A part YAML's ``mesh`` may name a cloud; a PLY without faces is a scan, one with faces a mesh."""
    import trimesh

    box = trimesh.creation.box(extents=(0.06, 0.04, 0.03))
    pts = trimesh.sample.sample_surface(box, 3000, seed=0)[0] + np.array([0.0, 0.0, 0.8])
    clouds.write_pcd(tmp_path / "scan.pcd", pts)
    (tmp_path / "part.yaml").write_text("name: boxscan\nmesh: scan.pcd\n")
    from asmteach.core.errors import UserError

    with pytest.raises(UserError, match="only `asmteach detect` takes a part given as a scan"):
        load_parts(tmp_path / "part.yaml")  # placements, grasps, planning: a closed mesh is needed
    part = load_parts(tmp_path / "part.yaml", scans=True)[0]
    assert part.name == "boxscan" and part.points is not None and len(part.points) == 3000
    assert np.allclose(part.mesh.extents, (0.06, 0.04, 0.03), atol=1e-3)
    box.export(tmp_path / "mesh.ply")
    assert load_parts(tmp_path / "mesh.ply", scans=True)[0].points is None
    from asmteach.core.perception.depth_camera import write_cloud_ply

    assert load_parts(write_cloud_ply(tmp_path / "cloud.ply", pts), scans=True)[0].points is not None
    # A scan in millimetres given as metres, and a flat one: one line each.
    clouds.write_pcd(tmp_path / "mm.pcd", pts * 1000.0)
    with pytest.raises(UserError, match="millimetres"):
        load_parts(tmp_path / "mm.pcd", scans=True)
    assert load_parts(tmp_path / "mm.pcd", units="mm", scans=True)[0].points is not None
    flat = pts.copy()
    flat[:, 2] = 0.8
    clouds.write_pcd(tmp_path / "flat.pcd", flat)
    with pytest.raises(UserError, match="flat"):
        load_parts(tmp_path / "flat.pcd", scans=True)


def test_verify_scan_along_rays(milk: tuple[PartModel, clouds.WorldCloud, Path]) -> None:
    """The true pose is explained along the camera's rays; the same scan 3 cm aside or 3 cm nearer is not."""
    from asmteach.plugins.detectors.fpfh.detector import FpfhSettings, scan_model, verify_scan

    part, wc, _ = milk
    s = FpfhSettings()
    model = scan_model(part, s.scan_spacing, s.normal_radius)
    pts = wc.points[np.all(np.isfinite(wc.points), axis=1)]
    T = wc.T_world_cam  # the truth: the scan's frame is the camera's
    cluster = geometry.transform_points(T, model.points)
    context = pts[np.linalg.norm(pts - cluster.mean(axis=0), axis=1) < 0.4]
    ok = verify_scan(T, cluster, context, wc.viewpoint, model, s.refine, s.scan_min_coverage)
    assert ok.accepted and ok.coverage > 0.95 and ok.contradicted < 0.01, ok
    toward = wc.viewpoint - cluster.mean(axis=0)
    for shift in (np.array([0.03, 0.0, 0.0]), 0.03 * toward / np.linalg.norm(toward)):  # aside; toward the camera
        moved = geometry.from_rotation(np.eye(3), shift) @ T
        bad = verify_scan(moved, cluster, context, wc.viewpoint, model, s.refine, s.scan_min_coverage)
        assert not bad.accepted and bad.coverage < 0.5, bad
