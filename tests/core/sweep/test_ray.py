"""``--executor ray`` on a private local Ray instance gives the same rows as the process pool."""

import json

import pytest

from asmteach.core.sweep import run_sweep


@pytest.mark.slow
def test_ray_executor_matches_process_pool(tmp_path, toy_square_experiment, monkeypatch):
    import ray  # in the dev extras, so a missing Ray fails here rather than skipping

    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    path = toy_square_experiment
    pool_rows = run_sweep(path, tmp_path / "pool", workers=2, progress=False)
    ray_rows = run_sweep(path, tmp_path / "ray", workers=1, executor="ray", progress=False)
    assert not ray.is_initialized()  # the instance the sweep started is shut down

    def key(rows):
        return sorted((r["trial_id"], r["ok"], json.dumps(r["metrics"], sort_keys=True), r["error"]) for r in rows)

    assert len(ray_rows) == 6 and key(ray_rows) == key(pool_rows)
    assert sum(not r["ok"] for r in ray_rows) == 2  # failures are results under Ray too
    assert (tmp_path / "ray" / "trials" / ray_rows[0]["trial_id"]).is_dir()
    # Resuming under Ray runs nothing new.
    again = run_sweep(path, tmp_path / "ray", executor="ray", progress=False)
    assert len(again) == 6
