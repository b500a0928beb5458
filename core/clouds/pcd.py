"""PCD v0.7 files (PCL's format) in all three encodings: ascii, binary, binary_compressed (LZF)."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike

from asmteach.core import geometry
from asmteach.core.clouds.cloud import Cloud
from asmteach.core.clouds.lzf import lzf_decompress, lzf_literal
from asmteach.core.errors import UserError

_PCD_TYPES = {
    ("F", 4): "<f4",
    ("F", 8): "<f8",
    ("U", 1): "<u1",
    ("U", 2): "<u2",
    ("U", 4): "<u4",
    ("U", 8): "<u8",
    ("I", 1): "<i1",
    ("I", 2): "<i2",
    ("I", 4): "<i4",
    ("I", 8): "<i8",
}


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
    body = raw[h.offset :]
    if h.data == "ascii":
        text = body.decode("ascii", errors="replace").split()
        total = sum(h.counts)
        if len(text) < n * total:
            raise UserError(f"{p}: PCD ascii data hold {len(text)} values, need {n * total}")
        # Every value as float64 first: exact for every PCL type but 64-bit ints above 2^53 (never seen).
        table = np.array(text[: n * total], dtype=np.float64).reshape(n, total)
        col = 0
        for name, dt, c in zip(h.fields, dtypes, h.counts, strict=True):
            columns[name] = table[:, col : col + c].astype(dt)
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
            plain = lzf_decompress(body[8 : 8 + csize], usize) if n else b""
        except ValueError as exc:
            raise UserError(f"{p}: PCD binary_compressed data are corrupt ({exc})") from None
        # PCL's compressed layout is one array per field (all x, then all y, ...), not one record per point.
        off = 0
        for name, dt, c in zip(h.fields, dtypes, h.counts, strict=True):
            k = n * c * dt.itemsize
            columns[name] = np.frombuffer(plain, dtype=dt, count=n * c, offset=off).reshape(n, c)
            off += k
    pts = np.column_stack([np.asarray(columns[a], dtype=np.float64).reshape(n) for a in "xyz"])
    extras = {
        k: (v.reshape(n) if v.ndim == 2 and v.shape[1] == 1 else v).copy()
        for k, v in columns.items()
        if k not in ("x", "y", "z") and k != "_"
    }
    vp = h.viewpoint
    T = None
    if not np.allclose(vp, [0, 0, 0, 1, 0, 0, 0]):
        q = vp[3:7]
        if abs(np.linalg.norm(q) - 1.0) > 1e-3:
            raise UserError(f"{p}: PCD VIEWPOINT quaternion (qw qx qy qz) {q.tolist()} is not a unit quaternion")
        T = geometry.from_quat([q[1], q[2], q[3], q[0]], vp[:3])
    return Cloud(points=pts, fields=extras, width=h.width, height=h.height, T_data_sensor=T, path=p, encoding=h.data)


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
    cols: list[tuple[str, np.ndarray]] = [
        ("x", pts[:, 0].astype("<f4")),
        ("y", pts[:, 1].astype("<f4")),
        ("z", pts[:, 2].astype("<f4")),
    ]
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
