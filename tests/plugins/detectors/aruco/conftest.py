"""Fixtures of the ArUco tests. The ``real_data`` fixture and its skip/fail rule moved to ``tests/conftest.py``
(shared with the robot tests); ``require_real_data`` is re-exported here for the test that loads this file by path."""

from __future__ import annotations

import importlib.util
from pathlib import Path

_ROOT_CONFTEST = Path(__file__).resolve().parents[3] / "conftest.py"
_spec = importlib.util.spec_from_file_location("tests_root_conftest", _ROOT_CONFTEST)
assert _spec is not None and _spec.loader is not None
_root = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_root)

REAL_DATA = _root.REAL_DATA
require_real_data = _root.require_real_data
