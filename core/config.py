"""Run configurations: YAML into pydantic, with errors a person can act on.

A config names one plugin per role and carries that plugin's settings, which
the plugin's own ``Settings`` model validates. Every error is one line giving
the key path and the reason, e.g.
``detector.settings.voxel_size: Input should be greater than 0 (got -1)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pydantic import BaseModel, Field, ValidationError

from asmteach.core.errors import UserError
from asmteach.core.interfaces import Plugin
from asmteach.core.io import read_yaml
from asmteach.core.models import StrictModel, resolve_relative

__all__ = [
    "PluginChoice",
    "RunConfig",
    "TableSettings",
    "format_validation_error",
    "load_run_config",
    "validate_settings",
]


class PluginChoice(StrictModel):
    """Which plugin fills a role, and its settings (validated by the plugin)."""

    plugin: str = Field(description="entry-point name within the role's group")
    settings: dict[str, Any] = Field(default_factory=dict)


class TableSettings(StrictModel):
    """The work table in front of the robot (world frame, metres)."""

    height: float = Field(0.0, ge=-2.0, le=2.0, description="table top z in the world frame")
    center: tuple[float, float] = Field((0.45, 0.0), description="table centre x, y")
    size: tuple[float, float] = Field((0.8, 1.2), description="table extent along x, y")


class RunConfig(StrictModel):
    """Top-level config of ``asmteach run`` / ``validate``."""

    name: str = "run"
    seed: int = Field(0, ge=0, description="every random choice of the run flows from it")
    structure: str = Field(description="assembly structure YAML (parts A and B, T_A_B, v_a)")
    camera: str | None = Field(None, description="RGB camera intrinsics YAML; default: a C615-like webcam")
    table: TableSettings = Field(default_factory=TableSettings)
    teacher: PluginChoice = Field(default_factory=lambda: PluginChoice(plugin="aruco"))
    detector: PluginChoice = Field(default_factory=lambda: PluginChoice(plugin="cvfh_icp"))
    corrector: PluginChoice | None = Field(default_factory=lambda: PluginChoice(plugin="stable_placements"))
    grasp_planner: PluginChoice = Field(default_factory=lambda: PluginChoice(plugin="antipodal"))
    motion_planner: PluginChoice = Field(default_factory=lambda: PluginChoice(plugin="trrt"))
    robot: PluginChoice = Field(default_factory=lambda: PluginChoice(plugin="nextage_pybullet"))
    assembly_planner: PluginChoice = Field(default_factory=lambda: PluginChoice(plugin="regrasp"))
    demo: dict[str, Any] = Field(
        default_factory=dict, description="settings of the demonstration renderer (render-demo)"
    )
    execution: dict[str, Any] = Field(default_factory=dict, description="settings of the simulated execution")

    base_dir: Path | None = Field(None, exclude=True, description="folder of the YAML file; set by the loader")

    def path(self, relative: str) -> Path:
        """Resolve a path written in the config against the config's folder."""
        return resolve_relative(relative, self.base_dir or Path.cwd())


ROLE_OF_KEY = {
    "teacher": "teachers",
    "detector": "detectors",
    "corrector": "correctors",
    "grasp_planner": "grasp_planners",
    "motion_planner": "motion_planners",
    "robot": "robots",
    "assembly_planner": "assembly_planners",
}


def _fmt_loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def format_validation_error(exc: ValidationError, prefix: str = "") -> str:
    """First error of a pydantic ``ValidationError`` as ``key.path: reason (got value)``."""
    lines = []
    for err in exc.errors():
        loc = _fmt_loc(tuple(p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-"))))
        path = ".".join(x for x in (prefix, loc) if x)
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (not a setting of this section; check the spelling)"
        elif err["type"] == "missing":
            msg = "required key is missing"
        elif "input" in err and not isinstance(err["input"], dict | list):
            msg = f"{msg} (got {err['input']!r})"
        msg = msg.removeprefix("Value error, ")
        lines.append(f"{path or '<root>'}: {msg}")
    more = f" (and {len(lines) - 1} more)" if len(lines) > 1 else ""
    return lines[0] + more


def validate_settings(cls: type[Plugin], settings: dict[str, Any], *, where: str) -> BaseModel:
    """Validate ``settings`` with the plugin's own model; :class:`UserError` names the key path."""
    try:
        return cls.Settings.model_validate(settings)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, where)) from None


def load_run_config(
    path: str | Path, *, check_plugins: bool = True, overrides: dict[str, Any] | None = None
) -> RunConfig:
    """Read and validate a run config, including every chosen plugin's settings.

    ``overrides`` maps dotted keys (``"detector.settings.voxel_size"``) to
    values applied before validation (used by sweeps).
    """
    p = Path(path)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: a config must be a YAML mapping at the top level")
    for key, value in (overrides or {}).items():
        set_dotted(raw, key, value)
    try:
        cfg = RunConfig.model_validate(raw)
    except ValidationError as exc:
        raise UserError(f"{p}: {format_validation_error(exc)}") from None
    cfg.base_dir = p.resolve().parent
    if check_plugins:
        from asmteach.core import registry

        for key, role in ROLE_OF_KEY.items():
            choice: PluginChoice | None = getattr(cfg, key)
            if choice is None:
                continue
            try:
                cls = registry.get_class(role, choice.plugin)
            except UserError as exc:
                raise UserError(f"{p}: {key}.plugin: {exc}") from None
            try:
                validate_settings(cls, choice.settings, where=f"{key}.settings")
            except UserError as exc:
                raise UserError(f"{p}: {exc}") from None
        structure = cfg.path(cfg.structure)
        if not structure.is_file():
            raise UserError(f"{p}: structure: no such file {structure}")
    return cfg


def set_dotted(tree: dict[str, Any], dotted: str, value: Any) -> None:
    """Set ``tree["a"]["b"]["c"] = value`` for ``dotted == "a.b.c"``, creating mappings."""
    keys = dotted.split(".")
    node = tree
    for k in keys[:-1]:
        nxt = node.get(k)
        if nxt is None:
            nxt = node[k] = {}
        if not isinstance(nxt, dict):
            raise UserError(f"cannot set {dotted}: {k} is not a mapping")
        node = nxt
    node[keys[-1]] = value
