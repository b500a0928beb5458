"""Atomic file output and the file formats asmteach reads and writes.

Every result file is written to a temporary sibling and renamed into place,
so an interrupted run (Ctrl-C, crash) leaves either the old file or the new
one, never half of one.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel

from asmteach.core.errors import UserError

__all__ = [
    "append_jsonl",
    "atomic_path",
    "cache_root",
    "check_out_dir",
    "check_out_file",
    "describe_os_error",
    "pid_alive",
    "read_jsonl",
    "read_yaml",
    "run_folder",
    "to_jsonable",
    "write_bytes",
    "write_json",
    "write_model",
    "write_text",
]


def cache_root() -> Path:
    """Folder of asmteach's on-disk caches (view databases, grasp sets).

    ``$ASMTEACH_CACHE_DIR`` when set, else ``$XDG_CACHE_HOME/asmteach``, else
    ``~/.cache/asmteach``. Everything in it can be deleted; it is rebuilt on demand.
    """
    if os.environ.get("ASMTEACH_CACHE_DIR"):
        return Path(os.environ["ASMTEACH_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "asmteach"


def describe_os_error(exc: OSError) -> str:
    """``"<file>: <reason>; <what to do>"`` for an error of the file system, in one line."""
    where = exc.filename or "a file"
    reason = exc.strerror or type(exc).__name__
    fix = {
        errno.ENOSPC: "free some space and re-run; what was written before is intact",
        errno.EDQUOT: "free some space (disk quota) and re-run; what was written before is intact",
        errno.EROFS: "the file system is read-only; give a writable folder",
        errno.EACCES: "no permission to write there; give a writable folder",
        errno.EPERM: "no permission to write there; give a writable folder",
        errno.ENOTDIR: "a part of the path is a file, not a folder",
        errno.EISDIR: "it is a folder; give a file name",
    }.get(exc.errno or 0, "check the path")
    return f"{where}: {reason}; {fix}"


def _probe_writable(folder: Path, flag: str) -> None:
    """:class:`UserError` unless a file can be created in ``folder`` (the probe is removed at once)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".asmteach-probe-", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        raise UserError(f"{flag} {folder}: cannot write there ({exc.strerror}); give a writable folder") from None


def check_out_dir(path: str | os.PathLike[str], *, flag: str = "--out") -> Path:
    """Make sure ``path`` is (or can be made) a writable folder; returns it.

    Called before any work starts, so a read-only folder or an ``--out`` that
    names a file costs one line (exit 2), not a run's worth of computing.
    """
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UserError(f"{flag} {p}: is a file, not a folder; give a folder (it is created if missing)")
    try:
        p.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise UserError(f"{flag} {p}: a part of the path is a file, not a folder; give another folder") from None
    except OSError as exc:
        raise UserError(f"{flag} {p}: cannot create the folder ({exc.strerror}); give a writable folder") from None
    _probe_writable(p, flag)
    return p


def check_out_file(path: str | os.PathLike[str], *, flag: str = "--out", example: str = "out.json") -> Path:
    """Make sure the file ``path`` can be written (its folder is made if missing); returns it.

    ``example``: a file name suggested when ``path`` is a folder.
    """
    p = Path(path)
    if p.is_dir():
        raise UserError(f"{flag} {p}: is a folder; give a file name (e.g. {p / example})")
    if p.exists() and not os.access(p, os.W_OK):
        raise UserError(f"{flag} {p}: the file is read-only; give another file")
    check_out_dir(p.parent if str(p.parent) else Path("."), flag=f"{flag} {p}: folder")
    return p


RUN_MARKER = "report.json"
"""The file whose presence (and ``config.name``) says whose results a run folder holds."""


