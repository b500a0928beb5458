"""Experiment sweeps: parameter grids x seeds, resumable, parallel.

An *experiment kind* is a class registered in the entry-point group
``asmteach.experiments``. It declares a pydantic ``Params`` model, runs one
trial from validated params and a seed, and may summarise all rows into
tables and plots. An *experiment file* (YAML) picks the kind and the grid::

    experiment: teaching_precision     # entry-point name
    params: {frames: 30}               # base params (validated by the kind's Params)
    grid:                              # cartesian product over dotted keys of params
      distance: [0.35, 0.5, 0.8]
    seeds: 3                           # an int N (seeds 0..N-1) or a list
    workers: 2                         # local processes (default: 1)

``asmteach sweep FILE --out DIR`` appends one JSON line per finished trial to
``DIR/trials.jsonl`` (fsynced), skips trials already there when re-run, and
writes ``trials.csv``, ``summary.csv``, ``summary.md`` and the kind's own
figures atomically; a kind that draws no figure of its own gets the generic
``summary.png`` (each numeric metric against the grid key with most values).

Ctrl-C: the first one stops starting trials and waits for those in flight,
recording them, so nothing computed is lost (the Ray executor cancels its
trials in flight instead); a second one abandons the trials in flight. Either
way ``trials.jsonl`` stays valid and a re-run does exactly the missing trials.
A hard crash can tear the last line, which readers skip.
"""

from __future__ import annotations

import abc
import argparse
import contextlib
import csv
import hashlib
import io
import itertools
import json
import math
import os
import signal
import sys
import threading
import time
import traceback
from collections.abc import Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from importlib import metadata
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any, ClassVar

from pydantic import Field, ValidationError, field_validator

from asmteach.core.config import MAX_SEED, check_finite, format_validation_error, set_dotted
from asmteach.core.errors import UserError
from asmteach.core.io import (
    append_jsonl,
    atomic_path,
    check_out_dir,
    pid_alive,
    read_jsonl,
    read_yaml,
    to_jsonable,
    write_json,
    write_text,
)
from asmteach.core.models import StrictModel, resolve_relative
from asmteach.core.registry import closest

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = [
    "Experiment",
    "ExperimentFile",
    "TrialSpec",
    "add_sweep_command",
    "load_experiment",
    "run_sweep",
    "summary_figure",
    "summary_plot",
]

GROUP = "asmteach.experiments"


class Experiment(abc.ABC):
    """Base of an experiment kind.

    Subclasses set ``Params`` (a :class:`StrictModel`) and implement
    :meth:`run_trial`. ``base_dir`` is the experiment file's folder, for
    resolving paths written in params.
    """

    Params: ClassVar[type[StrictModel]]
    """Validated parameters of one trial; grid keys are dotted paths into it."""

    plot_metrics: ClassVar[tuple[str, ...]] = ()
    """Metrics drawn in the generic ``summary.png`` (at most six); empty: the first numeric ones.

    Only used when :meth:`summarize` writes no figure of its own.
    """

    def __init__(self, base_dir: Path) -> None:
        self.base_dir = base_dir

    def path(self, relative: str) -> Path:
        """Resolve a path written in the experiment file."""
        return resolve_relative(relative, self.base_dir)

    @abc.abstractmethod
    def run_trial(self, params: Any, seed: int, workdir: Path) -> dict[str, Any]:
        """Run one trial; return JSON-able metrics (flat ``name -> number/str/bool`` preferred).

        Raise :class:`UserError` (or any exception) to record a failed trial;
        the sweep keeps going. ``workdir`` is a per-trial folder for artefacts.
        """

    def summarize(self, rows: list[dict[str, Any]], out_dir: Path) -> list[Path]:
        """Write kind-specific tables and figures from all rows; return their paths."""
        return []

    def check(self, params: Any) -> None:
        """Check one grid point's params beyond their model (files named in them, plugin names) before any
        trial runs; raise :class:`UserError` naming the key. The default checks nothing more."""
        return None


