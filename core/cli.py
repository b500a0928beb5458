"""The ``asmteach`` command line: a thin shell over the library.

Core commands live here; plugins add theirs through the
``asmteach_add_commands`` hook. Any :class:`UserError` becomes one line on
stderr and exit code 2; nothing the user typed produces a traceback.
"""

from __future__ import annotations

import argparse
import logging
import sys
import traceback
from collections.abc import Sequence
from importlib import metadata
from pathlib import Path

from asmteach.core.errors import UserError
from asmteach.core.io import describe_os_error

__all__ = ["build_parser", "main"]

log = logging.getLogger("asmteach")


def _print_settings(title: str, model: type, prefix: str = "") -> None:
    """One block of ``plugins --settings``: a title line, then ``key  type  default  description`` rows."""
    from asmteach.core.settings_listing import describe_settings

    rows = describe_settings(model, prefix)
    print(f"{title}:" if rows else f"{title}: no settings")
    widths = [max(len(r[i]) for r in rows) for i in range(3)] if rows else []
    for key, kind, default, text in rows:
        print(f"  {key:<{widths[0]}}  {kind:<{widths[1]}}  {default:<{widths[2]}}  {text}".rstrip())
    print()


def _cmd_plugin_settings(args: argparse.Namespace) -> int:
    """``plugins --settings``: the run config's own sections, then every plugin's ``Settings`` (and ``demo``)."""
    from asmteach.core import registry
    from asmteach.core.config import ROLE_OF_KEY, RunConfig

    key_of_role = {role: key for key, role in ROLE_OF_KEY.items()}
    if args.role is None:
        _print_settings("run config (key, type, default, description)", RunConfig)
    broken = 0
    for info in registry.discover(args.role):
        where = f"{key_of_role.get(info.role, info.role)}.settings"
        title = f"{registry.group_name(info.role)} {info.name} ({where})"
        if info.cls is None:
            broken += 1
            print(f"{title}: import error: {info.error}\n")
            continue
        _print_settings(title, info.cls.Settings, prefix=f"{where}.")
        demo = getattr(info.cls, "DemoSettings", None)
        if demo is not None:
            _print_settings(f"{registry.group_name(info.role)} {info.name} (demo)", demo, prefix="demo.")
    if broken:
        print(f"{broken} plugin(s) failed to import; the others are usable.", file=sys.stderr)
    return 0


