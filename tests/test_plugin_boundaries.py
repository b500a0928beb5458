"""The architecture's import rules, checked on the source tree.

- ``core/`` never imports from ``plugins/`` (the core knows no plugin).
- A plugin is a folder ``plugins/<group>/<name>/``; it imports ``asmteach.core...``
  and its own folder only, never another plugin's folder: what two plugins share
  lives in the core under a public name, so a third-party package can rely on it.
- Nothing but ``__init__.py`` sits at ``plugins/`` or ``plugins/<group>/``: a
  module there would be shared by the plugins beside it, which is the core's job.

Imports are read with :mod:`ast`, so lazy imports inside functions count too.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "asmteach"


def _imports(text: str, rel: Path) -> list[tuple[int, str]]:
    """(line, dotted module) of every import in a source text at ``rel`` (relative to the repository root)."""
    here = [PACKAGE, *rel.with_suffix("").parts]
    found: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(text, filename=str(rel))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - node.level]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            found.append((node.lineno, module))
    return found


def _imported_modules(path: Path) -> list[tuple[int, str]]:
    return _imports(path.read_text(), path.relative_to(ROOT))


def _owner(module: str) -> str | None:
    """The plugin folder ``group/name`` a dotted ``asmteach.plugins...`` module lives in."""
    parts = module.split(".")
    if parts[:2] != [PACKAGE, "plugins"]:
        return None
    return "/".join(parts[2:4])


def _sources(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py"))


def test_the_trees_exist() -> None:
    # Guards the other tests against passing on an empty glob.
    assert len(_sources("core")) > 20 and len(_sources("plugins")) > 20


def test_core_imports_no_plugin() -> None:
    bad = [
        f"{path.relative_to(ROOT)}:{line} imports {module}"
        for path in _sources("core")
        for line, module in _imported_modules(path)
        if _owner(module) is not None or module == f"{PACKAGE}.plugins"
    ]
    assert not bad, "the core imports plugins:\n" + "\n".join(bad)


def test_every_plugin_module_is_inside_a_plugin_folder() -> None:
    stray = [
        str(path.relative_to(ROOT))
        for path in _sources("plugins")
        if len(path.relative_to(ROOT / "plugins").parts) < 3 and path.name != "__init__.py"
    ]
    assert not stray, "modules shared between plugins belong in core/:\n" + "\n".join(stray)


def test_no_plugin_imports_another() -> None:
    bad = []
    for path in _sources("plugins"):
        rel = path.relative_to(ROOT / "plugins").parts
        if len(rel) < 3:
            continue
        mine = "/".join(rel[:2])
        for line, module in _imported_modules(path):
            owner = _owner(module)
            if owner is not None and owner != mine:
                bad.append(f"plugins/{'/'.join(rel)}:{line} imports {module}")
    assert not bad, "a plugin imports another plugin's folder:\n" + "\n".join(bad)


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("from asmteach.plugins.planners.motion.trrt import X\n", "planners/motion"),
        ("from ..grasps.planner import X\n", "planners/grasps"),
        ("import asmteach.plugins.robots.nextage.sim\n", "robots/nextage"),
    ],
)
def test_the_checker_sees_imports(source: str, expected: str) -> None:
    # A checker that never finds anything would pass silently; feed it one import of each form.
    modules = [m for _, m in _imports(source, Path("plugins/planners/regrasp/probe.py"))]
    assert [_owner(m) for m in modules] == [expected]
