"""Fixtures of the ArUco tests: the real photos of ``<repo>/../shared/data`` (read in place, never copied)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# tests/plugins/detectors/aruco/conftest.py -> parents[4] is the repository root; the data sit beside it.
REAL_DATA = Path(__file__).resolve().parents[4] / ".." / "shared" / "data"


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The shared real-data folder; skipped when absent, but a failure when ``CI`` is set (CI provides it)."""
    if not (REAL_DATA / "real").is_dir():
        reason = f"real sensor data not found at {REAL_DATA.resolve()} (clone shared/ beside the repository)"
        if os.environ.get("CI"):
            pytest.fail(reason + "; CI must provide it")
        pytest.skip(reason)
    return REAL_DATA.resolve()
