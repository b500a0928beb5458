"""The one point-cloud reader: PCD (ascii, binary, binary_compressed), PLY and XYZ, units, and frames.

:func:`read_cloud` reads the scenes ``asmteach detect`` is given (real Kinect files as well as our own
renders, :func:`asmteach.core.perception.depth_camera.write_cloud_ply`) and a part's model given as a
scan (:func:`asmteach.core.parts.build_cloud_part`).

What a file may hold, and what comes back (:class:`Cloud`):

* PCD v0.7 (PCL's format), all three encodings. ``binary_compressed`` is PCL's LZF-compressed
  structure-of-arrays layout, decompressed by :func:`lzf_decompress` (pure Python, 0.4-0.6 s for a
  640x480 Kinect frame: no C extension to build, and the one path CI tests).
  Organized clouds (``HEIGHT > 1``) keep their NaN rows, so ``points.reshape(height, width, 3)`` is the
  depth image's grid; extra fields (``label``, ``rgb``/``rgba``, normals, anything) come back in
  ``fields`` by name, one row per point. The ``VIEWPOINT tx ty tz qw qx qy qz`` header is the sensor's
  pose in the cloud's frame (``T_data_sensor``); PCL writes the identity when it knows nothing, and a
  sensor driver writes it because its points *are* in the sensor frame.
* PLY and XYZ (``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.pts``) through Open3D, NaNs kept; a PLY's
  ``comment viewpoint X Y Z`` line (what our renderer writes) is the camera centre in the cloud's frame.

Units: clouds are metres inside. ``units="auto"`` looks at the extent (a depth sensor sees a few metres,
a part is at most ~1 m) and converts a cloud that is plainly in millimetres, with a warning in the log and
in ``Cloud.notes``; ``units="m"`` refuses it (:class:`UserError`); ``units="mm"`` scales by 0.001.

Frames. A sensor gives its cloud in its camera frame (OpenCV: x right, y down, z forward, metres), while
the detectors want the world frame (z up, the table top at the configured height). :func:`to_world`
maps a camera-frame cloud to the world with either the camera's pose from an extrinsics file
(:func:`load_extrinsics`) or, when none is given, the table plane found in the cloud
(:func:`table_frame`: z along the table normal toward the camera, x along the optical axis projected on
the table, origin below the camera at the table height), and says which it used. :func:`guess_frame`
tells a camera-frame cloud from a world-frame one.
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike

from asmteach.core import geometry
from asmteach.core.errors import UserError

__all__ = [
    "CLOUD_SUFFIXES",
    "Cloud",
    "Extrinsics",
    "TableFrame",
    "WorldCloud",
    "depth_sigma",
    "guess_frame",
    "load_extrinsics",
    "lzf_decompress",
    "lzf_literal",
    "read_cloud",
    "read_pcd",
    "robust_extent",
    "table_frame",
    "to_world",
    "write_pcd",
]

log = logging.getLogger(__name__)

CLOUD_SUFFIXES = frozenset({".pcd", ".ply", ".xyz", ".xyzn", ".xyzrgb", ".pts"})
"""File suffixes :func:`read_cloud` reads."""

PLY_VIEWPOINT = "comment viewpoint"
"""PLY header line prefix followed by the camera centre ``X Y Z`` (the cloud's frame, metres)."""

# A depth sensor sees a few metres at most (Kinect v1: 0.4-4 m, up to ~10 m of noise); a scene whose
# robust extent exceeds this many "metres" is in millimetres. A part is 10 mm to 1 m (core.parts), so a
# part's scan more than this wide is in millimetres too.
MAX_SCENE_EXTENT_M = 30.0
MAX_PART_EXTENT_M = 2.0

_PCD_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("U", 1): "<u1", ("U", 2): "<u2", ("U", 4): "<u4",
              ("U", 8): "<u8", ("I", 1): "<i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8"}


