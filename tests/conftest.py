"""Fixtures shared by every test folder: the real data of ``<repo>/../shared/data`` (read in place, never copied).

Moved here from ``tests/plugins/detectors/aruco/conftest.py`` so the robot tests (the vendor's Nextage URDF)
and the ArUco tests (real photos) use one skip/fail rule.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import pytest

if TYPE_CHECKING:
    import trimesh

# tests/conftest.py -> parents[1] is the repository root; the data sit beside it.
REAL_DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


def require_real_data(folder: Path, need: str = "real") -> Path:
    """``folder`` resolved if it holds ``need`` (a sub-folder); otherwise skip the test, or fail it when ``CI``
    is set (CI clones ``shared/`` beside the repository: a missing folder there is a broken setup, not a reason)."""
    if not (folder / need).is_dir():
        reason = f"real sensor data not found at {(folder / need).resolve()} (clone shared/ beside the repository)"
        if os.environ.get("CI"):
            pytest.fail(reason + "; CI must provide it")
        pytest.skip(reason)
    return folder.resolve()


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The shared real-data folder with its ``real/`` photos and scans (see :func:`require_real_data`)."""
    return require_real_data(REAL_DATA)


@pytest.fixture(scope="session")
def vendor_robots() -> Path:
    """``../shared/data/robots``: the vendor's robot descriptions (the same skip/fail rule)."""
    return require_real_data(REAL_DATA, "robots/nextage_open") / "robots"


@pytest.fixture(scope="session")
def d_peg_mesh() -> trimesh.Trimesh:
    """A round peg, radius 15 mm and 60 mm long along y, with a flat at x = 9 mm: the hull of the D outline
    (metres, part frame at the axis' middle). Read-only: shared by the tests that judge its rival turns."""
    import numpy as np
    import trimesh

    r, flat, length = 0.015, 0.009, 0.06
    a = np.linspace(0.0, 2.0 * np.pi, 96, endpoint=False)
    ring = np.c_[r * np.cos(a), r * np.sin(a)]
    ring = ring[ring[:, 0] <= flat]
    half = np.sqrt(r * r - flat * flat)
    outline = np.r_[ring, [[flat, -half], [flat, half]]]
    pts = np.r_[
        np.c_[outline[:, 0], np.full(len(outline), -length / 2), outline[:, 1]],
        np.c_[outline[:, 0], np.full(len(outline), length / 2), outline[:, 1]],
    ]
    return trimesh.convex.convex_hull(pts)
