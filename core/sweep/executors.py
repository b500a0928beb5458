"""Running the trials of a sweep: one at a time, in a process pool, or as Ray tasks.

Each finished trial's row is appended to the log at once (:func:`record`).
Ctrl-C is a request checked between trials (:class:`GracefulInterrupt`);
pool workers ignore it and die with the sweep process, even one killed with -9.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path
from types import FrameType
from typing import Any

from asmteach.core.errors import UserError
from asmteach.core.io import append_jsonl, pid_alive, to_jsonable
from asmteach.core.sweep.experiment import ExperimentFile, TrialSpec, load_kind, params_for


def run_one(kind_name: str, base_dir: str, exp_json: str, trial_json: str, out_dir: str) -> dict[str, Any]:
    """Worker entry: run one trial and return its row (never raises)."""
    exp = ExperimentFile.model_validate_json(exp_json)
    trial = TrialSpec.model_validate_json(trial_json)
    t0 = time.perf_counter()
    row: dict[str, Any] = {"trial_id": trial.trial_id, "point": trial.point, "seed": trial.seed}
    try:
        kind = load_kind(kind_name)
        params = params_for(kind, exp, trial.point)
        workdir = Path(out_dir) / "trials" / trial.trial_id
        workdir.mkdir(parents=True, exist_ok=True)
        metrics = kind(Path(base_dir)).run_trial(params, trial.seed, workdir)
        row.update(ok=True, metrics=to_jsonable(metrics), error=None)
    except UserError as exc:
        row.update(ok=False, metrics={}, error=str(exc))
    except Exception as exc:  # noqa: BLE001 - a failed trial is a result, recorded with its reason
        row.update(ok=False, metrics={}, error=f"{type(exc).__name__}: {exc}", traceback=traceback.format_exc(limit=8))
    row["seconds"] = round(time.perf_counter() - t0, 4)
    return row


class GracefulInterrupt:
    """Ctrl-C as a request checked between trials, so a finished trial is always recorded whole.

    The first SIGINT sets :attr:`requested`; the executors then stop starting
    trials, record those in flight and raise :class:`KeyboardInterrupt`. A
    second SIGINT raises at once (abandoning the trials in flight). Outside
    the main thread signals cannot be caught, so this does nothing there.
    """

    def __init__(self) -> None:
        self.count = 0
        self._previous: Any = None
        self._active = False

    @property
    def requested(self) -> bool:
        return self.count > 0

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        self.count += 1
        if self.count == 1:
            print(
                "\ninterrupted: finishing the trials in flight (Ctrl-C again to abandon them)",
                file=sys.stderr,
                flush=True,
            )
            return
        raise KeyboardInterrupt

    def __enter__(self) -> GracefulInterrupt:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
            self._active = True
        return self

    def __exit__(self, *exc: object) -> None:
        if self._active:
            signal.signal(signal.SIGINT, self._previous)


def record(log_path: Path, bar: ProgressBar, row: dict[str, Any]) -> None:
    append_jsonl(log_path, row)
    bar.advance(row)


def run_serial(args: list[tuple[Any, ...]], log_path: Path, bar: ProgressBar, interrupt: GracefulInterrupt) -> None:
    for a in args:
        if interrupt.requested:
            raise KeyboardInterrupt
        record(log_path, bar, run_one(*a))
    if interrupt.requested:
        raise KeyboardInterrupt


def _die_with_parent(parent: int) -> None:
    """End this worker when the sweep process ``parent`` dies, so a sweep killed with -9 leaves none running.

    Linux: the kernel kills the worker when the process that forked it dies
    (``PR_SET_PDEATHSIG``; with a fork server in between, the fork server,
    which ends with the sweep). Elsewhere, or without ``prctl``, a thread
    watches ``parent``.
    """
    if sys.platform.startswith("linux"):
        import ctypes

        PR_SET_PDEATHSIG = 1
        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the watching thread below does it
            pass
        else:
            if not pid_alive(parent):  # the sweep died before the request was made
                os._exit(1)
            return

    def watch() -> None:
        while pid_alive(parent):
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True, name="asmteach-parent-watch").start()


def _ignore_sigint(parent: int | None = None) -> None:
    """Pool-worker initializer: Ctrl-C reaches the whole process group, but only the parent decides; the
    worker dies with the parent (:func:`_die_with_parent`)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        _die_with_parent(parent)


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """Kill the pool's worker processes (they ignore SIGINT, and shutdown would wait for them)."""
    terminate = getattr(pool, "terminate_workers", None)  # public from Python 3.14
    if terminate is not None:
        terminate()
        return
    for proc in list((getattr(pool, "_processes", None) or {}).values()):
        proc.terminate()


