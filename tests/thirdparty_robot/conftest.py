"""Installs ``asmteach_gantry`` as a third-party distribution: a ``*.dist-info`` with ``entry_points.txt``.

The package's source stays in this folder; a temporary site folder holds its
metadata and is put on ``sys.path`` with the package's folder, so
importlib.metadata discovers ``gantry`` in ``asmteach.robots`` as it would
from an installed wheel. Nothing in asmteach is monkeypatched.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


@pytest.fixture
def gantry_dist(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """The ``asmteach-gantry`` distribution, discoverable for one test; returns its site folder."""
    site = tmp_path / "site"
    info = site / "asmteach_gantry-0.1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: asmteach-gantry\nVersion: 0.1.0\n")
    (info / "entry_points.txt").write_text("[asmteach.robots]\ngantry = asmteach_gantry.robot:GantryRobot\n")
    monkeypatch.syspath_prepend(str(HERE))
    monkeypatch.syspath_prepend(str(site))
    importlib.invalidate_caches()
    yield site
    for name in [m for m in sys.modules if m == "asmteach_gantry" or m.startswith("asmteach_gantry.")]:
        sys.modules.pop(name, None)
