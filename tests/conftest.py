"""Fixtures shared by every test folder: the real data of ``<repo>/../shared/data`` (read in place, never copied).

Moved here from ``tests/plugins/detectors/aruco/conftest.py`` so the robot tests (the vendor's Nextage URDF)
and the ArUco tests (real photos) use one skip/fail rule.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

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
