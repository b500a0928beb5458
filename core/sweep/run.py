"""Run (or resume) a sweep, and the ``asmteach sweep`` command."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from asmteach.core.errors import UserError
from asmteach.core.io import check_out_dir, read_jsonl, write_json
from asmteach.core.sweep.executors import GracefulInterrupt, ProgressBar, run_pool, run_ray, run_serial
from asmteach.core.sweep.experiment import load_experiment
from asmteach.core.sweep.summary import summarize
from asmteach.core.sweep.trials import current_rows, plan_trials


def run_sweep(
    path: str | Path,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    executor: str = "local",
    limit: int | None = None,
    progress: bool = True,
    retry_failed: bool = False,
) -> list[dict[str, Any]]:
    """Run (or resume) an experiment; returns the row of every planned trial run so far, old and new.

    ``retry_failed``: trials whose last row failed run again (a new row is
    appended; the newest row of a trial is its result).
    """
    exp, kind = load_experiment(path)
    out = check_out_dir(out_dir)
    if workers is not None and not 1 <= workers <= 64:
        raise UserError(f"--workers {workers}: give 1 to 64 processes")
    if limit is not None and limit < 0:
        raise UserError(f"--limit {limit}: give a number of trials >= 0")
    with _only_sweep_in(out):  # two sweeps appending to one log would run every trial twice
        log_path = out / "trials.jsonl"
        if log_path.exists() and not log_path.is_file():
            raise UserError(f"{log_path}: is not a file; give another --out")
        trials = plan_trials(exp, kind, Path(path).resolve().parent)
        previous = current_rows(read_jsonl(log_path), trials)
        done = {r["trial_id"] for r in previous if r.get("ok") or not retry_failed}
        todo = [t for t in trials if t.trial_id not in done]
        if limit is not None:
            todo = todo[:limit]
        write_json(out / "experiment.json", {"file": str(Path(path).resolve()), **exp.model_dump(mode="json")})
        base_dir = str(Path(path).resolve().parent)
        args = [(exp.experiment, base_dir, exp.model_dump_json(), t.model_dump_json(), str(out)) for t in todo]
        n_workers = workers or exp.workers
        bar = ProgressBar(len(todo), f"{exp.experiment} ({len(done)} done before)", enabled=progress)
        with GracefulInterrupt() as interrupt:
            try:
                if executor == "ray":
                    run_ray(args, log_path, bar, interrupt, n_workers)
                elif n_workers <= 1:
                    run_serial(args, log_path, bar, interrupt)
                else:
                    run_pool(args, log_path, bar, interrupt, n_workers)
            finally:
                bar.close()
        rows = current_rows(read_jsonl(log_path), trials)
        summarize(rows, out, kind(Path(base_dir)), title=exp.experiment)
        return rows


@contextlib.contextmanager
def _only_sweep_in(out: Path) -> Iterator[None]:
    """Hold ``out/.sweep.lock`` (``flock``) while a sweep writes into ``out``; :class:`UserError` if another
    does. The kernel drops the lock when its holder dies, even by kill -9."""
    try:
        import fcntl
    except ImportError:  # not POSIX: no lock
        yield
        return
    fd = os.open(out / ".sweep.lock", os.O_RDWR | os.O_CREAT, 0o666)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UserError(
                f"--out {out}: another sweep is writing into this folder; wait for it to end, or give another folder"
            ) from None
        yield
    finally:
        os.close(fd)


# ---------------------------------------------------------------- CLI
def _cmd_sweep(args: argparse.Namespace) -> int:
    rows = run_sweep(
        args.experiment,
        args.out,
        workers=args.workers,
        executor=args.executor,
        limit=args.limit,
        retry_failed=args.retry_failed,
    )
    n_ok = sum(bool(r.get("ok")) for r in rows)
    print(f"{len(rows)} trials ({n_ok} ok); summary: {Path(args.out) / 'summary.md'}")
    summary = Path(args.out) / "summary.md"
    if summary.exists() and len(summary.read_text()) < 6000:
        sys.stdout.write(summary.read_text())
    if n_ok < len(rows):
        # Exit 1: some trials raised (their errors are in summary.md); a re-run with --retry-failed redoes them.
        errors = {r.get("error") for r in rows if not r.get("ok")}
        first = " ".join(str(sorted(errors, key=str)[0]).split())[:160]
        print(
            f"asmteach: {len(rows) - n_ok} of {len(rows)} trials failed ({len(errors)} distinct error(s), e.g. "
            f"{first}); re-run with --retry-failed to run them again",
            file=sys.stderr,
        )
        return 1
    return 0


def add_sweep_command(sub: argparse._SubParsersAction) -> None:
    """Register ``asmteach sweep``."""
    p = sub.add_parser("sweep", help="run an experiment file: grid x seeds, resumable, parallel")
    p.add_argument("experiment", help="experiment YAML (configs/experiments/...)")
    p.add_argument("--out", required=True, help="output folder; re-running resumes it")
    p.add_argument("--workers", type=int, default=None, help="local processes (default: the file's workers)")
    p.add_argument("--executor", choices=["local", "ray"], default="local", help="ray needs asmteach[ray]")
    p.add_argument("--limit", type=int, default=None, help="run at most this many new trials")
    p.add_argument("--retry-failed", action="store_true", help="run the trials that failed again")
    p.set_defaults(func=_cmd_sweep)
