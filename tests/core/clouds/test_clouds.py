"""core.clouds: PCD in all three encodings (NaNs, extra fields, VIEWPOINT), LZF, units, extrinsics, frames."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

import asmteach.core  # noqa: F401  (libusb before open3d)
from asmteach.core import clouds, geometry
from asmteach.core.errors import UserError
from asmteach.core.perception.depth_camera import look_at, write_cloud_ply

import open3d as o3d  # isort: skip

ENCODINGS = ("ascii", "binary", "binary_compressed")


def _organized(seed: int = 0) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A 6 x 5 organized cloud (metres) with NaN rows and label / rgba / intensity fields."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1.0, 1.0, (30, 3))
    pts[[0, 7, 8, 29]] = np.nan
    fields = {
        "label": rng.integers(0, 5, 30).astype(np.uint32),
        "rgba": (np.uint32(255) << 24) | rng.integers(0, 2**24, 30).astype(np.uint32),
        "intensity": rng.uniform(0, 1, 30).astype(np.float32),
    }
    return pts, fields


@pytest.mark.parametrize("data", ENCODINGS)
def test_pcd_round_trip(tmp_path: Path, data: str) -> None:
    pts, fields = _organized()
    T = geometry.from_rpy(0.1, -0.2, 0.3, [0.5, -0.25, 1.5])
    path = clouds.write_pcd(
        tmp_path / f"c_{data}.pcd", pts, fields=fields, width=6, height=5, T_data_sensor=T, data=data
    )  # type: ignore[arg-type]
    c = clouds.read_cloud(path)
    assert c.encoding == data and (c.width, c.height) == (6, 5) and c.organized
    assert c.points.shape == (30, 3) and c.grid().shape == (5, 6, 3)
    nan = ~c.finite
    assert nan.tolist() == np.isnan(pts).any(axis=1).tolist()  # NaN rows kept in place: the image grid holds
    assert np.allclose(c.points[~nan], pts[~nan].astype(np.float32), atol=0, rtol=0)
    assert np.array_equal(c.labels, fields["label"]) and c.fields["label"].dtype == np.uint32
    assert np.array_equal(c.fields["rgba"], fields["rgba"])
    assert np.array_equal(c.fields["intensity"], fields["intensity"])
    rgb = np.stack([(fields["rgba"] >> s) & 255 for s in (16, 8, 0)], axis=1)
    assert np.array_equal(c.colors, rgb)
    assert np.allclose(c.T_data_sensor, T, atol=1e-9) and np.allclose(c.viewpoint, [0.5, -0.25, 1.5])
    # Open3D reads what we write (its PCD reader keeps NaN rows and drops the fields it does not know).
    o3_pts = np.asarray(o3d.io.read_point_cloud(str(path)).points)
    assert np.allclose(o3_pts, pts.astype(np.float32), equal_nan=True)


def test_identity_viewpoint_says_nothing(tmp_path: Path) -> None:
    path = clouds.write_pcd(tmp_path / "plain.pcd", np.eye(3))
    c = clouds.read_cloud(path)
    assert c.T_data_sensor is None and c.viewpoint is None and not c.organized and c.labels is None
    assert c.colors is None


def test_lzf_known_streams() -> None:
    # Literal run: control byte 2 -> 3 bytes follow.
    assert clouds.lzf_decompress(b"\x02abc", 3) == b"abc"
    # Back-reference overlapping what it writes (a run): length 6, distance 3.
    assert clouds.lzf_decompress(b"\x02abc\x80\x02", 9) == b"abcabcabc"
    # Long back-reference: top bits 7 + extra length byte 11 -> 7 + 11 + 2 = 20 bytes at distance 1.
    assert clouds.lzf_decompress(b"\x00a\xe0\x0b\x00", 21) == b"a" * 21
    # Non-overlapping reference of 3 bytes at distance 4 after two literal runs.
    assert clouds.lzf_decompress(b"\x03wxyz\x20\x03", 7) == b"wxyzwxy"
    for bad, size in ((b"\x02ab", 3), (b"\x20\x05", 3), (b"\x02abc", 4), (b"\x02abc\x80", 9), (b"\x05abc", 3)):
        with pytest.raises(ValueError):
            clouds.lzf_decompress(bad, size)
    data = np.random.default_rng(1).bytes(1000)
    assert clouds.lzf_decompress(clouds.lzf_literal(data), 1000) == data
    assert clouds.lzf_literal(b"") == b""


def test_units_auto_mm_and_refusals(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    scene_mm = rng.uniform(0, 1500.0, (500, 3)) + np.array([0, 0, 600.0])  # a 1.5 m wide scene written in millimetres
    path = clouds.write_pcd(tmp_path / "mm.pcd", scene_mm)
    c = clouds.read_cloud(path)
    assert c.scale == pytest.approx(0.001) and np.allclose(c.points, scene_mm.astype(np.float32) * 0.001)
    assert any("millimetres" in n for n in c.notes)
    with pytest.raises(UserError, match="millimetres") as exc:
        clouds.read_cloud(path, units="m")
    assert "\n" not in str(exc.value)
    assert np.allclose(clouds.read_cloud(path, units="mm").points, c.points)
    metres = clouds.write_pcd(tmp_path / "m.pcd", scene_mm * 0.001)
    assert clouds.read_cloud(metres).scale == 1.0
    # 20 units across is millimetres for a part's scan (at most 2 m), metres for a scene (up to 30 m).
    part_mm = rng.uniform(0, 20.0, (500, 3))
    pp = clouds.write_pcd(tmp_path / "part.pcd", part_mm)
    assert clouds.read_cloud(pp, kind="part").scale == pytest.approx(0.001)
    assert clouds.read_cloud(pp, kind="scene").scale == 1.0
    # Far too wide for either unit.
    huge = clouds.write_pcd(tmp_path / "huge.pcd", rng.uniform(0, 1e6, (100, 3)))
    with pytest.raises(UserError, match="too wide"):
        clouds.read_cloud(huge)


def test_ply_viewpoint_and_xyz(tmp_path: Path) -> None:
    pts = np.random.default_rng(3).uniform(0, 0.5, (50, 3))
    c = clouds.read_cloud(write_cloud_ply(tmp_path / "v.ply", pts, [0.1, 0.2, 0.9]))
    assert c.encoding == "open3d" and np.allclose(c.viewpoint, [0.1, 0.2, 0.9])
    assert np.allclose(c.points, pts.astype(np.float32))
    xyz = tmp_path / "p.xyz"
    np.savetxt(xyz, pts)
    assert np.allclose(clouds.read_cloud(xyz).points, pts) and clouds.read_cloud(xyz).viewpoint is None


def _bad_files(tmp: Path) -> list[tuple[Path, str]]:
    good = clouds.write_pcd(tmp / "good.pcd", np.random.default_rng(4).uniform(0, 1, (40, 3)), data="binary")
    raw = good.read_bytes()
    out = []

    def put(name: str, data: bytes, words: str) -> None:
        (tmp / name).write_bytes(data)
        out.append((tmp / name, words))

    put("truncated.pcd", raw[:-100], "truncated")
    put("nodata.pcd", raw[: raw.index(b"DATA")], "no DATA line")
    put("garbage.pcd", b"hello\nworld\nDATA ascii\n1 2 3\n", "header")
    put("noz.pcd", raw.replace(b"FIELDS x y z", b"FIELDS x y w"), "no 'z' field")
    put("badvp.pcd", raw.replace(b"VIEWPOINT 0.0 0.0 0.0 1.0", b"VIEWPOINT 0.0 0.0 0.0 2.0"), "unit quaternion")
    put("badtype.pcd", raw.replace(b"TYPE F F F", b"TYPE F F Q"), "field type")
    put("count.pcd", raw.replace(b"POINTS 40", b"POINTS 41"), "POINTS")
    put("nan.pcd", clouds.write_pcd(tmp / "n.pcd", np.full((5, 3), np.nan), data="ascii").read_bytes(), "no finite")
    comp = clouds.write_pcd(tmp / "comp.pcd", np.random.default_rng(5).uniform(0, 1, (40, 3)), data="binary_compressed")
    head, body = comp.read_bytes().split(b"DATA binary_compressed\n")
    csize, usize = struct.unpack("<II", body[:8])
    corrupt = struct.pack("<II", csize, usize) + b"\x1f" + body[9:20]  # a literal run that runs off the end
    put("corrupt.pcd", head + b"DATA binary_compressed\n" + corrupt, "corrupt")
    put("size.pcd", head + b"DATA binary_compressed\n" + struct.pack("<II", csize, usize + 4) + body[8:], "needs")
    put("empty.ply", b"", "no finite")
    return out


def test_bad_files_give_one_line(tmp_path: Path) -> None:
    for path, words in _bad_files(tmp_path):
        with pytest.raises(UserError) as exc:
            clouds.read_cloud(path, what="--cloud")
        msg = str(exc.value)
        assert words in msg and "\n" not in msg and len(msg) < 300, (path.name, msg)
    with pytest.raises(UserError, match="no such file"):
        clouds.read_cloud(tmp_path / "missing.pcd")
    (tmp_path / "mesh.stl").write_text("solid x\nendsolid x\n")
    with pytest.raises(UserError, match="not a point-cloud file"):
        clouds.read_cloud(tmp_path / "mesh.stl")


def test_real_kinect_files(real_data: Path) -> None:
    kinect = real_data / "real/kinect"
    scene = clouds.read_cloud(kinect / "milk_cartoon_all_small_clorox.pcd")
    assert scene.encoding == "binary_compressed" and (scene.width, scene.height) == (640, 480)
    assert scene.points.shape == (307200, 3) and int((~scene.finite).sum()) == 65793
    assert scene.T_data_sensor is None and scene.scale == 1.0 and not scene.notes
    assert scene.colors is not None and scene.colors.shape == (307200, 3)
    assert scene.colors[scene.finite].std() > 10  # real colours, not a constant
    # liblzf's streams, decoded by the pure-Python LZF: the same points as Open3D's own PCD reader.
    o3_pts = np.asarray(o3d.io.read_point_cloud(str(kinect / "milk_cartoon_all_small_clorox.pcd")).points)
    assert np.array_equal(o3_pts, scene.points, equal_nan=True)
    milk = clouds.read_cloud(kinect / "milk.pcd")
    assert milk.points.shape == (13704, 3) and milk.finite.all() and not milk.organized
    # The model is an exact subset of the scene (the README's identity ground truth).
    from scipy.spatial import cKDTree

    d, _ = cKDTree(scene.valid_points()).query(milk.points)
    assert d.max() == 0.0
    mosd = clouds.read_cloud(kinect / "mosd/test0.pcd")
    assert (mosd.width, mosd.height) == (640, 480) and mosd.labels is not None
    assert sorted(np.unique(mosd.labels).tolist()) == [0, 1, 20, 30]
    assert mosd.fields["label"].dtype == np.uint32 and mosd.colors is not None
    # Every labelled object point is a valid depth point (the labels index the image grid).
    assert mosd.finite[mosd.labels > 0].all()


# --------------------------------------------------------------------------------------------- frames
TABLE_H = 0.72
EYE = np.array([-0.55, 0.1, TABLE_H + 0.6])
T_WORLD_CAM = look_at(EYE, [0.0, 0.0, TABLE_H])


def _world_scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 1.2 m x 1.2 m table top at TABLE_H (noisy) with a 10 cm box on it; returns (points, is_table)."""
    rng = np.random.default_rng(seed)
    table = np.column_stack([rng.uniform(-0.6, 0.6, (20000, 2)), np.full(20000, TABLE_H)])
    box = np.column_stack([rng.uniform(-0.05, 0.05, (2000, 2)), np.full(2000, TABLE_H + 0.1)])
    side = np.column_stack(
        [np.full(1000, -0.05), rng.uniform(-0.05, 0.05, 1000), rng.uniform(TABLE_H, TABLE_H + 0.1, 1000)]
    )
    table = table[np.max(np.abs(table[:, :2]), axis=1) > 0.05]  # the box hides the table under it
    pts = np.vstack([table, box, side])
    pts[:, 2] += rng.normal(0, 0.001, len(pts))
    return pts, np.arange(len(pts)) < len(table)