def _cmd_plugins(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from asmteach.core import registry
    from asmteach.core.hooks import hook_errors, make_plugin_manager

    if args.settings:
        return _cmd_plugin_settings(args)
    infos = registry.discover(args.role)
    table = Table(title="asmteach plugins", show_lines=False)
    for col in ("group", "name", "distribution", "version", "status"):
        table.add_column(col)
    broken = 0
    for info in infos:
        status = "[green]ok" if info.error is None else f"[red]import error: {info.error}"
        broken += info.error is not None
        table.add_row(registry.group_name(info.role), info.name, info.distribution, info.version, status)
    if args.role is None:
        make_plugin_manager(progress=False)
        for name, (dist, version, err) in sorted(hook_errors().items()):
            status = "[green]ok" if err is None else f"[red]import error: {err}"
            broken += err is not None
            table.add_row("asmteach.hooks", name, dist, version, status)
    Console(width=200).print(table)
    if broken:
        print(f"{broken} plugin(s) failed to import; the others are usable.", file=sys.stderr)
    return 0


def _cmd_validate(args: argparse.Namespace) -> int:
    from asmteach.core.io import read_yaml
    from asmteach.core.run_setup import load_run

    raw = read_yaml(args.config)
    if isinstance(raw, dict) and "experiment" in raw and "structure" not in raw:
        # an experiment file: every grid point's params, as `sweep` checks them before its first trial
        from asmteach.core.sweep import load_experiment, plan_trials

        if args.set:
            raise UserError("--set applies to run configs; edit the experiment file's params instead")
        exp, kind = load_experiment(args.config)
        n = len(plan_trials(exp, kind))
        print(f"{args.config}: ok (experiment {exp.experiment}: {n} trial{'' if n == 1 else 's'})")
        return 0
    # The same loader as `run`: what validates here starts there (structure, meshes, markers, camera, demo,
    # execution, table, every plugin's settings).
    setup = load_run(args.config, overrides=_overrides(args.set))
    print(f"{args.config}: ok (seed {setup.cfg.seed}; {setup.summary()})")
    return 0


def _cmd_library(args: argparse.Namespace) -> int:
    from asmteach.core.io import check_out_file
    from asmteach.core.library import render_library

    out = render_library(Path(args.folder), check_out_file(args.out, example="sheet.png"))
    print(f"part library contact sheet: {out}")
    return 0


def _overrides(items: Sequence[str] | None) -> dict[str, object] | None:
    """``--set KEY=VALUE`` items as ``{dotted key: value}``, each value read as YAML (``3``, ``[1, 2]``, ``x``)."""
    import yaml

    overrides: dict[str, object] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UserError(f"--set {item!r}: write KEY=VALUE, e.g. --set seed=3")
        try:
            overrides[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError as exc:
            problem = getattr(exc, "problem", None) or "not a YAML value"
            raise UserError(
                f"--set {key.strip()}: the value is not valid YAML ({problem}); quote a text, e.g. --set name='a: b'"
            ) from None
    return overrides or None


def _cmd_run(args: argparse.Namespace) -> int:
    from asmteach.core.io import run_folder
    from asmteach.core.pipeline import run_pipeline
    from asmteach.core.run_setup import load_run

    setup = load_run(args.config, overrides=_overrides(args.set))  # bad input ends here, before any work
    cfg = setup.cfg
    out = Path(args.out)
    # The run writes into a staging folder; the results replace out's only once it has ended (nothing mixed).
    try:
        with run_folder(out, cfg.name, force=args.force) as stage:
            report = run_pipeline(cfg, stage, pm=args.plugin_manager)
    except KeyboardInterrupt:
        print(
            f"asmteach: interrupted; {out} is as it was before this run (its partial results were dropped)",
            file=sys.stderr,
        )
        return 130
    try:
        from asmteach.core.report_html import format_summary

        print(format_summary(report))
    except ImportError:
        print(f"{cfg.name}: {'success' if report.success else 'failed at ' + str(report.failed_stage)}")
    print(f"report: {out / 'report.html'}")
    if not report.success:
        why = " ".join(str(report.reason or "the parts did not end assembled").split())
        print(
            f"asmteach: {cfg.name} failed at {report.failed_stage}: {why[:300]} (report: {out / 'report.html'})",
            file=sys.stderr,
        )
    return 0 if report.success else 1


def build_parser(pm=None) -> argparse.ArgumentParser:
    """The argument parser with core commands and every plugin's commands."""
    try:
        version = metadata.version("asmteach")
    except metadata.PackageNotFoundError:
        version = "unknown"
    parser = argparse.ArgumentParser(
        prog="asmteach",
        description="Teach robots mechanical assembly by demonstration (metres, radians, z up).",
    )
    parser.add_argument("--version", action="version", version=f"asmteach {version}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("plugins", help="list discovered plugins per group, with import errors")
    p.add_argument("--role", default=None, help="only this role (e.g. detectors)")
    p.add_argument(
        "--settings",
        action="store_true",
        help="list every setting (key, type, default, description) of the run config and of each plugin",
    )
    p.set_defaults(func=_cmd_plugins)

    p = sub.add_parser(
        "validate",
        help="check a run config (builds everything `run` builds, before any work) or "
        "an experiment file (every grid point)",
    )
    p.add_argument("config")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key (dotted path)")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("library", help="render every part of a part-library folder to a PNG contact sheet")
    p.add_argument("folder", help="folder of part YAML files (searched recursively)")
    p.add_argument("--out", required=True, help="PNG file to write")
    p.set_defaults(func=_cmd_library)

    p = sub.add_parser("run", help="the whole pipeline in simulation (teach, detect, plan, execute) with a report")
    p.add_argument("config", help="run config YAML")
    p.add_argument("--out", required=True, help="output folder (report.json, report.html, figures, animation)")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config key (dotted path)")
    p.add_argument("--force", action="store_true", help="replace another run's results in --out")
    p.set_defaults(func=_cmd_run, plugin_manager=pm)

    from asmteach.core.check_part import add_check_part_command
    from asmteach.core.structure_corpus import add_make_structures_command
    from asmteach.core.sweep import add_sweep_command

    add_sweep_command(sub)
    add_check_part_command(sub, pm)
    add_make_structures_command(sub)

    if pm is not None:
        pm.hook.asmteach_add_commands(subparsers=sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Console-script entry point; returns the exit code."""
    from asmteach.core.hooks import make_plugin_manager

    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    verbose = "-v" in (argv if argv is not None else sys.argv[1:]) or "--verbose" in (
        argv if argv is not None else sys.argv[1:]
    )
    try:
        pm = make_plugin_manager()
        parser = build_parser(pm)
        args = parser.parse_args(argv)
        verbose = bool(args.verbose)
        if args.verbose:
            logging.getLogger().setLevel(logging.DEBUG)
        if getattr(args, "func", None) is None:
            parser.print_help()
            return 2
        return int(args.func(args) or 0)
    except UserError as exc:
        print(f"asmteach: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print("asmteach: interrupted; results written so far are intact", file=sys.stderr)
        return 130
    except OSError as exc:
        # The file system failed mid-way (a full disk, a folder made read-only): the task failed, the input
        # was fine; every result file is written atomically, so those written before are intact.
        print(f"asmteach: error: {describe_os_error(exc)}", file=sys.stderr)
        if verbose:
            traceback.print_exc()
        return 1
    except Exception as exc:  # noqa: BLE001 - one line for the user; the traceback with -v
        if verbose:
            traceback.print_exc()
        text = " ".join(str(exc).split())
        text = text if len(text) <= 200 else text[:200] + "..."
        print(
            f"asmteach: internal error ({type(exc).__name__}: {text}); this is a bug, please report it with "
            "the output of the same command with -v",
            file=sys.stderr,
        )
        return 1


if __name__ == "__main__":
    sys.exit(main())
