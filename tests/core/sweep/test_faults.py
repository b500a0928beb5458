"""Faults injected into sweeps and caches: nothing lost, nothing mixed (issue 26).

- kill -9 of a 2-worker ``asmteach sweep`` at random points: the workers die
  with their parent, and a resume gives exactly the results of a sweep that
  was never interrupted;
- a full disk (writes failing with ENOSPC) mid-sweep: the log stays valid,
  the command says so in one line (exit 1), a resume completes it;
- editing the experiment's params: the old results are not kept under the
  new params; failed trials run again with ``--retry-failed`` only, and the
  exit code says when trials failed;
- damaged caches (truncated, empty, garbage) are rebuilt, never fatal.

The experiment kind is a third-party distribution made in tmp: each trial
writes its worker's pid to ``runs.txt`` in its work folder, sleeps a little
and returns ``x * 10 + seed + offset``; it fails while ``$NAP_FAIL`` is set.
"""

from __future__ import annotations

import errno
import importlib
import json
import os
import random
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from asmteach.core.cli import main
from asmteach.core.io import read_jsonl
from asmteach.core.sweep import run_sweep

MODULE = """
import os
import time
from pathlib import Path
from asmteach.core.models import StrictModel
from asmteach.core.sweep import Experiment


class NapParams(StrictModel):
    x: int = 0
    sleep: float = 0.2
    offset: int = 0
    config: str = ""


class Nap(Experiment):
    Params = NapParams

    def run_trial(self, params, seed, workdir):
        with open(workdir / "runs.txt", "a") as fh:
            fh.write(f"{os.getpid()}\\n")
        if os.environ.get("NAP_FAIL"):
            raise RuntimeError("NAP_FAIL says fail")
        time.sleep(params.sleep)
        return {"y": params.x * 10 + seed + params.offset}
"""

N_X, N_SEEDS = 6, 2
TOTAL = N_X * N_SEEDS


@pytest.fixture
def nap(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """Returns ``write(**params) -> experiment file path``."""
    site = tmp_path / "site"
    info = site / "nap_asmteach_experiment-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: nap-asmteach-experiment\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[asmteach.experiments]\nnap = nap_asmteach_experiment:Nap\n")
    (site / "nap_asmteach_experiment.py").write_text(MODULE)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", str(site))
    importlib.invalidate_caches()

    def write(workers: int = 2, **params: object) -> Path:
        path = tmp_path / "nap.yaml"
        path.write_text(
            textwrap.dedent(f"""
            experiment: nap
            params: {json.dumps(params)}
            grid:
              x: {list(range(N_X))}
            seeds: {N_SEEDS}
            workers: {workers}
            """)
        )
        return path

    yield write
    sys.modules.pop("nap_asmteach_experiment", None)


def _results(rows: list[dict]) -> dict[str, tuple]:
    return {r["trial_id"]: (r["ok"], json.dumps(r["metrics"], sort_keys=True)) for r in rows}