@dataclass
class Cloud:
    """A cloud as read from a file: points in the file's frame (metres) and every other field.

    ``points`` is ``(n, 3) float64`` in metres (after any unit conversion), NaN rows kept (an organized
    cloud's invalid pixels); ``fields`` maps each extra field name to its ``(n,)`` or ``(n, count)`` array
    in the file's type (``label`` uint32, ``rgba`` uint32, ...). ``width`` x ``height`` is the PCD
    organisation (``height == 1``: unorganized). ``T_data_sensor`` is the sensor pose in the cloud's frame
    (4x4, metres) when the file gives one that says something (a PCD ``VIEWPOINT`` other than PCL's
    identity default; a PLY ``comment viewpoint``, which gives the centre only: identity rotation).
    """

    points: np.ndarray
    fields: dict[str, np.ndarray] = field(default_factory=dict)
    width: int = 0
    height: int = 1
    T_data_sensor: np.ndarray | None = None
    path: Path | None = None
    encoding: str = ""
    """``ascii``, ``binary``, ``binary_compressed`` (PCD) or ``open3d`` (PLY/XYZ)."""
    scale: float = 1.0
    """Factor applied to the file's coordinates to get metres (0.001 for a millimetre cloud)."""
    notes: list[str] = field(default_factory=list)

    @property
    def organized(self) -> bool:
        """Whether the cloud is a ``height x width`` image of points (a depth sensor's frame)."""
        return self.height > 1

    @property
    def finite(self) -> np.ndarray:
        """``(n,) bool``: rows whose three coordinates are finite (the sensor gave a return)."""
        return np.all(np.isfinite(self.points), axis=1)

    def valid_points(self) -> np.ndarray:
        """``(m, 3)`` finite points (metres, the file's frame)."""
        return self.points[self.finite]

    @property
    def viewpoint(self) -> np.ndarray | None:
        """``(3,)`` sensor centre in the cloud's frame (metres), or ``None`` when the file says nothing."""
        return None if self.T_data_sensor is None else self.T_data_sensor[:3, 3].copy()

    @property
    def labels(self) -> np.ndarray | None:
        """The ``label`` field (``(n,)`` ints), or ``None``."""
        lab = self.fields.get("label")
        return None if lab is None else np.asarray(lab).reshape(len(self.points))

    @property
    def colors(self) -> np.ndarray | None:
        """``(n, 3) uint8`` RGB from a PCD ``rgb``/``rgba`` field (packed ``0xAARRGGBB``) or a PLY's colours."""
        if "colors" in self.fields:
            return self.fields["colors"]
        for name in ("rgba", "rgb"):
            if name in self.fields:
                packed = np.ascontiguousarray(self.fields[name]).reshape(len(self.points))
                as_u32 = packed.view("<u4") if packed.dtype.itemsize == 4 else packed.astype("<u4")
                return np.stack([(as_u32 >> 16) & 255, (as_u32 >> 8) & 255, as_u32 & 255], axis=1).astype(np.uint8)
        return None

    def grid(self, values: np.ndarray | None = None) -> np.ndarray:
        """``values`` (default: the points) as the ``(height, width, ...)`` image of an organized cloud."""
        if not self.organized:
            raise ValueError("the cloud is not organized (PCD HEIGHT 1): it has no image grid")
        v = self.points if values is None else np.asarray(values)
        return v.reshape(self.height, self.width, *v.shape[1:])