def _extrinsics_files(tmp: Path) -> list[Path]:
    T = T_WORLD_CAM
    files = []
    flat = ", ".join(f"{v:.12g}" for v in T.ravel())
    (tmp / "a.yaml").write_text(f"camera_name: kinect\nT_world_cam: {{rows: 4, cols: 4, data: [{flat}]}}\n")
    (tmp / "b.json").write_text(json.dumps({"T_cam_world": geometry.invert(T).tolist()}))
    q = geometry.to_quat(T)
    t = ", ".join(f"{k}: {v!r}" for k, v in zip("xyz", T[:3, 3].tolist(), strict=True))
    r = ", ".join(f"{k}: {v!r}" for k, v in zip("xyzw", q.tolist(), strict=True))
    (tmp / "c.yaml").write_text(f"transform:\n  translation: {{{t}}}\n  rotation: {{{r}}}\n")
    # solvePnP of a board lying on the table: OpenCV's board z points into the table (down).
    T_world_board = geometry.from_rotation(np.diag([1.0, -1.0, -1.0]), [0, 0, 0])
    T_cam_board = geometry.invert(T) @ T_world_board
    rvec = cv2.Rodrigues(T_cam_board[:3, :3])[0].ravel()
    (tmp / "d.yaml").write_text(f"rvec: {rvec.tolist()}\ntvec: {T_cam_board[:3, 3].tolist()}\n")
    fs = cv2.FileStorage(str(tmp / "e.yml"), cv2.FILE_STORAGE_WRITE)
    fs.write("T_world_cam", T)
    fs.release()
    files += [tmp / n for n in ("a.yaml", "b.json", "c.yaml", "d.yaml", "e.yml")]
    return files