def _state(pid: int) -> str | None:
    """The process's state letter (``Z`` zombie), None when it is gone."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    line = next((ln for ln in text.splitlines() if ln.startswith("State:")), "State: ?")
    return line.split()[1]


def _alive(pid: int) -> bool:
    return _state(pid) not in (None, "Z", "X")


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_kill_9_at_random_points_then_resume_equals_an_uninterrupted_sweep(nap, tmp_path: Path) -> None:
    exp = nap(sleep=0.25)
    reference = _results(run_sweep(exp, tmp_path / "reference", progress=False))
    assert len(reference) == TOTAL and all(ok for ok, _ in reference.values())

    rng = random.Random(26)
    out = tmp_path / "killed"
    kills = 0
    while kills < 3:
        before = len(read_jsonl(out / "trials.jsonl"))
        if before >= TOTAL - 2:
            break
        cmd = [sys.executable, "-m", "asmteach.core.cli", "sweep", str(exp), "--out", str(out)]
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        # a random point: after 1 to 3 new trials, plus a random part of one more
        target = before + rng.randint(1, 3)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and proc.poll() is None:
            if len(read_jsonl(out / "trials.jsonl")) >= target:
                break
            time.sleep(0.01)
        time.sleep(rng.uniform(0.0, 0.25))
        assert proc.poll() is None, "the sweep ended before it could be killed"
        proc.send_signal(signal.SIGKILL)  # the parent only, as `kill -9 PID` does
        proc.wait(timeout=10)
        kills += 1
        # its workers die with it (PR_SET_PDEATHSIG): none is left running a trial
        pids = {int(p) for f in (out / "trials").glob("*/runs.txt") for p in f.read_text().split()}
        assert pids
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(_alive(p) for p in pids):
            time.sleep(0.05)
        left = [p for p in pids if _alive(p)]
        for p in left:  # do not leave them running if the check fails
            os.kill(p, signal.SIGKILL)
        assert not left, "workers outlived their killed parent"
        lines = out.joinpath("trials.jsonl").read_text().splitlines()
        assert all(json.loads(ln) for ln in lines[:-1])  # only the last line may be torn

    assert kills >= 2
    resumed = _results(run_sweep(exp, out, progress=False))
    assert resumed == reference  # nothing lost, nothing run under other params, nothing mixed


def test_a_full_disk_mid_sweep_keeps_the_log_valid_and_a_resume_completes_it(
    nap, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    exp = nap(workers=1, sleep=0.0)
    out = tmp_path / "out"
    real_write = os.write
    log = str(out / "trials.jsonl")
    state = {"lines": 0}

    def write(fd: int, data: bytes) -> int:
        # after 4 trial lines the disk is full: the fifth line is half written, then ENOSPC
        if fd > 2 and os.readlink(f"/proc/self/fd/{fd}") == log:
            state["lines"] += 1
            if state["lines"] == 5:
                real_write(fd, data[: len(data) // 2])
                raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(fd, data)

    monkeypatch.setattr(os, "write", write)
    assert main(["sweep", str(exp), "--out", str(out)]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("asmteach:")]
    assert len(err) == 1 and "No space left on device; free some space" in err[0]
    monkeypatch.setattr(os, "write", real_write)
    assert len(read_jsonl(out / "trials.jsonl")) == 4  # the torn fifth line is skipped, the four kept
    rows = run_sweep(exp, out, progress=False)
    reference = run_sweep(exp, tmp_path / "reference", progress=False)
    assert _results(rows) == _results(reference)


def test_edited_params_run_again_and_old_results_stay_out_of_the_summary(nap, tmp_path: Path) -> None:
    out = tmp_path / "out"
    first = run_sweep(nap(workers=1, sleep=0.0), out, progress=False)
    assert sorted(r["metrics"]["y"] for r in first) == sorted(x * 10 + s for x in range(N_X) for s in range(N_SEEDS))
    second = run_sweep(nap(workers=1, sleep=0.0, offset=1000), out, progress=False)
    assert len(second) == TOTAL and all(r["metrics"]["y"] >= 1000 for r in second)
    assert not set(_results(first)) & set(_results(second))  # other params, other trial ids
    assert len(read_jsonl(out / "trials.jsonl")) == 2 * TOTAL  # nothing lost: the old rows stay in the log
    assert "24 trials" not in (out / "summary.md").read_text() and f"{TOTAL} trials" in (out / "summary.md").read_text()


def test_a_file_named_by_the_params_is_part_of_them(nap, tmp_path: Path) -> None:
    """A run config edited between two runs of a sweep is other params: its trials run again."""
    (tmp_path / "run.yaml").write_text("seed: 1\n")
    out = tmp_path / "out"
    first = run_sweep(nap(workers=1, sleep=0.0, config="run.yaml"), out, progress=False)
    assert len(run_sweep(nap(workers=1, sleep=0.0, config="run.yaml"), out, progress=False)) == TOTAL
    assert len(read_jsonl(out / "trials.jsonl")) == TOTAL  # unchanged file: nothing ran again
    (tmp_path / "run.yaml").write_text("seed: 2\n")
    second = run_sweep(nap(workers=1, sleep=0.0, config="run.yaml"), out, progress=False)
    assert not set(_results(first)) & set(_results(second))
    assert len(read_jsonl(out / "trials.jsonl")) == 2 * TOTAL


def test_failed_trials_run_again_only_with_retry_failed(
    nap, tmp_path: Path, capsys: pytest.CaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    exp = nap(workers=1, sleep=0.0)
    out = tmp_path / "out"
    monkeypatch.setenv("NAP_FAIL", "1")
    assert main(["sweep", str(exp), "--out", str(out)]) == 1
    assert f"{TOTAL} of {TOTAL} trials failed" in capsys.readouterr().err
    monkeypatch.delenv("NAP_FAIL")
    assert main(["sweep", str(exp), "--out", str(out)]) == 1  # a failed trial is a result: kept on resume
    assert len(read_jsonl(out / "trials.jsonl")) == TOTAL
    assert main(["sweep", str(exp), "--out", str(out), "--retry-failed"]) == 0
    rows = run_sweep(exp, out, progress=False)
    assert len(rows) == TOTAL and all(r["ok"] for r in rows)  # the newest row of each trial
    assert len(read_jsonl(out / "trials.jsonl")) == 2 * TOTAL


# ---------------------------------------------------------------- damaged caches
DAMAGE = {
    "truncated": lambda b: b[: len(b) // 2],
    "empty": lambda b: b"",
    "garbage": lambda b: b"PK\x03\x04 not a zip at all",
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_convex_pieces_cache_is_rebuilt(damage: str, tmp_path: Path) -> None:
    from asmteach.core import convex_pieces
    from asmteach.core.convex_pieces import route
    from asmteach.core.models import PartSpec
    from asmteach.core.parts import build_part

    part = build_part(
        PartSpec.model_validate(
            {
                "name": "blk",
                "solid": {
                    "add": [{"shape": "box", "size": [0.04, 0.03, 0.02]}],
                    "subtract": [{"shape": "box", "size": [0.02, 0.04, 0.01], "pose": {"xyz": [0, 0, 0.01]}}],
                },
            }
        )
    )
    route._MEMO.clear()
    first = convex_pieces.decompose(part, cache_dir=tmp_path)
    (path,) = tmp_path.glob("*.npz")
    path.write_bytes(DAMAGE[damage](path.read_bytes()))
    route._MEMO.clear()
    again = convex_pieces.decompose(part, cache_dir=tmp_path)
    assert not again.cached and len(again.pieces) == len(first.pieces)
    route._MEMO.clear()
    assert convex_pieces.decompose(part, cache_dir=tmp_path).cached  # the rebuilt file reads back


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_view_database_is_rebuilt(damage: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from asmteach.plugins.detectors.cvfh import views

    built = []

    def tiny(mesh, v, d, c, key):  # a real database, small: building the 42 views is not what is tested
        built.append(key)
        return views.ViewDatabase(
            key=key,
            T_acam_part=np.tile(np.eye(4), (2, 1, 1)),
            centroids=np.zeros((2, 3)),
            crh=np.zeros((2, 90)),
            hists=np.ones((3, 308)),
            region_view=np.array([0, 1, 1]),
            region_centroids=np.zeros((3, 3)),
            view_dirs=np.eye(3)[:2],
        )

    monkeypatch.setattr(views, "build_views", tiny)
    settings = views.ViewSettings(cache_dir=str(tmp_path))
    args = (None, "meshhash", settings, views.DescriptorSettings(), views.KinectSettings())
    db, fresh = views.load_or_build(*args)
    assert fresh
    (path,) = tmp_path.glob("*.npz")
    path.write_bytes(DAMAGE[damage](path.read_bytes()))
    db2, fresh2 = views.load_or_build(*args)
    assert fresh2 and len(built) == 2 and db2.key == db.key
    assert views.load_or_build(*args)[1] is False  # the rebuilt file reads back


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_grasp_cache_is_planned_again(damage: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from asmteach.core.models import Grasp, PartSpec
    from asmteach.core.parts import build_part
    from asmteach.plugins.planners.grasps.planner import AntipodalGraspPlanner
    from asmteach.plugins.robots.nextage.hand import nextage_hand

    part = build_part(
        PartSpec.model_validate({"name": "blk", "solid": {"add": [{"shape": "box", "size": [0.04, 0.03, 0.02]}]}})
    )
    planner = AntipodalGraspPlanner({"cache_dir": str(tmp_path)})
    calls = []
    grasp = Grasp(id=0, p0=[0, -0.015, 0], p1=[0, 0.015, 0], R=np.eye(3), width=0.03, score=1.0)

    def plan(p, hand):
        calls.append(1)
        return [grasp], {}

    monkeypatch.setattr(planner, "_plan", plan)
    hand = nextage_hand()
    assert len(planner.plan(part, hand)) == 1
    (path,) = tmp_path.glob("*.json")
    path.write_bytes(DAMAGE[damage](path.read_bytes()))
    assert len(planner.plan(part, hand)) == 1 and len(calls) == 2
    assert planner.plan(part, hand)[0].width == pytest.approx(0.03) and len(calls) == 2  # read back


WATCHED = """
import os, sys, time, multiprocessing as mp
from asmteach.core.sweep import executors

def worker(parent, path):
    sys.platform = "other"  # no prctl: the watching thread must do it
    executors._die_with_parent(parent)
    open(path, "w").write(str(os.getpid()))
    time.sleep(60)

if __name__ == "__main__":
    mp.set_start_method("fork")
    p = mp.Process(target=worker, args=(os.getpid(), sys.argv[1]))
    p.start()
    time.sleep(60)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_without_prctl_a_thread_ends_the_worker_with_its_parent(tmp_path: Path) -> None:
    script, pid_file = tmp_path / "watched.py", tmp_path / "worker.pid"
    script.write_text(WATCHED)
    proc = subprocess.Popen([sys.executable, str(script), str(pid_file)], start_new_session=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not (pid_file.exists() and pid_file.read_text()):
        time.sleep(0.05)
    worker = int(pid_file.read_text())
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and _alive(worker):
        time.sleep(0.05)
    alive = _alive(worker)
    if alive:
        os.kill(worker, signal.SIGKILL)
    assert not alive, "the worker outlived its parent"
