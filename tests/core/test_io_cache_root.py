"""Where the on-disk caches go: one root for every cache, chosen by environment variables."""

from __future__ import annotations

from pathlib import Path

import pytest

from asmteach.core.io import cache_root


def test_cache_root_prefers_asmteach_then_xdg_then_home(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.delenv("ASMTEACH_CACHE_DIR", raising=False)
    monkeypatch.delenv("XDG_CACHE_HOME", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cache_root() == tmp_path / "home" / ".cache" / "asmteach"
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_root() == tmp_path / "xdg" / "asmteach"
    monkeypatch.setenv("ASMTEACH_CACHE_DIR", str(tmp_path / "mine"))
    assert cache_root() == tmp_path / "mine"


def test_view_database_and_grasp_sets_share_the_root(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    from asmteach.plugins.detectors.cvfh.views import default_cache_dir as views_dir
    from asmteach.plugins.planners.grasps.planner import default_cache_dir as grasps_dir

    monkeypatch.setenv("ASMTEACH_CACHE_DIR", str(tmp_path))
    assert views_dir().parent == grasps_dir().parent == tmp_path