def test_load_extrinsics_forms(tmp_path: Path) -> None:
    for path in _extrinsics_files(tmp_path):
        ext = clouds.load_extrinsics(path)
        assert np.allclose(ext.T_world_cam, T_WORLD_CAM, atol=1e-9), path.name
        assert path.name in ext.source
    for text, words in (
        ("T_world_cam: [1, 2, 3]\n", "4x4"),
        ("T_world_cam: [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n", "not a rotation"),
        ("T_world_cam: [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,1,1]]\n", "last row"),
        ("rotation: [0, 0, 0, 2]\ntranslation: [0, 0, 1]\n", "unit quaternion"),
        ("camera_name: x\n", "no camera pose"),
        ("- 1\n- 2\n", "mapping"),
    ):
        (tmp_path / "bad.yaml").write_text(text)
        with pytest.raises(UserError, match=words) as exc:
            clouds.load_extrinsics(tmp_path / "bad.yaml")
        assert "\n" not in str(exc.value)
    with pytest.raises(UserError, match="no such file"):
        clouds.load_extrinsics(tmp_path / "none.yaml")


def test_to_world_with_extrinsics_and_table_plane(tmp_path: Path) -> None:
    world, is_table = _world_scene()
    cam = geometry.transform_points(geometry.invert(T_WORLD_CAM), world)
    path = clouds.write_pcd(tmp_path / "cam.pcd", cam, data="binary_compressed")
    cloud = clouds.read_cloud(path)
    assert clouds.guess_frame(cloud)[0] == "camera"
    # The extrinsics give the world back exactly (float32 storage aside).
    wc = clouds.to_world(cloud, extrinsics=clouds.load_extrinsics(_extrinsics_files(tmp_path)[0]))
    assert wc.frame == "extrinsics" and np.allclose(wc.points, world, atol=2e-6)
    assert np.allclose(wc.viewpoint, EYE, atol=1e-9)
    # The table plane: the table top at the height asked for, z up, the camera at its true height above it.
    wt = clouds.to_world(cloud, table_height=TABLE_H, seed=0)
    assert wt.frame == "table_plane" and wt.table is not None and "table plane" in wt.how
    assert abs(np.median(wt.points[is_table, 2]) - TABLE_H) < 5e-4
    assert np.allclose(wt.T_world_cam[:3, 2] @ [0, 0, 1], T_WORLD_CAM[:3, 2] @ [0, 0, 1], atol=1e-3)  # same tilt
    assert abs(wt.viewpoint[2] - EYE[2]) < 1e-3
    box_top = wt.points[~is_table][:2000, 2]
    assert abs(np.median(box_top) - (TABLE_H + 0.1)) < 1e-3  # objects stand above the table: z is up
    # Heights above the table agree with the truth point by point (the plane frame differs only by a yaw
    # about z and a shift in x, y).
    assert np.allclose(wt.points[:, 2], wc.points[:, 2], atol=3e-3)