def run_pool(
    args: list[tuple[Any, ...]], log_path: Path, bar: ProgressBar, interrupt: GracefulInterrupt, n_workers: int
) -> None:
    pool = ProcessPoolExecutor(max_workers=n_workers, initializer=_ignore_sigint, initargs=(os.getpid(),))
    pending: set[Future[dict[str, Any]]] = set()
    queue = list(args)
    try:
        while pending or (queue and not interrupt.requested):
            if interrupt.requested:
                # Not-yet-started trials are dropped (a re-run does them); started ones refuse
                # to cancel, stay pending and are recorded below as they finish.
                pending = {f for f in pending if not f.cancel()}
                queue.clear()
            while queue and len(pending) < 2 * n_workers:
                pending.add(pool.submit(run_one, *queue.pop(0)))
            # A timeout so that a Ctrl-C is noticed while trials run.
            finished, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
            for fut in finished:
                if not fut.cancelled():
                    record(log_path, bar, fut.result())
    except KeyboardInterrupt:
        _terminate_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    if interrupt.requested:
        raise KeyboardInterrupt


def run_ray(
    args: list[tuple[Any, ...]], log_path: Path, bar: ProgressBar, interrupt: GracefulInterrupt, n_workers: int
) -> None:
    """Trials as Ray tasks: a local Ray instance, or the cluster named by ``RAY_ADDRESS``."""
    if not args:
        return
    try:
        import ray
    except ImportError:
        raise UserError("--executor ray needs Ray: pip install 'asmteach[ray]'") from None
    started_here = not ray.is_initialized()
    if started_here:
        if os.environ.get("RAY_ADDRESS"):
            ray.init(log_to_driver=False)
        else:
            # A private local instance sized like the process pool; no dashboard to serve.
            ray.init(num_cpus=n_workers, include_dashboard=False, log_to_driver=False)
    remote = ray.remote(num_cpus=1)(run_one)
    refs = [remote.remote(*a) for a in args]
    try:
        while refs:
            if interrupt.requested:
                # Ray does not say which queued tasks have started, so all unfinished ones are
                # cancelled; a re-run does them.
                for ref in refs:
                    ray.cancel(ref)
                raise KeyboardInterrupt
            ready, refs = ray.wait(refs, num_returns=1, timeout=0.25)
            for ref in ready:
                record(log_path, bar, ray.get(ref))
    finally:
        if started_here:
            ray.shutdown()


class ProgressBar:
    """A rich progress bar over trials (on stderr), or nothing."""

    def __init__(self, total: int, label: str, *, enabled: bool) -> None:
        self.progress = None
        if enabled and total:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self.progress = Progress(
                TextColumn(label),
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(),
                TextColumn("{task.fields[failed]} failed"),
            )
            self.task = self.progress.add_task(label, total=total, failed=0)
            self.failed = 0
            self.progress.start()

    def advance(self, row: dict[str, Any]) -> None:
        if self.progress is not None:
            self.failed += not row.get("ok", False)
            self.progress.update(self.task, advance=1, failed=self.failed)

    def close(self) -> None:
        if self.progress is not None:
            self.progress.stop()
