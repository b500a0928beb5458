"""Fixtures of the descriptor tests: the PCL 1.13 reference views of tests/data/pcl (see its README).

(Re-created by the detector helper after it overwrote this file by mistake; the fixtures follow how
test_cvfh_descriptors_pcl.py uses them.)
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[3] / "data" / "pcl"
VIEWS = ("00", "07", "21", "33")


@dataclass
class PclView:
    """One reference view: PCL's points, normals, curvatures (camera frame, metres) and its JSON output."""

    name: str
    points: np.ndarray
    normals: np.ndarray
    curvatures: np.ndarray
    ref: dict[str, Any]


def _read_pcd(path: Path) -> np.ndarray:
    """The ``(n, 7)`` float rows (x y z normal_x normal_y normal_z curvature) of a binary PCD."""
    raw = path.read_bytes()
    marker = b"DATA binary\n"
    start = raw.index(marker) + len(marker)
    header = raw[:start].decode("ascii")
    fields = next(line.split()[1:] for line in header.splitlines() if line.startswith("FIELDS"))
    count = int(next(line.split()[1] for line in header.splitlines() if line.startswith("POINTS")))
    data = np.frombuffer(raw[start:], dtype="<f4", count=count * len(fields)).reshape(count, len(fields))
    return data.astype(np.float64)


def _load(name: str) -> PclView:
    rows = _read_pcd(DATA / f"view_{name}.proc.pcd")
    ref = json.loads((DATA / f"view_{name}.pcl.json").read_text())
    return PclView(name=name, points=rows[:, :3], normals=rows[:, 3:6], curvatures=rows[:, 6], ref=ref)


@pytest.fixture(scope="session")
def view_loader() -> Callable[[str], PclView]:
    """``view_loader("07")`` -> the reference view ``view_07``."""
    cache: dict[str, PclView] = {}

    def load(name: str) -> PclView:
        if name not in cache:
            cache[name] = _load(name)
        return cache[name]

    return load


@pytest.fixture(params=VIEWS, ids=[f"view_{v}" for v in VIEWS])
def pcl_view(request: pytest.FixtureRequest, view_loader: Callable[[str], PclView]) -> PclView:
    """Each of the four reference views in turn."""
    return view_loader(request.param)