class ExperimentFile(StrictModel):
    """The YAML schema of an experiment file."""

    experiment: str = Field(description="experiment kind: entry-point name in asmteach.experiments")
    description: str = ""
    params: dict[str, Any] = Field(default_factory=dict)
    grid: dict[str, list[Any]] = Field(default_factory=dict)
    seeds: int | list[int] = Field(1, description="an int N (seeds 0..N-1) or an explicit list")
    workers: int = Field(1, ge=1, le=64)

    @field_validator("seeds")
    @classmethod
    def _seeds(cls, v: int | list[int]) -> int | list[int]:
        # seeds: 0 would plan no trial at all, a negative seed fails in the middle of a trial
        if isinstance(v, int) and v < 1:
            raise ValueError("give a number of seeds >= 1, or a list of seeds")
        if isinstance(v, int) and v > MAX_SEED:
            raise ValueError(f"give at most {MAX_SEED} seeds")
        if isinstance(v, list):
            if not v or any(s < 0 or s > MAX_SEED for s in v):
                raise ValueError(f"give a non-empty list of seeds, each 0 to {MAX_SEED}")
            if len(set(v)) != len(v):
                raise ValueError("a seed is listed twice; each (grid point, seed) is one trial")
        return v

    def seed_list(self) -> list[int]:
        return list(range(self.seeds)) if isinstance(self.seeds, int) else list(self.seeds)


class TrialSpec(StrictModel):
    """One trial: its grid point, seed and stable id."""

    trial_id: str
    point: dict[str, Any]
    seed: int


def experiment_kinds() -> dict[str, metadata.EntryPoint]:
    """Registered experiment kinds by name."""
    return {ep.name: ep for ep in metadata.entry_points(group=GROUP)}


def load_kind(name: str) -> type[Experiment]:
    """The experiment class registered as ``name``; :class:`UserError` if unknown."""
    kinds = experiment_kinds()
    if name not in kinds:
        hint = closest(name, list(kinds))
        more = f"; did you mean {hint!r}?" if hint else f" (known: {', '.join(sorted(kinds)) or 'none'})"
        raise UserError(f"experiment: no experiment kind named {name!r}{more}")
    cls = kinds[name].load()
    if not (isinstance(cls, type) and issubclass(cls, Experiment)):
        raise UserError(f"experiment kind {name!r} ({kinds[name].value}) is not an Experiment subclass")
    return cls


def load_experiment(path: str | Path) -> tuple[ExperimentFile, type[Experiment]]:
    """Read and validate an experiment file and every grid point's params."""
    p = Path(path)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: an experiment file must be a YAML mapping")
    check_finite(raw, str(p))  # a NaN passes every bound of a Params model
    try:
        exp = ExperimentFile.model_validate(raw)
    except ValidationError as exc:
        raise UserError(f"{p}: {format_validation_error(exc)}") from None
    kind = load_kind(exp.experiment)
    checker = kind(p.resolve().parent)
    for point in grid_points(exp):
        # Every grid point is validated before the first trial runs: a typo in the tenth value of a grid
        # costs one line now, not a sweep of failed trials.
        params = params_for(kind, exp, point, where=str(p))
        try:
            checker.check(params)
        except UserError as exc:
            at = ", ".join(f"{k}={v!r}" for k, v in point.items())
            raise UserError(f"{p}: {exc}" + (f" (grid point {at})" if at else "")) from None
    return exp, kind


def grid_points(exp: ExperimentFile) -> list[dict[str, Any]]:
    """Cartesian product of the grid, in file order."""
    keys = list(exp.grid)
    if not keys:
        return [{}]
    return [dict(zip(keys, values, strict=True)) for values in itertools.product(*(exp.grid[k] for k in keys))]


def params_for(kind: type[Experiment], exp: ExperimentFile, point: dict[str, Any], *, where: str = "") -> Any:
    """Validated params of one grid point (base params with the point's keys set)."""
    raw = json.loads(json.dumps(exp.params))
    for key, value in point.items():
        set_dotted(raw, key, value)
    try:
        return kind.Params.model_validate(raw)
    except ValidationError as exc:
        prefix = f"{where}: " if where else ""
        raise UserError(f"{prefix}{format_validation_error(exc, 'params')}") from None