def test_guess_frame_world_clouds(tmp_path: Path) -> None:
    world, _ = _world_scene(1)
    # A world cloud whose table is at 0.72 m: every z > 0, but the origin is under the table.
    assert clouds.guess_frame(clouds.read_cloud(clouds.write_pcd(tmp_path / "w.pcd", world)))[0] == "world"
    # Table at z = 0: half the table points are below 0.
    low = world - [0, 0, TABLE_H]
    frame, why = clouds.guess_frame(clouds.read_cloud(clouds.write_pcd(tmp_path / "w0.pcd", low)))
    assert frame == "world" and "z > 0" in why
    # A file that records its sensor's position is in the frame of that position.
    cam = geometry.transform_points(geometry.invert(T_WORLD_CAM), world)
    ply = write_cloud_ply(tmp_path / "v.ply", cam, [0.0, 0.0, 0.0])
    assert clouds.guess_frame(clouds.read_cloud(ply))[0] == "world"


def test_table_plane_of_the_real_milk_scene(real_data: Path) -> None:
    """No table truth here: the plane frame must put most of the cloud on z = 0 and the carton above it."""
    kinect = real_data / "real/kinect"
    scene = clouds.read_cloud(kinect / "milk_cartoon_all_small_clorox.pcd")
    assert clouds.guess_frame(scene)[0] == "camera"
    wc = clouds.to_world(scene, seed=0)
    z = wc.points[scene.finite, 2]
    assert np.mean(np.abs(z) < 0.01) > 0.6
    milk = geometry.transform_points(wc.T_world_cam, clouds.read_cloud(kinect / "milk.pcd").points)
    assert np.percentile(milk[:, 2], 1) > -0.005 and milk[:, 2].max() > 0.15  # stands on it, ~20 cm tall
    assert 0.3 < wc.viewpoint[2] < 1.0 and wc.table is not None and 20 < wc.table.tilt_deg < 60


def test_table_plane_refused_without_a_table() -> None:
    rng = np.random.default_rng(6)
    blob = rng.normal([0, 0, 1.0], 0.2, (5000, 3))
    with pytest.raises(UserError, match="extrinsics"):
        clouds.table_frame(blob)