def _owner(folder: Path, marker: str, key: tuple[str, ...]) -> str | None:
    """The name of the run whose results ``folder`` holds (``marker``'s JSON at ``key``); ``""`` if unknown;
    None if it holds nothing."""
    entries = [e for e in folder.iterdir() if not e.name.startswith(".")]
    if not entries:
        return None
    try:
        node: Any = json.loads((folder / marker).read_text(encoding="utf-8"))
        for k in key:
            node = node[k]
        return str(node)
    except (OSError, ValueError, KeyError, TypeError):
        return ""  # files, but no readable marker: someone else's, or a torn run of an old version


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (one we may not signal counts as alive)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextlib.contextmanager
def run_folder(
    out: str | os.PathLike[str],
    name: str,
    *,
    force: bool = False,
    marker: str = RUN_MARKER,
    key: tuple[str, ...] = ("config", "name"),
) -> Iterator[Path]:
    """A fresh folder to write a run named ``name`` into; its files replace ``out``'s when the block ends.

    Nothing lost, nothing mixed: the run writes into a hidden staging folder
    inside ``out``; only when the block ends normally are ``out``'s old
    results moved aside and the new ones moved in (renames in one folder),
    then the old ones deleted. An interrupted or crashed run leaves ``out``
    as it was (its staging folder is removed, or, after a kill -9, removed by
    the next run). ``out`` holding another run's results (a ``marker`` file
    naming another run at ``key``) is refused unless ``force``; the results
    of the same run are replaced; files without a marker are never replaced.
    """
    target = check_out_dir(out)
    for stale in [*target.glob(".partial-*"), *target.glob(".replaced-*")]:  # left by a run killed with -9
        with contextlib.suppress(ValueError):
            if not pid_alive(int(stale.name.rsplit("-", 1)[1])):
                shutil.rmtree(stale, ignore_errors=True)
    owner = _owner(target, marker, key)
    if owner == "":
        # Never replaced, not even with --force: they may be anything (--out . in a project folder).
        raise UserError(
            f"--out {target}: holds files that are not a run's results (no readable {marker}); give "
            "an empty or new folder"
        )
    if owner is not None and owner != name and not force:
        raise UserError(
            f"--out {target}: holds the results of run {owner!r}; give an empty or new folder, or add "
            "--force to replace them"
        )
    stage = target / f".partial-{os.getpid()}"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir()
    try:
        yield stage
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    old = target / f".replaced-{os.getpid()}"
    old.mkdir(exist_ok=True)
    for entry in target.iterdir():
        if not entry.name.startswith("."):
            entry.rename(old / entry.name)
    for entry in stage.iterdir():
        entry.rename(target / entry.name)
    stage.rmdir()
    shutil.rmtree(old, ignore_errors=True)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success.

    Use for writers that want a file name (matplotlib, OpenCV, Open3D)::

        with atomic_path("out.png") as tmp:
            fig.savefig(tmp)
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    # mkstemp creates 0600; results get the permissions an ordinary open() would give.
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o666 & ~umask)
    try:
        yield tmp
        os.replace(tmp, target)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 text atomically; returns the path."""
    return write_bytes(path, text.encode("utf-8"))


def to_jsonable(obj: Any) -> Any:
    """``obj`` with numpy arrays and scalars as lists and numbers, keys as strings, anything else as ``str``."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if hasattr(obj, "tolist"):  # numpy arrays and scalars
        return to_jsonable(obj.tolist())
    return str(obj)


def write_json(path: str | os.PathLike[str], obj: Any) -> Path:
    """Write JSON (2-space indent) atomically. Pydantic models are dumped in JSON mode."""
    if isinstance(obj, BaseModel):
        obj = obj.model_dump(mode="json")
    return write_text(path, json.dumps(obj, indent=2, allow_nan=True) + "\n")


def write_model(path: str | os.PathLike[str], model: BaseModel) -> Path:
    """Write a pydantic model as JSON atomically."""
    return write_text(path, model.model_dump_json(indent=2) + "\n")


def append_jsonl(path: str | os.PathLike[str], record: dict[str, Any]) -> None:
    """Append one JSON line and fsync it, so a crash loses at most the line in flight."""
    line = json.dumps(record, allow_nan=True) + "\n"
    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_APPEND, 0o666)
    try:
        # A crash (or a full disk) can leave a torn last line; start on a fresh line so the
        # torn fragment stays alone (and is skipped) instead of swallowing this record.
        size = os.lseek(fd, 0, os.SEEK_END)
        if size > 0 and os.pread(fd, 1, size - 1) != b"\n":
            line = "\n" + line
        data = line.encode("utf-8")
        while data:  # os.write may write part of it; the rest follows (or an OSError says why not)
            data = data[os.write(fd, data) :]
        os.fsync(fd)
    finally:
        os.close(fd)


def read_jsonl(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """Read JSON lines, skipping a torn last line left by a crash."""
    p = Path(path)
    if not p.exists():
        return []
    out: list[dict[str, Any]] = []
    for line in p.read_text(encoding="utf-8").splitlines():
        line = line.strip()
        if not line:
            continue
        try:
            record = json.loads(line)
        except json.JSONDecodeError:
            continue
        if isinstance(record, dict):  # a torn line can still parse (a bare number): skip it too
            out.append(record)
    return out


def read_yaml(path: str | os.PathLike[str]) -> Any:
    """Read a YAML file with ``yaml.safe_load``; errors become one-line :class:`UserError`."""
    p = Path(path)
    if p.is_dir():
        raise UserError(f"{p}: is a folder; give a YAML file")
    if not p.is_file():
        raise UserError(f"{p}: no such file")
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise UserError(f"{p}: cannot read it ({exc.strerror})") from None
    if b"\x00" in data[:65536]:
        raise UserError(f"{p}: not a text file (binary data); give a YAML file")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UserError(f"{p}: not UTF-8 text (bad byte at offset {exc.start}); save the YAML as UTF-8") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise UserError(f"{p}: invalid YAML{where}: {problem}") from None