def params_hash(kind_name: str, params: Any, base_dir: Path | None = None) -> str:
    """Hash of a trial's resolved params (every value, defaults included) and its experiment kind.

    With ``base_dir`` (the experiment file's folder), a text param naming a
    file there (``run_config: ../demo.yaml``) adds the file's contents: a
    run config edited between two runs of a sweep is other params too. One
    level only: the files such a file names in turn are not read.
    """
    resolved = params.model_dump(mode="json") if hasattr(params, "model_dump") else params
    files: dict[str, str] = {}
    if base_dir is not None:
        for value in _texts(resolved):
            if len(value) < 4096 and "\n" not in value:
                try:
                    path = resolve_relative(value, base_dir)
                    if path.is_file() and path.stat().st_size < 16_000_000:
                        files[value] = hashlib.sha1(path.read_bytes()).hexdigest()
                except (OSError, ValueError):
                    continue
    blob = json.dumps({"kind": kind_name, "params": resolved, **({"files": files} if files else {})},
                      sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def _texts(node: Any) -> Iterator[str]:
    """Every text value in a tree of params."""
    if isinstance(node, str):
        yield node
    elif isinstance(node, dict):
        for v in node.values():
            yield from _texts(v)
    elif isinstance(node, list):
        for v in node:
            yield from _texts(v)


def trial_id(point: dict[str, Any], seed: int, resolved: str = "") -> str:
    """Stable id of a trial, independent of grid order.

    ``resolved`` is :func:`params_hash` of the trial's params: editing the
    experiment's base params (or a default of the kind) gives new ids, so a
    resumed sweep runs the trials again instead of keeping results of the
    old params under the new ones.
    """
    key: dict[str, Any] = {"point": point, "seed": seed}
    if resolved:
        key["params"] = resolved
    blob = json.dumps(key, sort_keys=True, default=str)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def plan_trials(exp: ExperimentFile, kind: type[Experiment] | None = None,
                base_dir: Path | None = None) -> list[TrialSpec]:
    """Every (grid point, seed) pair of the experiment; ids include the resolved params' hash when ``kind``
    is given (as :func:`run_sweep` does, with the experiment file's folder as ``base_dir``)."""
    out = []
    for point in grid_points(exp):
        resolved = params_hash(exp.experiment, params_for(kind, exp, point), base_dir) if kind is not None else ""
        out += [TrialSpec(trial_id=trial_id(point, seed, resolved), point=point, seed=seed) for seed in exp.seed_list()]
    return out


def current_rows(rows: list[dict[str, Any]], trials: list[TrialSpec]) -> list[dict[str, Any]]:
    """The log's rows of the planned trials, the last row of each (a retried trial's newest), in log order.

    Rows of other params (an edited experiment file) stay in the log but are
    not results of this sweep.
    """
    planned = {t.trial_id for t in trials}
    last: dict[str, int] = {}
    for i, r in enumerate(rows):
        if r.get("trial_id") in planned:
            last[r["trial_id"]] = i
    return [rows[i] for i in sorted(last.values())]


def _run_one(kind_name: str, base_dir: str, exp_json: str, trial_json: str, out_dir: str) -> dict[str, Any]:
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
        bar = _Bar(len(todo), f"{exp.experiment} ({len(done)} done before)", enabled=progress)
        with _GracefulInterrupt() as interrupt:
            try:
                if executor == "ray":
                    _run_ray(args, log_path, bar, interrupt, n_workers)
                elif n_workers <= 1:
                    _run_serial(args, log_path, bar, interrupt)
                else:
                    _run_pool(args, log_path, bar, interrupt, n_workers)
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
            raise UserError(f"--out {out}: another sweep is writing into this folder; wait for it to end, or give "
                            "another folder") from None
        yield
    finally:
        os.close(fd)


class _GracefulInterrupt:
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

    def __enter__(self) -> _GracefulInterrupt:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
            self._active = True
        return self

    def __exit__(self, *exc: object) -> None:
        if self._active:
            signal.signal(signal.SIGINT, self._previous)


def _record(log_path: Path, bar: _Bar, row: dict[str, Any]) -> None:
    append_jsonl(log_path, row)
    bar.advance(row)


def _run_serial(args: list[tuple[Any, ...]], log_path: Path, bar: _Bar, interrupt: _GracefulInterrupt) -> None:
    for a in args:
        if interrupt.requested:
            raise KeyboardInterrupt
        _record(log_path, bar, _run_one(*a))
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


def _run_pool(
    args: list[tuple[Any, ...]], log_path: Path, bar: _Bar, interrupt: _GracefulInterrupt, n_workers: int
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
                pending.add(pool.submit(_run_one, *queue.pop(0)))
            # A timeout so that a Ctrl-C is noticed while trials run.
            finished, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
            for fut in finished:
                if not fut.cancelled():
                    _record(log_path, bar, fut.result())
    except KeyboardInterrupt:
        _terminate_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    if interrupt.requested:
        raise KeyboardInterrupt


def _run_ray(
    args: list[tuple[Any, ...]], log_path: Path, bar: _Bar, interrupt: _GracefulInterrupt, n_workers: int
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
    remote = ray.remote(num_cpus=1)(_run_one)
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
                _record(log_path, bar, ray.get(ref))
    finally:
        if started_here:
            ray.shutdown()


class _Bar:
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


# ---------------------------------------------------------------- summaries
def flatten(row: dict[str, Any]) -> dict[str, Any]:
    """One flat record per trial: grid keys, seed, ok, error, the trial's wall time (``trial_seconds``, named
    apart from any metric of an experiment, such as the planning time ``seconds``) and the metrics."""
    flat: dict[str, Any] = {**row.get("point", {}), "seed": row.get("seed"), "ok": row.get("ok")}
    for k, v in (row.get("metrics") or {}).items():
        if isinstance(v, int | float | str | bool) or v is None:
            flat[k] = v
    flat["trial_seconds"] = row.get("seconds")
    flat["error"] = row.get("error") or ""
    return flat


def _num(v: Any) -> float | None:
    if isinstance(v, bool) or v is None:
        return float(v) if isinstance(v, bool) else None
    if isinstance(v, int | float) and math.isfinite(v):
        return float(v)
    return None


def group_table(rows: list[dict[str, Any]], keys: Iterable[str]) -> list[dict[str, Any]]:
    """Per grid point: trial count, the rate of trials that ran (``ok_rate``), the rate of each yes/no
    metric (``success_rate``) and the median / max of each numeric one."""
    import numpy as np

    keys = list(keys)
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {}
    for r in rows:
        f = flatten(r)
        groups.setdefault(tuple(json.dumps(f.get(k), default=str) for k in keys), []).append(f)
    table = []
    for gkey, members in groups.items():
        rec: dict[str, Any] = {k: json.loads(v) for k, v in zip(keys, gkey, strict=True)}
        rec["trials"] = len(members)
        rec["ok_rate"] = round(sum(bool(m["ok"]) for m in members) / len(members), 4)
        metric_names = [k for k in members[0] if k not in (*keys, "seed", "ok", "error")]
        for name in metric_names:
            flags = [m.get(name) for m in members if isinstance(m.get(name), bool)]
            if flags and len(flags) == sum(m.get(name) is not None for m in members):
                rec[f"{name}_rate"] = round(sum(flags) / len(flags), 4)  # a yes/no result: how often yes
                continue
            vals = [x for x in (_num(m.get(name)) for m in members) if x is not None]
            if vals:
                rec[f"{name}_median"] = round(float(np.median(vals)), 6)
                rec[f"{name}_max"] = round(float(np.max(vals)), 6)
        table.append(rec)
    return table


def to_csv(records: list[dict[str, Any]]) -> str:
    """Records as CSV text (union of keys, in first-seen order)."""
    cols: list[str] = []
    for r in records:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    for r in records:
        w.writerow({k: r.get(k, "") for k in cols})
    return buf.getvalue()


def to_markdown(records: list[dict[str, Any]], cols: list[str] | None = None) -> str:
    """Records as a GitHub markdown table."""
    if not records:
        return "_no trials_\n"
    cols = cols or list(dict.fromkeys(k for r in records for k in r))

    def cell(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v).replace("|", "\\|")

    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(cell(r.get(c, "")) for c in cols) + " |" for r in records]
    return "\n".join(lines) + "\n"


def summarize(rows: list[dict[str, Any]], out: Path, kind: Experiment, *, title: str = "") -> list[Path]:
    """Generic summary (per-trial CSV, per-point table) plus the kind's own outputs.

    When the kind writes no figure, the generic :func:`summary_plot` is added.
    """
    keys = list(dict.fromkeys(k for r in rows for k in r.get("point", {})))
    flat = [flatten(r) for r in rows]
    table = group_table(rows, keys)
    paths = [
        write_text(out / "trials.csv", to_csv(flat)),
        write_text(out / "summary.csv", to_csv(table)),
    ]
    own = list(kind.summarize(rows, out) or [])
    plot = None
    if not any(Path(p).suffix.lower() in IMAGE_SUFFIXES for p in own):
        plot = summary_plot(rows, out, title=title or type(kind).__name__, metrics=kind.plot_metrics)
    n_ok = sum(bool(r.get("ok")) for r in rows)
    md = (f"# Sweep summary\n\n{len(rows)} trials, {n_ok} ran to the end ({len(rows) - n_ok} raised an error); "
          "a trial's own verdict is among its metrics.\n\n" + to_markdown(table))
    if plot is not None:
        md += f"\n![summary]({plot.name})\n"
    failures = [r for r in rows if not r.get("ok")]
    if failures:
        md += "\n## Failed trials\n\n" + to_markdown(
            [
                {"trial": r["trial_id"], "seed": r["seed"], **r.get("point", {}), "error": r.get("error")}
                for r in failures[:50]
            ]
        )
    paths.append(write_text(out / "summary.md", md))
    return paths + own + ([plot] if plot is not None else [])


# ---------------------------------------------------------------- generic plot
IMAGE_SUFFIXES = frozenset({".png", ".svg", ".pdf", ".jpg", ".jpeg", ".gif"})
MAX_PLOT_METRICS = 6
MAX_PLOT_SERIES = 6


def _label(v: Any, width: int = 18) -> str:
    text = json.dumps(v, default=str) if isinstance(v, list | dict) else str(v)
    return text if len(text) <= width else text[: width - 1] + "…"


def _is_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def plot_columns(
    rows: list[dict[str, Any]], preferred: Iterable[str] = (), limit: int = MAX_PLOT_METRICS
) -> list[str]:
    """Metrics worth a panel: numeric (not bool) in at least one successful trial.

    The ``preferred`` ones that are numeric come first, in their order; without
    them, the numeric metrics in first-seen order. Falls back to
    ``["trial_seconds"]`` (trial wall time) when no metric is numeric.
    """
    numeric = list(
        dict.fromkeys(k for r in rows if r.get("ok") for k, v in (r.get("metrics") or {}).items() if _is_number(v))
    )
    chosen = [k for k in dict.fromkeys(preferred) if k in numeric] or numeric
    return chosen[:limit] if chosen else ["trial_seconds"]


def plot_axis_key(rows: list[dict[str, Any]]) -> str | None:
    """The grid key with the most distinct values (file order breaks ties); None without a grid."""
    keys = list(dict.fromkeys(k for r in rows for k in r.get("point", {})))
    if not keys:
        return None
    counts = {k: len({json.dumps(r.get("point", {}).get(k), default=str) for r in rows}) for k in keys}
    return max(keys, key=lambda k: counts[k])


def series_stats(xs: list[float], ys: list[float]) -> tuple[Any, Any, Any, Any]:
    """Per distinct x (ascending): the median and the 25th and 75th percentiles of y.

    Returns ``(x, median, q25, q75)``, each a ``(k,)`` float array.
    """
    import numpy as np

    x = np.asarray(xs, dtype=float)
    y = np.asarray(ys, dtype=float)
    ux = np.unique(x)
    q = np.array([np.percentile(y[x == u], [50.0, 25.0, 75.0]) for u in ux]).reshape(-1, 3)
    return ux, q[:, 0], q[:, 1], q[:, 2]


def _metric_value(row: dict[str, Any], col: str) -> Any:
    return row.get("seconds") if col == "trial_seconds" else (row.get("metrics") or {}).get(col)


def summary_figure(rows: list[dict[str, Any]], *, title: str = "", metrics: Iterable[str] = ()) -> Figure | None:
    """The generic sweep figure, or None when there is nothing to draw.

    One panel per numeric metric (:func:`plot_columns`, ``metrics`` first;
    successful trials only) against the grid key with most values (:func:`plot_axis_key`). A
    numeric key gives the median line with its inter-quartile band and the
    trials as dots, one line per combination of the other grid keys (pooled
    when there are more than six); a categorical key (or none) gives box
    plots pooled over the other keys. If any trial failed, a first panel
    shows the success rate per key value.
    """
    import numpy as np
    from matplotlib.figure import Figure

    if not rows:
        return None
    x_key = plot_axis_key(rows)
    xs_all = [r.get("point", {}).get(x_key) for r in rows] if x_key else ["all"] * len(rows)
    numeric_x = x_key is not None and all(_is_number(v) for v in xs_all)
    other = [k for k in dict.fromkeys(k for r in rows for k in r.get("point", {})) if k != x_key]
    series_of = [", ".join(f"{k}={_label(r.get('point', {}).get(k))}" for k in other) for r in rows]
    pooled = len(set(series_of)) > MAX_PLOT_SERIES
    if pooled or not numeric_x:
        series_of = [""] * len(rows)
    cols = plot_columns(rows, metrics)
    if not any(_is_number(_metric_value(r, c)) for r in rows if r.get("ok") for c in cols):
        cols = []
    any_failed = not all(r.get("ok") for r in rows)
    panels = (["success rate"] if any_failed else []) + cols
    if not panels:
        return None

    ncols = min(3, len(panels))
    nrows = math.ceil(len(panels) / ncols)
    fig = Figure(figsize=(4.4 * ncols, 3.4 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    categories = list(dict.fromkeys(json.dumps(v, default=str) for v in xs_all))
    for ax, panel in zip(axes, panels, strict=False):
        is_rate = panel == "success rate"
        pts = [
            (x, s, 1.0 if r.get("ok") else 0.0) if is_rate else (x, s, _metric_value(r, panel))
            for x, s, r in zip(xs_all, series_of, rows, strict=True)
            if is_rate or (r.get("ok") and _is_number(_metric_value(r, panel)))
        ]
        if numeric_x:
            for name in dict.fromkeys(s for _, s, _ in pts):
                px = [float(x) for x, s, _ in pts if s == name]
                py = [float(y) for _, s, y in pts if s == name]
                ux, med, q25, q75 = series_stats(px, py)
                if is_rate:
                    med = np.array([np.mean([y for x, y in zip(px, py, strict=True) if x == u]) for u in ux])
                (line,) = ax.plot(ux, med, marker="o", label=name or None)
                if not is_rate:
                    ax.fill_between(ux, q25, q75, color=line.get_color(), alpha=0.25, linewidth=0)
                    ax.scatter(px, py, s=8, color=line.get_color(), alpha=0.35)
            if any(s for _, s, _ in pts):
                ax.legend(fontsize="x-small")
        else:
            data = [[float(y) for x, _, y in pts if json.dumps(x, default=str) == c] for c in categories]
            labels = [_label(json.loads(c)) for c in categories]
            if is_rate:
                ax.bar(range(1, len(data) + 1), [sum(d) / len(d) if d else 0.0 for d in data])
                ax.set_xticks(range(1, len(data) + 1), labels)
            else:
                keep = [i for i, d in enumerate(data) if d]
                ax.boxplot([data[i] for i in keep], positions=[i + 1 for i in keep], widths=0.6)
                ax.set_xticks(range(1, len(data) + 1), labels)
            if len(categories) > 4:
                ax.tick_params(axis="x", labelrotation=30)
        if is_rate:
            ax.set_ylim(-0.05, 1.05)
        ax.set_title(panel + (" (s)" if panel.endswith("seconds") else ""), fontsize="medium")
        ax.set_xlabel(x_key or "")
        ax.grid(alpha=0.3)
    for ax in axes[len(panels) :]:
        ax.set_visible(False)
    n_ok = sum(bool(r.get("ok")) for r in rows)
    note = f"; pooled over {', '.join(other)}" if other and (pooled or not numeric_x) else ""
    fig.suptitle(f"{title}: {len(rows)} trials, {n_ok} ok{note}" if title else f"{len(rows)} trials{note}")
    return fig


def summary_plot(
    rows: list[dict[str, Any]], out: Path, *, title: str = "", metrics: Iterable[str] = ()
) -> Path | None:
    """Write :func:`summary_figure` to ``out/summary.png`` atomically; None when there is nothing to draw."""
    fig = summary_figure(rows, title=title, metrics=metrics)
    if fig is None:
        return None
    path = Path(out) / "summary.png"
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    return path


# ---------------------------------------------------------------- CLI
def _cmd_sweep(args: argparse.Namespace) -> int:
    rows = run_sweep(args.experiment, args.out, workers=args.workers, executor=args.executor, limit=args.limit,
                     retry_failed=args.retry_failed)
    n_ok = sum(bool(r.get("ok")) for r in rows)
    print(f"{len(rows)} trials ({n_ok} ok); summary: {Path(args.out) / 'summary.md'}")
    summary = Path(args.out) / "summary.md"
    if summary.exists() and len(summary.read_text()) < 6000:
        sys.stdout.write(summary.read_text())
    if n_ok < len(rows):
        # Exit 1: some trials raised (their errors are in summary.md); a re-run with --retry-failed redoes them.
        errors = {r.get("error") for r in rows if not r.get("ok")}
        first = " ".join(str(sorted(errors, key=str)[0]).split())[:160]
        print(f"asmteach: {len(rows) - n_ok} of {len(rows)} trials failed ({len(errors)} distinct error(s), e.g. "
              f"{first}); re-run with --retry-failed to run them again", file=sys.stderr)
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
