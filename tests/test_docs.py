"""Docs that run: every fenced code block of README.md, docs/*.md and docs/results/**/*.md is run or checked.

Rules, by the block's language tag (README.md and docs/*.md):

* ``python``: the blocks of one document run in order, each in a fresh interpreter, in one temporary folder
  (the working directory, also on ``PYTHONPATH``). A block whose first line is a comment naming a ``.py``
  file (``# my_detector/plugin.py``) is also written to that file there, so later blocks import it.
* ``sh`` / ``bash`` / ``console``: every command line runs from the repository root with the venv's ``bin``
  first on ``PATH`` and must exit 0. In a ``console`` block the lines after a ``$`` prompt are commands and
  the rest is their output; output that starts ``asmteach: error:`` says the command fails: it must exit 2
  and print that line. A path after ``--out`` is moved into the temporary folder. Three kinds of command are
  not run as written:

  - ``asmteach run CONFIG ...`` and ``asmteach sweep EXPERIMENT ...`` take minutes: the fast test runs
    ``asmteach validate`` on their config (the same loader, so a config that validates is one whose run
    starts) and the real argument parser accepts their flags. Whole runs are the pipeline's own tests
    (``tests/core/pipeline``, ``tests/core/test_end_to_end_experiment.py``), not repeated here.
  - ``pip install PATH`` would change the venv: it runs as ``pip install --dry-run --no-deps
    --no-build-isolation --no-index PATH`` (the package builds, nothing is installed).
  - ``make TARGET`` runs as ``make -n TARGET`` (what it would do: ``make test`` inside a test recurses).

* ``yaml``: parsed. A whole run config (it has ``structure:``) is validated with ``asmteach validate``,
  its relative paths read from the repository root; a fragment's top-level keys must be run-config
  sections.
* ``toml``: parsed with :mod:`tomllib`.
* ``text`` (or no tag): an illustration (a layout, an output), not run; an untagged block whose lines look
  like commands fails, so a command is never left unchecked by forgetting its tag.

docs/results/** holds the commands behind measured results; they take minutes to hours (sweeps of hundreds
of trials, a PCL build), so they are checked to parse, not run: an ``asmteach`` command by the real
argument parser (the command exists and accepts its flags), ``python benchmarks/X.py ...`` by the script's
``--help`` naming every flag used, ``python -m pytest PATH`` by PATH existing. Set-up tools (apt-get,
cmake, make) are not checked there.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
RESULTS = sorted((REPO / "docs" / "results").rglob("*.md"))
SHELL = {"sh", "bash", "shell", "console"}
ILLUSTRATION = {"text", "", "output"}
LONG = {"run", "sweep"}
"""asmteach commands that take minutes: validated and their flags parsed, not run."""
COMMAND_LIKE = re.compile(r"^\s*(\$ |asmteach |\.venv/bin/|python |pip |make |cd )")


@dataclass
class Block:
    doc: Path
    line: int
    lang: str
    text: str

    @property
    def id(self) -> str:
        return f"{self.doc.relative_to(REPO)}:{self.line}:{self.lang or 'untagged'}"


def blocks(doc: Path) -> list[Block]:
    """The fenced code blocks of ``doc`` (```` ``` ```` fences, the info string's first word as the tag)."""
    out, lines = [], doc.read_text().splitlines()
    i = 0
    while i < len(lines):
        m = re.match(r"^(\s*)(`{3,})\s*([\w+-]*)", lines[i])
        if not m:
            i += 1
            continue
        fence, start = m.group(2), i
        body = []
        i += 1
        while i < len(lines) and not lines[i].strip().startswith(fence):
            body.append(lines[i])
            i += 1
        out.append(Block(doc, start + 1, m.group(3).lower(), "\n".join(body) + "\n"))
        i += 1
    return out


def steps(block: Block) -> list[tuple[list[str], list[str]]]:
    """``(command words, output lines shown after it)`` of a shell block, split as the shell would."""
    out: list[tuple[list[str], list[str]]] = []
    for line in block.text.splitlines():
        if block.lang == "console" and not line.startswith("$ "):
            if out and line.strip():
                out[-1][1].append(line)
            continue
        words = shlex.split(line.removeprefix("$ ") if block.lang == "console" else line, comments=True)
        if words:
            out.append((words, []))
    return out


def commands(block: Block) -> list[list[str]]:
    """The command lines of a shell block (comments dropped)."""
    return [words for words, _ in steps(block)]


def env() -> dict[str, str]:
    return {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ.get('PATH', '')}"}


def _asmteach(words: list[str]) -> list[str] | None:
    """``words`` without the ``asmteach`` program name, or None when it is not an asmteach command."""
    if words and Path(words[0]).name == "asmteach":
        return words[1:]
    return None


