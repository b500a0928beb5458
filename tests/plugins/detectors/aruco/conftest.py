"""Fixtures of the ArUco tests: the real photos of ``<repo>/../shared/data`` (read in place, never copied)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# tests/plugins/detectors/aruco/conftest.py -> parents[4] is the repository root; the data sit beside it.
REAL_DATA = Path(__file__).resolve().parents[4] / ".." / "shared" / "data"


def require_real_data(folder: Path) -> Path:
    """``folder`` resolved if it holds ``real/``; otherwise skip the test, or fail it when ``CI`` is set
    (CI clones ``shared/`` beside the repository: a missing folder there is a broken setup, not a reason)."""
    if not (folder / "real").is_dir():
        reason = f"real sensor data not found at {folder.resolve()} (clone shared/ beside the repository)"
        if os.environ.get("CI"):
            pytest.fail(reason + "; CI must provide it")
        pytest.skip(reason)
    return folder.resolve()


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The shared real-data folder (see :func:`require_real_data` for the skip/fail rule)."""
    return require_real_data(REAL_DATA)
