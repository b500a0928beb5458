"""The same config and seed give the same report.json and plan.json, apart from timing fields (issue 26).

The demo runs twice: once in this process and once in a fresh interpreter with
another ``PYTHONHASHSEED`` (set and dict order of strings, anything else a
process carries: thread pools, caches, PyBullet). Every leaf of both files is
compared exactly (floats bit for bit), except under the keys of
:data:`TIMING_KEYS`, which hold wall-clock measurements of this machine.

Run it alone: ``.venv/bin/python -m pytest -p no:warnings tests/core/test_determinism.py``
(two runs of the demo without its animation: 2-5 min on two shared cores).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from asmteach.core.cli import main

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "configs/demo.yaml"
# The animation only adds GIF frames (not in either JSON) and a minute of rendering.
ARGS = ["--set", "execution.animation=false"]

TIMING_KEYS = frozenset(
    {
        "seconds",  # a stage's wall time; a transfer's total
        "planning_seconds",  # the plan stage's wall time (report and plan stats)
        "graph_seconds",
        "search_seconds",
        "motion_seconds",  # the regrasp planner's wall time per phase
        "timing_seconds",  # wall time of the time parametrisation
        "timing_ms",  # a detection's wall (and CPU) time per step
        "view_db_built_ms",  # wall time of building a view database, 0.0 when it came from the disk cache
        "computer_seconds",  # the report's wall time per stage
    }
)
"""Keys whose whole value is a wall-clock measurement. Not exempt, because they are computed, not measured:
``execution_seconds``, ``robot_seconds`` (the robot's simulated motion time) and trajectory ``times``."""


def differences(a: Any, b: Any, path: str = "") -> list[str]:
    """Every leaf where ``a`` and ``b`` differ (``"path: a != b"``), keys of :data:`TIMING_KEYS` skipped."""
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for key in sorted(set(a) | set(b)):
            if key in TIMING_KEYS:
                continue
            if key not in a or key not in b:
                out.append(f"{path}/{key}: only in {'the first' if key in a else 'the second'}")
                continue
            out += differences(a[key], b[key], f"{path}/{key}")
        return out
    if isinstance(a, list) and isinstance(b, list):
        out = [f"{path}: {len(a)} items != {len(b)}"] if len(a) != len(b) else []
        for i, (x, y) in enumerate(zip(a, b, strict=False)):  # the extra items are counted above
            out += differences(x, y, f"{path}/{i}")
        return out
    # type too: 1 == 1.0 == True in Python, not in the file
    return [] if type(a) is type(b) and a == b else [f"{path}: {a!r} != {b!r}"]


def test_differences_skip_only_the_timing_keys() -> None:
    a = {"seconds": 1.0, "x": [1.0, {"timing_ms": {"icp": 3.0}, "execution_seconds": 2.0}]}
    b = {"seconds": 2.0, "x": [1.0, {"timing_ms": {"icp": 4.0}, "execution_seconds": 2.5}]}
    assert differences(a, b) == ["/x/1/execution_seconds: 2.0 != 2.5"]
    assert differences({"a": 1}, {"a": 1.0}) == ["/a: 1 != 1.0"]
    assert differences({"a": [1]}, {"a": [1, 2], "b": 0}) == ["/a: 1 items != 2", "/b: only in the second"]


def _load(out: Path, name: str) -> Any:
    # Paths inside the output folder would differ between the two folders, not between the runs.
    return json.loads((out / name).read_text().replace(str(out), "<out>"))


@pytest.mark.slow
def test_the_demo_gives_the_same_report_and_plan_in_this_process_and_in_another(tmp_path: Path) -> None:
    here, there = tmp_path / "here", tmp_path / "there"
    main(["run", str(DEMO), "--out", str(here), *ARGS])
    hash_seed = str(int(os.environ.get("PYTHONHASHSEED", "0") or 0) + 1)
    env = {**os.environ, "PYTHONHASHSEED": hash_seed}
    code = "import sys; from asmteach.core.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run(
        [sys.executable, "-c", code, "run", str(DEMO), "--out", str(there), *ARGS],
        env=env,
        cwd=tmp_path,
        check=False,
        capture_output=True,
        text=True,
        timeout=1800,
    )
    assert (there / "plan.json").is_file(), proc.stderr[-2000:]
    report = _load(here, "report.json")
    assert report["stages"] and all(s["ok"] for s in report["stages"]), report["reason"]
    for name in ("report.json", "plan.json"):
        diff = differences(_load(here, name), _load(there, name))
        assert not diff, f"{name}: {len(diff)} fields differ, first: " + "; ".join(diff[:10])
    # A wall-clock limit that cut a search makes the plan depend on the machine's load: none may have.
    for part in ("A", "B"):
        assert report["plan_stats"][part]["wall_clock_cuts"] == []