def _with_out_in(words: list[str], tmp: Path) -> list[str]:
    """``--out DIR`` moved into ``tmp`` (a doc's output never lands in the repository)."""
    out = list(words)
    for i, w in enumerate(out[:-1]):
        if w == "--out":
            out[i + 1] = str(tmp / Path(out[i + 1]).name)
    return out


def _parse(argv: list[str]) -> None:
    """The real ``asmteach`` argument parser (with every plugin's commands) accepts ``argv``."""
    from asmteach.core.cli import build_parser
    from asmteach.core.hooks import make_plugin_manager

    try:
        build_parser(make_plugin_manager(progress=False)).parse_args(argv)
    except SystemExit as exc:
        pytest.fail(f"asmteach {shlex.join(argv)}: the argument parser refuses it (exit {exc.code})")


def _run(argv: list[str], where: Block, cwd: Path = REPO, timeout: float = 300) -> str:
    proc = subprocess.run(argv, cwd=cwd, env=env(), capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{where.id}: {shlex.join(argv)} exited {proc.returncode}:\n{proc.stderr[-2000:]}"
    return proc.stdout


def run_command(words: list[str], block: Block, tmp: Path, shown: list[str] = ()) -> None:
    """One command of a docs/*.md or README.md shell block, by the rules of the module docstring."""
    args = _asmteach(words)
    if shown and shown[0].startswith("asmteach: error:"):  # a documented failure: exit 2 and that line
        assert args is not None, f"{block.id}: only asmteach commands are shown failing"
        proc = subprocess.run(
            [str(BIN / "asmteach"), *_with_out_in(args, tmp)],
            cwd=REPO,
            env=env(),
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert proc.returncode == 2, f"{block.id}: {shlex.join(words)} exited {proc.returncode}, the doc says 2"
        assert shown[0].strip() in proc.stderr, f"{block.id}: the doc shows {shown[0]!r}, got {proc.stderr!r}"
    elif args is not None:
        args = _with_out_in(args, tmp)
        if args and args[0] in LONG:
            _parse(args)
            config = next(a for a in args[1:] if not a.startswith("-"))
            _run([str(BIN / "asmteach"), "validate", config], block)
        else:
            _run([str(BIN / "asmteach"), *args], block)
    elif words[:2] == ["pip", "install"]:
        _run(
            [
                str(BIN / "python"),
                "-m",
                "pip",
                "install",
                "--dry-run",
                "--no-deps",
                "--no-build-isolation",
                "--no-index",
                "--quiet",
                *words[2:],
            ],
            block,
        )
    elif words[0] == "make":
        assert _run(["make", "-n", *words[1:]], block).strip(), f"{block.id}: make {words[1:]} does nothing"
    else:
        pytest.fail(f"{block.id}: {shlex.join(words)}: no rule for this command (see the module docstring)")


def check_yaml(block: Block, tmp: Path) -> None:
    from asmteach.core.config import RunConfig

    data = yaml.safe_load(block.text)
    assert isinstance(data, dict), f"{block.id}: a yaml block is a mapping"
    if "structure" in data:  # a whole run config: relative paths from the repository root
        for key in ("structure", "camera"):
            if isinstance(data.get(key), str) and not Path(data[key]).is_absolute():
                data[key] = str(REPO / data[key])
        path = tmp / f"config_{block.line}.yaml"
        path.write_text(yaml.safe_dump(data))
        _run([str(BIN / "asmteach"), "validate", str(path)], block)
    elif "experiment" not in data and "part_a" not in data and "name" not in data:
        unknown = set(data) - set(RunConfig.model_fields)
        assert not unknown, f"{block.id}: {sorted(unknown)} are not run-config sections"


CHECK_PLUGINS = """
import inspect, runpy, sys
from asmteach.core.interfaces import ROLES, Plugin

names = runpy.run_path(sys.argv[1], run_name="__main__")
for cls in [v for v in names.values() if isinstance(v, type) and issubclass(v, Plugin) and v.__module__ == "__main__"]:
    for base in (b for b in ROLES.values() if issubclass(cls, b)):
        for name, member in vars(cls).items():
            role_method = getattr(base, name, None)
            if inspect.isfunction(member) and not name.startswith("_") and inspect.isfunction(role_method):
                want = list(inspect.signature(getattr(base, name)).parameters)
                got = list(inspect.signature(member).parameters)
                assert got == want, f"{cls.__name__}.{name}{tuple(got)} does not match {base.__name__}: {tuple(want)}"
    for key, field in cls.Settings.model_fields.items():
        assert field.description, f"{cls.__name__}.Settings.{key} has no description (say what it is and its unit)"
"""
"""Runs a docs block as ``__main__``, then checks the plugin classes it defines: each method it overrides takes
the role interface's parameters (a ``detect`` without ``viewpoint`` would fail in a run), each setting has a
description."""


def run_python(doc_blocks: list[Block], tmp: Path) -> None:
    for block in doc_blocks:
        first = block.text.lstrip().splitlines()[0] if block.text.strip() else ""
        m = re.match(r"#\s*([\w./-]+\.py)\s*$", first)
        if m:
            target = tmp / m.group(1)
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(block.text)
        script = tmp / f"block_{block.line}.py"
        script.write_text(block.text)
        proc = subprocess.run(
            [sys.executable, "-c", CHECK_PLUGINS, str(script)],
            cwd=tmp,
            capture_output=True,
            text=True,
            timeout=120,
            env={**env(), "PYTHONPATH": str(tmp)},
        )
        assert proc.returncode == 0, f"{block.id} failed:\n{proc.stderr[-3000:]}"


ALL = [b for doc in DOCS for b in blocks(doc)]


def test_the_docs_have_blocks_of_every_kind() -> None:
    """The extractor finds the blocks (an empty list would make every test below pass)."""
    kinds = {b.lang for b in ALL}
    assert {"python", "sh", "yaml", "toml"} <= kinds, kinds
    assert any(b.doc.name == "plugins.md" and b.lang == "python" for b in ALL)


@pytest.mark.parametrize("doc", DOCS, ids=[str(d.relative_to(REPO)) for d in DOCS])
def test_python_blocks_run(doc: Path, tmp_path: Path) -> None:
    run_python([b for b in blocks(doc) if b.lang == "python"], tmp_path)


@pytest.mark.parametrize("block", [b for b in ALL if b.lang in SHELL], ids=lambda b: b.id)
def test_shell_blocks_run(block: Block, tmp_path: Path) -> None:
    for words, shown in steps(block):
        run_command(words, block, tmp_path, shown)


@pytest.mark.parametrize("block", [b for b in ALL if b.lang in ("yaml", "toml")], ids=lambda b: b.id)
def test_data_blocks_parse_and_configs_validate(block: Block, tmp_path: Path) -> None:
    if block.lang == "toml":
        tomllib.loads(block.text)
    else:
        check_yaml(block, tmp_path)


@pytest.mark.parametrize("block", [b for b in ALL if b.lang in ILLUSTRATION], ids=lambda b: b.id)
def test_illustrations_hold_no_commands(block: Block) -> None:
    if block.lang == "":
        looks = [line for line in block.text.splitlines() if COMMAND_LIKE.match(line)]
        assert not looks, f"{block.id}: untagged block with commands {looks[:2]}; fence it as sh (or text)"


# ---------------------------------------------------------------- docs/results: parsed, not run
RESULT_BLOCKS = [b for doc in RESULTS for b in blocks(doc) if b.lang not in {"text", "yaml", "toml", "python"}]


def _benchmark_flags(script: Path) -> str:
    proc = subprocess.run(
        [sys.executable, str(script), "--help"], cwd=REPO, env=env(), capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, f"{script} --help exited {proc.returncode}: {proc.stderr[-500:]}"
    return proc.stdout


@pytest.mark.parametrize("block", RESULT_BLOCKS, ids=lambda b: b.id)
def test_results_commands_parse(block: Block) -> None:
    checked = 0
    for words in commands(Block(block.doc, block.line, "sh", block.text)):
        args = _asmteach(words)
        if args is not None:
            _parse(args)
        elif Path(words[0]).name.startswith("python") and words[1:3] == ["-m", "pytest"]:
            paths = [w for w in words[3:] if not w.startswith("-") and w != "no:warnings"]
            assert paths and all((REPO / p).exists() for p in paths), f"{block.id}: {shlex.join(words)}"
        elif Path(words[0]).name.startswith("python") and words[1].startswith("benchmarks/"):
            script = REPO / words[1]
            assert script.is_file(), f"{block.id}: no {words[1]}"
            helptext = _benchmark_flags(script)
            for flag in (w.split("=")[0] for w in words[2:] if w.startswith("--")):
                assert flag in helptext, f"{block.id}: {words[1]} has no {flag}"
        elif words[0] in ("apt-get", "cmake", "make", "sudo"):
            continue  # set-up tools: not checked
        else:
            pytest.fail(f"{block.id}: {shlex.join(words)}: no rule for this command (see the module docstring)")
        checked += 1
    assert checked, f"{block.id}: a results block without a command to check"