# --------------------------------------------------------------------------------------------- LZF
def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decompress an LZF stream (liblzf's format, the one PCL's ``binary_compressed`` uses) to ``size`` bytes.

    Tokens: a control byte below 32 starts a literal run of ``ctrl + 1`` bytes; otherwise the top three
    bits are the back-reference length - 2 (7: one more length byte follows) and the low five bits with the
    next byte the distance - 1. Overlapping references (runs: the NaN stretches of a depth image) are
    copied a period at a time. Raises ``ValueError`` on a corrupt stream.
    """
    src = memoryview(bytes(data))
    buf = bytearray(size)
    ip = op = 0
    n = len(src)
    try:
        while ip < n:
            ctrl = src[ip]
            ip += 1
            if ctrl < 32:
                ln = ctrl + 1
                if op + ln > size or ip + ln > n:
                    raise ValueError("LZF literal run overflows")
                buf[op:op + ln] = src[ip:ip + ln]
                ip += ln
                op += ln
                continue
            ln = ctrl >> 5
            if ln == 7:
                ln += src[ip]
                ip += 1
            ref = op - ((ctrl & 0x1F) << 8) - src[ip] - 1
            ip += 1
            ln += 2
            if ref < 0 or op + ln > size:
                raise ValueError("LZF back-reference out of range")
            dist = op - ref
            if dist >= ln:
                buf[op:op + ln] = buf[ref:ref + ln]
            else:  # the reference overlaps what it writes: repeat its period
                period = bytes(buf[ref:op])
                buf[op:op + ln] = (period * (ln // dist + 1))[:ln]
            op += ln
    except IndexError:
        raise ValueError("LZF stream ends inside a token") from None
    if op != size:
        raise ValueError(f"LZF stream decompresses to {op} bytes, the header says {size}")
    return bytes(buf)


def lzf_literal(data: bytes) -> bytes:
    """``data`` as a valid LZF stream of literal runs only (32 bytes per run, 1/32 larger than ``data``).

    What :func:`write_pcd` puts in a ``binary_compressed`` file: liblzf, PCL and :func:`lzf_decompress`
    read it. No back-references are searched for (a pure-Python matcher would take seconds per frame);
    the encoding exists for files that must be ``binary_compressed``, not to save space.
    """
    raw = bytes(data)
    return b"".join(bytes((len(raw[i:i + 32]) - 1,)) + raw[i:i + 32] for i in range(0, len(raw), 32))


# --------------------------------------------------------------------------------------------- PCD
@dataclass
class _PcdHeader:
    fields: list[str]
    sizes: list[int]
    types: list[str]
    counts: list[int]
    width: int
    height: int
    points: int
    viewpoint: np.ndarray
    data: str
    offset: int


def _pcd_header(raw: bytes, path: Path) -> _PcdHeader:
    keys: dict[str, list[str]] = {}
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise UserError(f"{path}: PCD header has no DATA line; the file is truncated or not a PCD")
        line = raw[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        keys[key.upper()] = vals
        if key.upper() == "DATA":
            break
    try:
        fields = keys["FIELDS"]
        n = len(fields)
        sizes = [int(v) for v in keys.get("SIZE", ["4"] * n)]
        types = [v.upper() for v in keys.get("TYPE", ["F"] * n)]
        counts = [int(v) for v in keys.get("COUNT", ["1"] * n)]
        width = int(keys["WIDTH"][0])
        height = int(keys.get("HEIGHT", ["1"])[0])
        points = int(keys.get("POINTS", [str(width * height)])[0])
        vp = np.array([float(v) for v in keys.get("VIEWPOINT", ["0", "0", "0", "1", "0", "0", "0"])], dtype=float)
        data = keys["DATA"][0].lower()
    except (KeyError, IndexError, ValueError) as exc:
        raise UserError(f"{path}: PCD header is missing or garbles {exc}; expected PCL's v0.7 header") from None
    if not (len(sizes) == len(types) == len(counts) == n):
        raise UserError(f"{path}: PCD header FIELDS/SIZE/TYPE/COUNT disagree in length")
    for t, s in zip(types, sizes, strict=True):
        if (t, s) not in _PCD_TYPES:
            raise UserError(f"{path}: PCD field type {t}{s} is not one PCL writes (F4/F8, U1-8, I1-8)")
    if vp.shape != (7,) or not np.all(np.isfinite(vp)):
        raise UserError(f"{path}: PCD VIEWPOINT should hold 7 finite numbers (tx ty tz qw qx qy qz)")
    if points != width * height:
        raise UserError(f"{path}: PCD POINTS {points} != WIDTH {width} x HEIGHT {height}")
    if data not in {"ascii", "binary", "binary_compressed"}:
        raise UserError(f"{path}: PCD DATA {data!r} is not ascii, binary or binary_compressed")
    for axis in "xyz":
        if axis not in fields:
            raise UserError(f"{path}: PCD has no {axis!r} field (FIELDS {' '.join(fields)})")
    return _PcdHeader(fields, sizes, types, counts, width, height, points, vp, data, pos)


def read_pcd(path: str | Path) -> Cloud:
    """Read a PCD file (ascii, binary or binary_compressed), organisation, NaNs, extra fields and VIEWPOINT.

    Coordinates are returned as stored (no unit check: :func:`read_cloud` does that). :class:`UserError`
    on a file that is not a readable PCD.
    """
    p = Path(path)
    raw = p.read_bytes()
    h = _pcd_header(raw, p)
    n = h.points
    dtypes = [np.dtype(_PCD_TYPES[(t, s)]) for t, s in zip(h.types, h.sizes, strict=True)]
    columns: dict[str, np.ndarray] = {}
    body = raw[h.offset:]
    if h.data == "ascii":
        text = body.decode("ascii", errors="replace").split()
        total = sum(h.counts)
        if len(text) < n * total:
            raise UserError(f"{p}: PCD ascii data hold {len(text)} values, need {n * total}")
        # Every value as float64 first: exact for every PCL type but 64-bit ints above 2^53 (never seen).
        table = np.array(text[: n * total], dtype=np.float64).reshape(n, total)
        col = 0
        for name, dt, c in zip(h.fields, dtypes, h.counts, strict=True):
            columns[name] = table[:, col:col + c].astype(dt)
            col += c
    elif h.data == "binary":
        rec = np.dtype([(f"f{i}", dt, (c,)) for i, (dt, c) in enumerate(zip(dtypes, h.counts, strict=True))])
        if len(body) < n * rec.itemsize:
            raise UserError(f"{p}: PCD binary data hold {len(body)} bytes, need {n * rec.itemsize}; truncated")
        arr = np.frombuffer(body, dtype=rec, count=n)
        for i, name in enumerate(h.fields):
            columns[name] = arr[f"f{i}"]
    else:
        if len(body) < 8:
            raise UserError(f"{p}: PCD binary_compressed data are missing their sizes")
        csize, usize = struct.unpack("<II", body[:8])
        need = n * sum(dt.itemsize * c for dt, c in zip(dtypes, h.counts, strict=True))
        if usize != need:
            raise UserError(f"{p}: PCD binary_compressed holds {usize} bytes uncompressed, the header needs {need}")
        try:
            plain = lzf_decompress(body[8:8 + csize], usize) if n else b""
        except ValueError as exc:
            raise UserError(f"{p}: PCD binary_compressed data are corrupt ({exc})") from None
        # PCL's compressed layout is one array per field (all x, then all y, ...), not one record per point.
        off = 0
        for name, dt, c in zip(h.fields, dtypes, h.counts, strict=True):
            k = n * c * dt.itemsize
            columns[name] = np.frombuffer(plain, dtype=dt, count=n * c, offset=off).reshape(n, c)
            off += k
    pts = np.column_stack([np.asarray(columns[a], dtype=np.float64).reshape(n) for a in "xyz"])
    extras = {k: (v.reshape(n) if v.ndim == 2 and v.shape[1] == 1 else v).copy()
              for k, v in columns.items() if k not in ("x", "y", "z") and k != "_"}
    vp = h.viewpoint
    T = None
    if not np.allclose(vp, [0, 0, 0, 1, 0, 0, 0]):
        q = vp[3:7]
        if abs(np.linalg.norm(q) - 1.0) > 1e-3:
            raise UserError(f"{p}: PCD VIEWPOINT quaternion (qw qx qy qz) {q.tolist()} is not a unit quaternion")
        T = geometry.from_quat([q[1], q[2], q[3], q[0]], vp[:3])
    return Cloud(points=pts, fields=extras, width=h.width, height=h.height, T_data_sensor=T, path=p,
                 encoding=h.data)


def write_pcd(
    path: str | Path,
    points: ArrayLike,
    *,
    fields: dict[str, np.ndarray] | None = None,
    width: int | None = None,
    height: int = 1,
    T_data_sensor: ArrayLike | None = None,
    data: Literal["ascii", "binary", "binary_compressed"] = "binary",
) -> Path:
    """Write ``(n, 3)`` points (metres; NaN rows allowed) and extra ``(n,)`` fields as a PCD v0.7 file.

    ``width`` x ``height`` is the organisation (default unorganized); ``T_data_sensor`` the sensor pose in
    the cloud's frame (the ``VIEWPOINT`` header; identity when ``None``). PCL, Open3D and :func:`read_pcd`
    read it. Coordinates and float fields are stored as float32, integer fields as (u)int32.
    ``binary_compressed`` is PCL's field-by-field layout in an LZF stream of literal runs
    (:func:`lzf_literal`): readable by PCL, not smaller.
    """
    from asmteach.core.io import write_bytes

    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = len(pts)
    cols: list[tuple[str, np.ndarray]] = [("x", pts[:, 0].astype("<f4")), ("y", pts[:, 1].astype("<f4")),
                                          ("z", pts[:, 2].astype("<f4"))]
    for name, vals in (fields or {}).items():
        arr = np.asarray(vals).reshape(n)
        if arr.dtype.kind == "f":
            arr = arr.astype("<f4")
        elif arr.dtype.kind in "ub":
            arr = arr.astype("<u4")
        else:
            arr = arr.astype("<i4")
        cols.append((name, arr))
    width = n if width is None else int(width)
    if width * height != n:
        raise ValueError(f"write_pcd: width {width} x height {height} != {n} points")
    if T_data_sensor is None:
        vp = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    else:
        T = geometry.as_transform(T_data_sensor)
        qx, qy, qz, qw = geometry.to_quat(T)
        vp = [*T[:3, 3].tolist(), qw, qx, qy, qz]
    kind = {"f": "F", "u": "U", "i": "I"}
    header = [
        "# .PCD v0.7 - Point Cloud Data file format (asmteach)",
        "VERSION 0.7",
        "FIELDS " + " ".join(c for c, _ in cols),
        "SIZE " + " ".join("4" for _ in cols),
        "TYPE " + " ".join(kind[a.dtype.kind] for _, a in cols),
        "COUNT " + " ".join("1" for _ in cols),
        f"WIDTH {width}",
        f"HEIGHT {height}",
        "VIEWPOINT " + " ".join(repr(float(v)) for v in vp),
        f"POINTS {n}",
        f"DATA {data}",
    ]
    head = ("\n".join(header) + "\n").encode("ascii")
    if data == "ascii":
        rows = []
        for i in range(n):
            rows.append(" ".join(repr(float(a[i])) if a.dtype.kind == "f" else str(int(a[i])) for _, a in cols))
        body = ("\n".join(rows) + ("\n" if rows else "")).encode("ascii")
    elif data == "binary":
        rec = np.empty(n, dtype=[(c, a.dtype) for c, a in cols])
        for c, a in cols:
            rec[c] = a
        body = rec.tobytes()
    elif data == "binary_compressed":
        plain = b"".join(np.ascontiguousarray(a).tobytes() for _, a in cols)  # all x, then all y, ...
        packed = lzf_literal(plain)
        body = struct.pack("<II", len(packed), len(plain)) + packed
    else:
        raise ValueError(f"write_pcd: data must be 'ascii', 'binary' or 'binary_compressed', got {data!r}")
    return write_bytes(path, head + body)


# --------------------------------------------------------------------------------------------- PLY/XYZ
def _read_open3d(p: Path) -> Cloud:
    import asmteach.core  # noqa: F401  (loads libusb before open3d)

    import open3d as o3d  # isort: skip

    pc = o3d.io.read_point_cloud(str(p), remove_nan_points=False, remove_infinite_points=False)
    pts = np.asarray(pc.points, dtype=np.float64).reshape(-1, 3)
    fields: dict[str, np.ndarray] = {}
    if pc.has_colors():
        fields["colors"] = np.clip(np.round(np.asarray(pc.colors) * 255.0), 0, 255).astype(np.uint8)
    if pc.has_normals():
        fields["normals"] = np.asarray(pc.normals, dtype=np.float64)
    T = None
    if p.suffix.lower() == ".ply":
        eye = _ply_viewpoint(p)
        if eye is not None:
            T = geometry.from_rotation(np.eye(3), eye)
    if len(pts) == 0 and p.stat().st_size > 0:
        raise UserError(f"{p}: no points read: the file holds none, or is not a point-cloud {p.suffix} Open3D reads")
    return Cloud(points=pts, fields=fields, width=len(pts), height=1, T_data_sensor=T, path=p, encoding="open3d")


def _ply_viewpoint(p: Path) -> np.ndarray | None:
    with p.open("rb") as fh:
        head = fh.read(65536)
    for raw in head.split(b"\n"):
        line = raw.decode("ascii", errors="replace").strip()
        if line == "end_header":
            return None
        if line.startswith(PLY_VIEWPOINT + " "):
            try:
                eye = np.array([float(v) for v in line[len(PLY_VIEWPOINT):].split()[:3]], dtype=float)
            except ValueError:
                eye = np.array([])
            if eye.shape != (3,) or not np.all(np.isfinite(eye)):
                raise UserError(f"{p}: header line {line!r} should hold 3 finite numbers; fix it or give --viewpoint")
            return eye
    return None


# --------------------------------------------------------------------------------------------- reader
def read_cloud(
    path: str | Path,
    *,
    units: Literal["auto", "m", "mm"] = "auto",
    kind: Literal["scene", "part"] = "scene",
    what: str = "cloud",
) -> Cloud:
    """Read any cloud asmteach takes (PCD, PLY, XYZ) into metres; see the module docstring.

    ``kind`` sets the unit check: a ``scene`` (a sensor's view, up to tens of metres) or a ``part``'s scan
    (at most 2 m across, as a part's mesh). ``what`` names the input in messages (``--cloud``).
    :class:`UserError` for a missing, unreadable or empty file, or millimetres given as ``units="m"``.
    """
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{what}: no such file {p}")
    suffix = p.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise UserError(f"{what}: {p.name} is not a point-cloud file; give a .pcd, .ply or .xyz")
    cloud = read_pcd(p) if suffix == ".pcd" else _read_open3d(p)
    fin = cloud.finite
    if not fin.any():
        raise UserError(f"{what}: {p.name} holds no finite point ({len(cloud.points)} rows, all NaN or empty)")
    _apply_units(cloud, units, kind, what)
    return cloud


def robust_extent(points: np.ndarray) -> float:
    """Largest 1st-99th percentile spread over x, y, z of the finite points (units of the points)."""
    pts = points[np.all(np.isfinite(points), axis=1)]
    if len(pts) == 0:
        return 0.0
    sample = pts[:: max(1, len(pts) // 20000)]
    lo, hi = np.percentile(sample, [1, 99], axis=0)
    return float(np.max(hi - lo))


def _apply_units(cloud: Cloud, units: str, kind: str, what: str) -> None:
    name = cloud.path.name if cloud.path is not None else "cloud"
    if units == "mm":
        _scale(cloud, 0.001)
        return
    limit = MAX_PART_EXTENT_M if kind == "part" else MAX_SCENE_EXTENT_M
    ext = robust_extent(cloud.points)
    if ext <= limit:
        return
    if units == "m":
        raise UserError(
            f"{what}: {name} spans {ext:.0f} units, too wide for metres (a {kind} is at most {limit:.0f} m); "
            "it looks like millimetres: pass units mm"
        )
    if ext / 1000.0 > limit:
        raise UserError(f"{what}: {name} spans {ext:.0f} units, too wide for metres or millimetres; check the file")
    _scale(cloud, 0.001)
    note = f"{name} spans {ext:.0f} units: read as millimetres and scaled to metres"
    cloud.notes.append(note)
    log.warning("%s: %s", what, note)


def _scale(cloud: Cloud, s: float) -> None:
    cloud.points = cloud.points * s
    cloud.scale *= s
    if cloud.T_data_sensor is not None:
        cloud.T_data_sensor = cloud.T_data_sensor.copy()
        cloud.T_data_sensor[:3, 3] *= s


# --------------------------------------------------------------------------------------------- frames
@dataclass
class Extrinsics:
    """The camera's pose in the world, ``T_world_cam`` (4x4, metres; camera frame OpenCV's), and its source."""

    T_world_cam: np.ndarray
    source: str


def _matrix(node: Any, shape: tuple[int, ...], key: str, p: Path) -> np.ndarray:
    if isinstance(node, dict) and "data" in node:  # ROS / OpenCV-YAML style {rows, cols, data}
        node = node["data"]
    try:
        arr = np.asarray(node, dtype=float)
        arr = arr.reshape(shape)
    except (TypeError, ValueError):
        raise UserError(f"{p}: {key}: expected {'x'.join(map(str, shape))} numbers") from None
    if not np.all(np.isfinite(arr)):
        raise UserError(f"{p}: {key}: holds a non-finite number")
    return arr


def _rigid(T: np.ndarray, key: str, p: Path) -> np.ndarray:
    R = T[:3, :3]
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise UserError(f"{p}: {key}: the last row must be 0 0 0 1")
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0.999:
        raise UserError(f"{p}: {key}: the rotation part is not a rotation (R R^T != I or det != 1)")
    # Re-orthonormalise: files carry 6-10 digits.
    U, _, Vt = np.linalg.svd(R)
    out = T.copy()
    out[:3, :3] = U @ Vt
    return out


EXTRINSICS_KEYS = ("T_world_cam", "T_cam_world", "rvec/tvec", "translation + rotation")


def load_extrinsics(path: str | Path) -> Extrinsics:
    """The camera's pose in the world from a YAML/JSON file (metres, radians; world z up).

    One of (the forms calibrations and hand-eye tools write):

    * ``T_world_cam``: 4x4 (nested lists or ``{rows: 4, cols: 4, data: [...]}``), the camera in the world;
    * ``T_cam_world``: 4x4, the world in the camera (its inverse);
    * ``rvec`` and ``tvec`` (3 numbers each): OpenCV's pose of a board lying on the table in the camera,
      what ``solvePnP`` or ``calibrateCamera`` give for the view (``T_cam_board``); the world is the board
      with z up (OpenCV's board z points into the board, so it is turned half a turn about x when the
      camera would otherwise be below the table);
    * ``translation`` (x y z) and ``rotation`` (quaternion ``x y z w``): the camera in the world, as a ROS
      ``TransformStamped`` or easy_handeye writes it.

    Matrices may be written as ``asmteach calibrate`` writes ``camera_matrix`` (``{rows, cols, data}``), so a
    camera YAML with a ``T_world_cam`` key added is an extrinsics file too (other keys are ignored). An
    OpenCV FileStorage file (``%YAML:1.0``) with these keys works too. :class:`UserError` names a bad file.
    """
    p = Path(path)
    if not p.is_file():
        raise UserError(f"--extrinsics: no such file {p}")
    text = p.read_text(encoding="utf-8", errors="replace")
    if text.lstrip().startswith("%YAML"):
        raw = _filestorage(p)
    else:
        from asmteach.core.io import read_yaml

        raw = read_yaml(p)
    if isinstance(raw, dict) and isinstance(raw.get("transform"), dict):
        raw = raw["transform"]  # a TransformStamped's transform
    if not isinstance(raw, dict):
        raise UserError(f"{p}: an extrinsics file must be a mapping with one of {', '.join(EXTRINSICS_KEYS)}")
    if "T_world_cam" in raw:
        T = _rigid(_matrix(raw["T_world_cam"], (4, 4), "T_world_cam", p), "T_world_cam", p)
        return Extrinsics(T, f"{p.name}: T_world_cam")
    if "T_cam_world" in raw:
        T = _rigid(_matrix(raw["T_cam_world"], (4, 4), "T_cam_world", p), "T_cam_world", p)
        return Extrinsics(geometry.invert(T), f"{p.name}: T_cam_world (inverted)")
    if "rvec" in raw and "tvec" in raw:
        rv = _matrix(raw["rvec"], (3,), "rvec", p)
        tv = _matrix(raw["tvec"], (3,), "tvec", p)
        T_board_cam = geometry.invert(geometry.from_rotvec(rv, tv))
        if T_board_cam[2, 3] >= 0:
            return Extrinsics(T_board_cam, f"{p.name}: rvec/tvec (board on the table, z up)")
        # OpenCV's board frame has z = x cross y pointing *into* the board, away from a camera that sees it:
        # for a board lying on the table that is down. Half a turn about the board's x makes the world z up.
        T_world_cam = geometry.from_rotation(np.diag([1.0, -1.0, -1.0])) @ T_board_cam
        return Extrinsics(T_world_cam, f"{p.name}: rvec/tvec (board on the table, its z turned up)")
    if "translation" in raw and "rotation" in raw:
        t, q = raw["translation"], raw["rotation"]
        if isinstance(t, dict):
            t = [t.get(k) for k in "xyz"]
        if isinstance(q, dict):
            q = [q.get(k) for k in "xyzw"]
        tv = _matrix(t, (3,), "translation", p)
        qv = _matrix(q, (4,), "rotation", p)
        if abs(np.linalg.norm(qv) - 1.0) > 1e-3:
            raise UserError(f"{p}: rotation: {qv.tolist()} is not a unit quaternion (x y z w)")
        return Extrinsics(geometry.from_quat(qv / np.linalg.norm(qv), tv), f"{p.name}: translation + rotation")
    raise UserError(f"{p}: no camera pose found; give one of {', '.join(EXTRINSICS_KEYS)}")


def _filestorage(p: Path) -> dict[str, Any]:
    import cv2

    fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
    try:
        out: dict[str, Any] = {}
        for key in ("T_world_cam", "T_cam_world", "rvec", "tvec"):
            node = fs.getNode(key)
            if not node.empty():
                mat = node.mat()
                out[key] = mat.tolist() if mat is not None else None
        return out
    finally:
        fs.release()


@dataclass
class TableFrame:
    """The world frame a table plane defines, seen from the camera.

    ``T_world_cam`` (4x4): world z along the table normal toward the camera, x the optical axis projected on
    the table, origin below the camera at ``table_height``. ``normal_cam`` and ``offset_cam`` are the plane
    in the camera frame (``normal . p = offset``, metres, normal toward the camera); ``inliers`` the share
    of the valid points on it; ``camera_height`` the camera centre's height above the table, metres;
    ``tilt_deg`` the angle between the optical axis and the table.
    """

    T_world_cam: np.ndarray
    normal_cam: np.ndarray
    offset_cam: float
    inliers: float
    camera_height: float
    tilt_deg: float
    table_height: float


def depth_sigma(z: np.ndarray) -> np.ndarray:
    """Kinect v1 axial noise std (metres) at depth ``z`` (metres): ``0.0012 + 0.0019 (z - 0.4)^2``.

    Nguyen, Izadi and Lovell (2012), the model our virtual Kinect uses too; it is why thresholds on real
    clouds grow with the square of the depth.
    """
    return 0.0012 + 0.0019 * (np.asarray(z, dtype=float) - 0.4) ** 2


def table_frame(
    points_cam: np.ndarray,
    *,
    table_height: float = 0.0,
    seed: int = 0,
    min_fraction: float = 0.15,
    min_camera_height: float = 0.1,
) -> TableFrame:
    """Find the table in a camera-frame cloud (metres) and the world frame it defines (see :class:`TableFrame`).

    The table is the largest plane (RANSAC on a 1 cm voxel grid, 2.5 sigma of the Kinect's depth noise at
    the cloud's median depth but at least 1 cm, seeded) among the planes whose side toward the camera holds
    most of the other points: objects stand on a table, while a wall has them in front of it but the
    camera's optical axis runs into it (rejected when it is within 30 deg of facing the camera head-on and
    a horizontal-looking plane is available). The plane is refined by least squares on its points within 3
    sigma of their own depth. :class:`UserError` when no plane holds ``min_fraction`` of the points or the
    camera is less than ``min_camera_height`` above it (then the cloud is not in a camera frame looking at
    a table: give --extrinsics, or the cloud in the world frame).
    """
    import asmteach.core  # noqa: F401  (loads libusb before open3d)

    import open3d as o3d  # isort: skip

    pts = np.asarray(points_cam, dtype=float)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) < 100:
        raise UserError(f"no table plane: the cloud has {len(pts)} valid points")
    z_med = float(np.median(pts[:, 2]))
    dist = max(0.01, 2.5 * float(depth_sigma(z_med)))
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts)).voxel_down_sample(0.01)
    rest = np.asarray(pc.points)
    o3d.utility.random.seed(int(seed))
    candidates = []
    work = pc
    for _ in range(3):
        if len(work.points) < 50:
            break
        model, inl = _plane_one_thread(o3d, work, dist)
        n = np.asarray(model[:3], dtype=float)
        d = -float(model[3])
        s = float(np.linalg.norm(n))
        n, d = n / s, d / s
        if d > 0:  # orient the normal toward the camera: the camera (origin) has n.0 - d > 0
            n, d = -n, -d
        frac = len(inl) / len(rest)
        h = rest @ n - d
        off = np.abs(h) > dist
        # Share of the points off the plane on the camera's side (objects on a table, not behind a wall).
        front = float(np.mean(h[off] > 0)) if off.any() else 1.0
        facing = float(np.degrees(np.arccos(np.clip(-n[2], -1.0, 1.0))))  # 0: the plane faces the camera
        candidates.append((frac, n, d, front, facing))
        work = work.select_by_index(inl, invert=True)
    ok = [c for c in candidates if c[0] >= min_fraction and c[3] >= 0.8]
    if not ok:
        best = max((c[0] for c in candidates), default=0.0)
        raise UserError(
            f"no table plane: the largest plane with the objects on the camera's side holds {100 * best:.0f}% of "
            f"the cloud (need {100 * min_fraction:.0f}%); give --extrinsics FILE (the camera pose) instead"
        )
    not_wall = [c for c in ok if c[4] > 30.0]
    frac, n, d, _, _ = max(not_wall or ok, key=lambda c: c[0])
    # Least squares on the full-resolution points near the plane, each within 3 sigma of its own depth.
    near = pts[np.abs(pts @ n - d) < np.maximum(3.0 * depth_sigma(pts[:, 2]), 0.005)]
    if len(near) >= 3:
        c = near.mean(axis=0)
        q = near - c
        _, vecs = np.linalg.eigh(q.T @ q)
        n2 = vecs[:, 0]
        if n2 @ n < 0:
            n2 = -n2
        n, d = n2, float(n2 @ c)
    cam_h = -d  # height of the camera (origin) above the plane along n
    if cam_h < min_camera_height:
        raise UserError(
            f"no table frame: the camera is {cam_h * 1000:.0f} mm from the largest plane; the cloud does not look "
            "like a camera-frame view of a table (give --extrinsics FILE, or a world-frame cloud with --viewpoint)"
        )
    z_w = n
    optical = np.array([0.0, 0.0, 1.0])
    x_w = optical - (optical @ z_w) * z_w
    if np.linalg.norm(x_w) < 1e-6:  # looking straight down: x is the image's up direction on the table
        up = np.array([0.0, -1.0, 0.0])
        x_w = up - (up @ z_w) * z_w
    x_w /= np.linalg.norm(x_w)
    y_w = np.cross(z_w, x_w)
    origin = -cam_h * z_w - table_height * z_w  # the foot below the camera, then down to world z = 0
    T_cam_world = np.eye(4)
    T_cam_world[:3, 0], T_cam_world[:3, 1], T_cam_world[:3, 2], T_cam_world[:3, 3] = x_w, y_w, z_w, origin
    tilt = float(np.degrees(np.arcsin(np.clip(-(optical @ z_w), -1.0, 1.0))))
    return TableFrame(geometry.invert(T_cam_world), n, d, frac, cam_h, tilt, table_height)


def _plane_one_thread(o3d: Any, pc: Any, dist: float) -> tuple[Any, list[int]]:
    """Open3D's RANSAC plane (500 iterations) on one thread: run in parallel, one seed need not give one
    plane (as Open3D's ICP and feature RANSAC did not give one pose; not traced in Open3D's source)."""
    limit = getattr(o3d.utility, "set_max_threads", None)
    if limit is None:
        return pc.segment_plane(dist, 3, 500)
    before = o3d.utility.get_max_threads()
    limit(1)
    try:
        return pc.segment_plane(dist, 3, 500)
    finally:
        limit(before)


@dataclass
class WorldCloud:
    """A cloud put in the world frame: points, the camera pose used, and how it was found."""

    points: np.ndarray
    """(n, 3) world frame, metres, NaN rows kept."""
    T_world_cam: np.ndarray
    frame: str
    """How the camera pose was found: ``extrinsics`` or ``table_plane``."""
    how: str
    """One line for the report: which camera pose was used and where it came from."""
    table: TableFrame | None = None

    @property
    def viewpoint(self) -> np.ndarray:
        """``(3,)`` camera centre, world frame, metres."""
        return self.T_world_cam[:3, 3].copy()


def to_world(
    cloud: Cloud,
    *,
    extrinsics: Extrinsics | None = None,
    table_height: float | None = None,
    seed: int = 0,
) -> WorldCloud:
    """Map a camera-frame ``cloud`` into the world (z up): with ``extrinsics`` when given, else the table plane.

    The cloud's own ``T_data_sensor`` (a PCD ``VIEWPOINT``) is undone first, so a cloud stored in some other
    frame with its sensor pose still lands in the camera frame. With the table plane the table top is at
    ``table_height`` (default 0).
    """
    pts = cloud.points
    if cloud.T_data_sensor is not None:
        pts = geometry.transform_points(geometry.invert(cloud.T_data_sensor), pts)
    if extrinsics is not None:
        T = extrinsics.T_world_cam
        how = f"camera frame -> world with the extrinsics of {extrinsics.source}"
        return WorldCloud(geometry.transform_points(T, pts), T, "extrinsics", how)
    tf = table_frame(pts, table_height=0.0 if table_height is None else table_height, seed=seed)
    how = (
        f"camera frame -> world from the table plane found in the cloud ({100 * tf.inliers:.0f}% of the points; "
        f"camera {tf.camera_height * 1000:.0f} mm above it, looking {tf.tilt_deg:.0f} deg down; table top at "
        f"z = {tf.table_height:g} m)"
    )
    return WorldCloud(geometry.transform_points(tf.T_world_cam, pts), tf.T_world_cam, "table_plane", how, tf)


def guess_frame(cloud: Cloud, *, seed: int = 0) -> tuple[Literal["camera", "world"], str]:
    """Whether ``cloud`` is in a camera frame (z forward) or already in the world (z up), and why (one line).

    The rule, cheapest test first:

    * a file that records its sensor's position (a PLY ``comment viewpoint``, a PCD ``VIEWPOINT`` other than
      the identity) is in the frame that position is given in: the world;
    * a sensor's own frame has every point in front of the camera (>= 99% with z > 0, median depth >= 0.2 m)
      *and* a table plane with the objects on the camera's side at least 0.1 m from the origin
      (:func:`table_frame`). A world-frame cloud fails one of these: its table lies near z = 0 (half its
      points below), or its origin is under the table, away from the objects.
    """
    if cloud.T_data_sensor is not None:
        return "world", "the file records its sensor's position, so its points are in the frame of that position"
    pts = cloud.valid_points()
    if len(pts) == 0:
        return "world", "no valid points"
    ahead = float(np.mean(pts[:, 2] > 0))
    median = float(np.median(pts[:, 2]))
    if ahead < 0.99 or median < 0.2:
        return "world", f"{100 * ahead:.0f}% of the points have z > 0 (median z {median:.2f} m): not a camera's view"
    try:
        tf = table_frame(pts, seed=seed)
    except UserError:
        return "world", "every point is in front of the origin, but no table plane with the objects on its near side"
    return "camera", (
        f"every point is in front of the origin (median depth {median:.2f} m) and a table plane lies "
        f"{tf.camera_height * 1000:.0f} mm from it with the objects on its side"
    )
