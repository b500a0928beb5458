"""Sweeps: grid x seeds, one JSON line per trial, resume without loss, failures recorded."""

import json

import pytest

from asmteach.core.cli import main
from asmteach.core.errors import UserError
from asmteach.core.io import read_jsonl
from asmteach.core.sweep import group_table, run_sweep


@pytest.fixture
def experiment(toy_square_experiment):
    return toy_square_experiment


def test_sweep_runs_grid_times_seeds_and_records_failures(experiment, tmp_path):
    out = tmp_path / "out"
    rows = run_sweep(experiment, out, progress=False)
    assert len(rows) == 6
    ok = {(r["point"]["x"], r["seed"]): r["metrics"]["square"] for r in rows if r["ok"]}
    assert ok == {(1.0, 0): 1.0, (1.0, 1): 2.0, (2.0, 0): 4.0, (2.0, 1): 5.0}
    failed = [r for r in rows if not r["ok"]]
    assert len(failed) == 2 and all("x=3.0 too large" in r["error"] for r in failed)
    assert (out / "summary.csv").read_text().startswith("x,trials,ok_rate")
    assert "| x | trials | ok_rate" in (out / "summary.md").read_text()
    assert (out / "square.txt").read_text() == "6"


def test_sweep_resumes_without_repeating_or_losing(experiment, tmp_path):
    out = tmp_path / "out"
    run_sweep(experiment, out, limit=2, progress=False)
    assert len(read_jsonl(out / "trials.jsonl")) == 2
    # a torn last line (crash mid-write) is ignored, not fatal
    with open(out / "trials.jsonl", "a") as fh:
        fh.write('{"trial_id": "torn')
    rows = run_sweep(experiment, out, progress=False)
    ids = [r["trial_id"] for r in rows]
    assert len(ids) == 6 and len(set(ids)) == 6


def test_sweep_parallel_matches_serial(experiment, tmp_path):
    serial = run_sweep(experiment, tmp_path / "a", progress=False)
    parallel = run_sweep(experiment, tmp_path / "b", workers=2, progress=False)

    def key(rows):
        return sorted((r["trial_id"], json.dumps(r["metrics"], sort_keys=True)) for r in rows)

    assert key(serial) == key(parallel)


def test_bad_grid_key_is_a_user_error(tmp_path, toy_dist):
    path = tmp_path / "bad.yaml"
    path.write_text("experiment: toy_square\ngrid: {y: [1]}\n")
    with pytest.raises(UserError, match=r"params\.y: unknown key"):
        run_sweep(path, tmp_path / "o", progress=False)
    path.write_text("experiment: toy_squar\n")
    assert main(["sweep", str(path), "--out", str(tmp_path / "o")]) == 2


def test_summary_gives_a_yes_no_metric_as_a_rate_and_numbers_as_median_and_max():
    rows = [
        {"point": {}, "seed": s, "ok": True, "metrics": {"success": s != 2, "error_mm": float(s)}} for s in range(4)
    ]
    (rec,) = group_table(rows, [])
    assert rec["success_rate"] == 0.75 and "success_median" not in rec
    assert rec["error_mm_median"] == 1.5 and rec["error_mm_max"] == 3.0


def test_a_metric_named_seconds_is_kept_apart_from_the_trials_wall_time():
    """The assembly planning experiment reports its planning time as ``seconds``; the trial's wall time
    (planning plus set-up and the re-check) must not overwrite it in the summary."""
    rows = [
        {"point": {}, "seed": s, "ok": True, "seconds": 10.0 + s, "metrics": {"seconds": 1.0 + s}} for s in range(3)
    ]
    (rec,) = group_table(rows, [])
    assert rec["seconds_median"] == 2.0 and rec["trial_seconds_median"] == 11.0
