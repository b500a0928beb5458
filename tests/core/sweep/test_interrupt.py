"""Ctrl-C during a parallel sweep: valid JSON lines, then a re-run does exactly the missing trials.

The sweep runs as a real ``asmteach sweep`` subprocess in its own process
group, and SIGINT goes to the whole group, as a terminal's Ctrl-C does.
The experiment kind is a third-party distribution made in tmp: each trial
appends its pid to ``runs.txt`` in its work folder and then sleeps a
little, so the test can count how often every trial was started.
"""

import importlib
import json
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from asmteach.core.sweep import run_sweep

SLEEPY_MODULE = '''
import os
import time
from asmteach.core.models import StrictModel
from asmteach.core.sweep import Experiment


class SleepyParams(StrictModel):
    x: int = 0
    sleep: float = 0.3


class Sleepy(Experiment):
    """Sleeps, records that it ran, returns x * 10 + seed."""
    Params = SleepyParams

    def run_trial(self, params, seed, workdir):
        with open(workdir / "runs.txt", "a") as fh:  # written first: counts trials started
            fh.write(f"{os.getpid()}\\n")
        time.sleep(params.sleep)
        return {"y": params.x * 10 + seed}
'''

N_X, N_SEEDS = 8, 2
TOTAL = N_X * N_SEEDS


@pytest.fixture
def sleepy_experiment(tmp_path, monkeypatch):
    site = tmp_path / "site"
    info = site / "sleepy_asmteach_experiment-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: sleepy-asmteach-experiment\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[asmteach.experiments]\nsleepy = sleepy_asmteach_experiment:Sleepy\n")
    (site / "sleepy_asmteach_experiment.py").write_text(SLEEPY_MODULE)
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", str(site))
    importlib.invalidate_caches()
    path = tmp_path / "sleepy.yaml"
    path.write_text(
        textwrap.dedent(
            f"""
            experiment: sleepy
            params: {{sleep: 0.3}}
            grid:
              x: {list(range(N_X))}
            seeds: {N_SEEDS}
            workers: 2
            """
        )
    )
    yield path
    sys.modules.pop("sleepy_asmteach_experiment", None)


def _strict_lines(path):
    """Every line of the log parsed strictly (a torn line fails the test)."""
    return [json.loads(line) for line in path.read_text().splitlines()]


def _interrupt_after(cmd, log, n_lines, *, signals):
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and proc.poll() is None:
        if log.exists() and log.read_text().count("\n") >= n_lines:
            break
        time.sleep(0.02)
    assert proc.poll() is None, "the sweep ended before it could be interrupted"
    for _ in range(signals):
        os.killpg(proc.pid, signal.SIGINT)
        time.sleep(0.05)
    out, err = proc.communicate(timeout=60)
    return proc.returncode, out, err


@pytest.mark.slow
@pytest.mark.parametrize("workers", [2, 1], ids=["pool", "serial"])
def test_ctrl_c_records_trials_in_flight_and_rerun_does_only_the_missing(sleepy_experiment, tmp_path, workers):
    out = tmp_path / "out"
    cmd = [
        sys.executable,
        "-m",
        "asmteach.core.cli",
        "sweep",
        str(sleepy_experiment),
        "--out",
        str(out),
        "--workers",
        str(workers),
    ]
    code, _, err = _interrupt_after(cmd, out / "trials.jsonl", 2, signals=1)
    assert code == 130
    assert "interrupted" in err and "Traceback" not in err

    first = _strict_lines(out / "trials.jsonl")
    assert 2 <= len(first) < TOTAL
    assert len({r["trial_id"] for r in first}) == len(first) and all(r["ok"] for r in first)

    rows = run_sweep(sleepy_experiment, out, progress=False)
    lines = _strict_lines(out / "trials.jsonl")
    assert len(lines) == TOTAL and len({r["trial_id"] for r in lines}) == TOTAL
    assert lines[: len(first)] == first  # old lines untouched, new ones appended
    assert sorted(r["metrics"]["y"] for r in rows) == sorted(x * 10 + s for x in range(N_X) for s in range(N_SEEDS))
    # Trials in flight at the Ctrl-C were finished and recorded, so no trial ran twice.
    runs = {p.parent.name: p.read_text().split() for p in (out / "trials").glob("*/runs.txt")}
    assert len(runs) == TOTAL and all(len(v) == 1 for v in runs.values())
    assert (out / "summary.png").exists()


@pytest.mark.slow
def test_second_ctrl_c_abandons_trials_in_flight_and_log_stays_valid(sleepy_experiment, tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "asmteach.core.cli", "sweep", str(sleepy_experiment), "--out", str(out)]
    code, _, err = _interrupt_after(cmd, out / "trials.jsonl", 1, signals=2)
    assert code == 130 and "Traceback" not in err
    first = _strict_lines(out / "trials.jsonl")
    assert 1 <= len(first) < TOTAL
    run_sweep(sleepy_experiment, out, progress=False)
    lines = _strict_lines(out / "trials.jsonl")
    assert len(lines) == TOTAL and len({r["trial_id"] for r in lines}) == TOTAL
