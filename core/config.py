"""Run configurations: YAML into pydantic, with errors a person can act on.

Every section of a run config is a strict model (an unknown key is an error):
the top level (:class:`RunConfig`), ``table`` (:class:`TableSettings`),
``execution`` (:class:`ExecutionSettings`, its ``scene`` a
:class:`SceneSettings`), each role's ``settings`` (the
plugin's own ``Settings`` model) and ``demo`` (the teacher plugin's
``DemoSettings`` model). ``asmteach plugins --settings`` lists them all.
Every error is one line giving the key path and the reason, e.g.
``detector.settings.voxel_size: Input should be greater than 0 (got -1)``.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field, ValidationError, field_validator

from asmteach.core.errors import UserError
from asmteach.core.interfaces import Plugin, Teacher
from asmteach.core.io import read_yaml
from asmteach.core.models import StrictModel, resolve_relative

__all__ = [
    "MAX_SEED",
    "ExecutionSettings",
    "PluginChoice",
    "RunConfig",
    "SceneSettings",
    "TableSettings",
    "check_finite",
    "check_overrides",
    "check_plugin_settings",
    "format_validation_error",
    "load_run_config",
    "validate_demo",
    "validate_settings",
]


class PluginChoice(StrictModel):
    """Which plugin fills a role, and its settings (validated by the plugin)."""

    plugin: str = Field(description="entry-point name within the role's group (`asmteach plugins` lists them)")
    settings: dict[str, Any] = Field(
        default_factory=dict, description="the plugin's own settings, validated by its Settings model"
    )


Coordinate = Annotated[float, Field(ge=-5.0, le=5.0)]
"""A world coordinate within 5 m of the origin (metres); NaN fails the bounds."""
Extent = Annotated[float, Field(gt=0.0, le=5.0)]
"""A positive length up to 5 m (metres); NaN fails the bounds."""


class TableSettings(StrictModel):
    """The work table in front of the robot (world frame, metres).

    One place owns each number: ``height`` is the run's (the simulated table,
    the planners' table plane and the detectors' all use it); ``center`` and
    ``size`` are the robot plugin's own table (its ``table_center`` /
    ``table_size`` settings) unless written here, in which case the run loader
    (:mod:`asmteach.core.run_setup`) hands them to the robot and checks that
    the parts' start region lies on that table. The rendered detection scenes
    of the ``cvfh`` plugin use their own scene table when they are ``None``.
    """

    height: float = Field(0.0, ge=-2.0, le=2.0, description="table top z in the world frame, metres")
    center: tuple[Coordinate, Coordinate] | None = Field(
        None, description="table centre x, y in the world frame, metres; null: the robot plugin's own table"
    )
    size: tuple[Extent, Extent] | None = Field(
        None, description="table extent along world x, y, metres; null: the robot plugin's own table"
    )


class SceneSettings(StrictModel):
    """Where the parts start: world x and |world y| ranges of each part's footprint centre (metres).

    A on one side of the robot (+y or -y, chosen by the seed), B on the other
    (:func:`asmteach.core.scene.random_start_poses`).
    """

    x_range: tuple[float, float] = Field((0.30, 0.44), description="world x of a part's centre, [low, high] metres")
    y_range: tuple[float, float] = Field(
        (0.14, 0.28), description="|world y| of a part's centre, [low, high] metres (both sides)"
    )
    min_probability: float = Field(
        0.05, ge=0.0, le=1.0, description="least likely resting pose drawn (probability 0..1)"
    )


class ExecutionSettings(StrictModel):
    """The run config's ``execution`` section: the simulated world and what is recorded."""

    scene: SceneSettings = Field(
        default_factory=SceneSettings, description="where the parts start on the table (world x, |y|, metres)"
    )
    animation: bool = Field(True, description="record an animated GIF of the execution (execution.gif)")
    animation_fps: float = Field(4.0, gt=0.0, le=30.0, description="GIF frames per simulated second, 1/s")
    success_position_mm: float = Field(
        2.0, gt=0.0, description="success needs B's position in A's frame within this of T_A_B, millimetres"
    )
    success_angle_deg: float = Field(
        2.0, gt=0.0, description="success needs B's rotation in A's frame within this of T_A_B, degrees"
    )
    success_a_goal_mm: float = Field(
        3.0, gt=0.0, description="success needs A within this of its planned goal position, millimetres"
    )
    depth_frames: int = Field(
        4,
        ge=1,
        le=30,
        description="depth frames stacked into the cloud each time the parts are looked at: the noise is new in "
        "every frame, and four frames cut the peg's detection error from 0.3-0.7 mm to 0.1-0.4 mm (demo seeds 0, 1, "
        "19, 49, 57, 63), against the hole's 0.5 mm clearance",
    )
    recheck_plan: bool = Field(True, description="re-check the plan with the robot's independent collision check")
    look_again: Literal["never", "ambiguous", "always"] = Field(
        "always",
        description="when to detect A again once it stands at its goal: 'ambiguous' only when its first detection "
        "was (a twin pose explained the view as well); the assembly is planned again if A is not at its goal, and "
        "B's insertion is aimed at the A that is seen if it is a little off (reaim_mm, reaim_deg)",
    )
    reaim_mm: float = Field(
        0.8,
        ge=0.0,
        description="A seen at its goal puts B's assembled pose this far (millimetres) from the planned one: B's "
        "insertion is planned again into the A that is seen. The detection there is 0.1-0.5 mm off (A itself is put "
        "down 0.1 mm off as a rule); below this, aiming at what is seen adds more error than it removes",
    )
    reaim_deg: float = Field(1.0, ge=0.0, description="the same, for the rotation of B's assembled pose, degrees")

    @field_validator("look_again", mode="before")
    @classmethod
    def _look_again_bool(cls, v: Any) -> Any:
        # configs written before the choice existed said true / false
        return {True: "ambiguous", False: "never"}.get(v, v) if isinstance(v, bool) else v


MAX_SEED = 2**31 - 1
"""Largest seed: libraries seeded from it (Open3D's RANSAC) take a signed 32-bit integer."""


class RunConfig(StrictModel):
    """Top-level config of ``asmteach run`` / ``validate``; paths are relative to the config's folder."""

    name: str = Field("run", description="name of the run (report title, output folder's record)")
    seed: int = Field(0, ge=0, le=MAX_SEED, description="every random choice of the run flows from it")
    structure: str = Field(description="assembly structure YAML (parts A and B, T_A_B, v_a)")
    camera: str | None = Field(None, description="RGB camera intrinsics YAML; default: a C615-like webcam")
    table: TableSettings = Field(default_factory=TableSettings, description="the work table (world frame, metres)")
    teacher: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="aruco"), description="learns T_A_B and v_a (teachers)"
    )
    detector: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="cvfh_icp"), description="finds each part's pose (detectors)"
    )
    corrector: PluginChoice | None = Field(
        default_factory=lambda: PluginChoice(plugin="stable_placements"),
        description="snaps a detected pose to a resting pose (correctors); null: none",
    )
    grasp_planner: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="antipodal"), description="grasps of each part (grasp_planners)"
    )
    motion_planner: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="trrt"), description="collision-free arm paths (motion_planners)"
    )
    robot: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="nextage_pybullet"),
        description="the simulated robot, its sensor and table (robots)",
    )
    assembly_planner: PluginChoice = Field(
        default_factory=lambda: PluginChoice(plugin="regrasp"),
        description="the pick, place and insert plan (assembly_planners)",
    )
    demo: dict[str, Any] = Field(
        default_factory=dict,
        description="settings of the teacher's rendered demonstration, validated by the teacher plugin's "
        "DemoSettings model (`asmteach plugins --settings` lists them)",
    )
    execution: ExecutionSettings = Field(
        default_factory=ExecutionSettings, description="the simulated execution and what counts as success"
    )

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


MAX_ECHO = 40
"""Longest input value quoted back in an error; a longer text is described, never printed (it may be a file's
contents read by mistake, such as ``--hand /etc/passwd``)."""


def _echo(value: Any) -> str:
    """``value`` for an error message: short values as written, long texts by their length only."""
    if hasattr(value, "tolist") and not isinstance(value, str | bytes):  # a numpy array: as the numbers written
        value = value.tolist()
    if isinstance(value, str | bytes) and (len(value) > MAX_ECHO or "\n" in str(value)):
        return f"a text of {len(value)} characters"
    text = repr(value)
    return text if len(text) <= MAX_ECHO else f"a {type(value).__name__}"


_KIND = {
    "str": "a text",
    "int": "a number",
    "float": "a number",
    "bool": "true/false",
    "list": "a list",
    "NoneType": "nothing (null)",
}
"""How a value read from YAML is named in an error, by its Python type."""


def format_validation_error(exc: ValidationError, prefix: str = "") -> str:
    """First error of a pydantic ``ValidationError`` as ``key.path: reason (got value)``."""
    lines = []
    # A misspelt key also makes the key it was meant to be "missing": the unknown key is the cause, said first.
    for err in sorted(exc.errors(), key=lambda e: e["type"] != "extra_forbidden"):
        loc = _fmt_loc(tuple(p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-"))))
        path = ".".join(x for x in (prefix, loc) if x)
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key (not a setting of this section; check the spelling)"
        elif err["type"] == "missing":
            at = err["loc"][-1] if err["loc"] else None
            msg = (
                f"too few values (item [{at}] is missing)"
                if isinstance(at, int) and not isinstance(at, bool)
                else "required key is missing"
            )
        elif err["type"] in ("model_type", "dict_type", "model_attributes_type"):
            # the whole section (or file) is not a mapping; its text is not echoed
            got = _KIND.get(type(err.get("input")).__name__, f"a {type(err.get('input')).__name__}")
            msg = f"expected a mapping of keys and values, got {got}"
        elif "input" in err and not isinstance(err["input"], dict | list):
            msg = f"{msg} (got {_echo(err['input'])})"
        msg = msg.removeprefix("Value error, ")
        lines.append(f"{path}: {msg}" if path else msg)  # a check of the whole section speaks for itself
    more = f" (and {len(lines) - 1} more)" if len(lines) > 1 else ""
    return lines[0] + more


def check_finite(tree: Any, where: str = "") -> None:
    """:class:`UserError` naming the key path of the first NaN or infinity in a tree read from YAML.

    YAML writes them ``.nan`` / ``.inf``; no setting of asmteach takes one, and
    a NaN passes every ``>``/``<`` bound check unnoticed, so they are refused
    wherever they are (plugin settings included).
    """

    def walk(node: Any, path: str) -> str | None:
        if isinstance(node, float) and not math.isfinite(node):
            return path or "<root>"
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        for k, v in items:
            sub = f"{path}[{k}]" if isinstance(k, int) else ".".join(x for x in (path, str(k)) if x)
            found = walk(v, sub)
            if found is not None:
                return found
        return None

    bad = walk(tree, "")
    if bad is not None:
        prefix = f"{where}: " if where else ""
        raise UserError(f"{prefix}{bad}: not a finite number (NaN or infinity); write a number")


def validate_settings(cls: type[Plugin], settings: dict[str, Any], *, where: str) -> BaseModel:
    """Validate ``settings`` with the plugin's own model; :class:`UserError` names the key path."""
    try:
        return cls.Settings.model_validate(settings)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, where)) from None


def check_plugin_settings(role: str, name: str, settings: dict[str, Any], *, name_key: str, settings_key: str) -> None:
    """Plugin ``name`` of ``role`` exists and ``settings`` pass its model; :class:`UserError` naming the key.

    For settings an experiment's params carry for a plugin it builds per trial (checked up front, in
    ``Experiment.check``, like a run config's).
    """
    from asmteach.core import registry

    try:
        cls = registry.get_class(role, name)
    except UserError as exc:
        raise UserError(f"{name_key}: {exc}") from None
    validate_settings(cls, settings, where=settings_key)


def validate_demo(teacher: type[Teacher], name: str, demo: dict[str, Any]) -> BaseModel | None:
    """The ``demo`` section validated by the teacher's ``DemoSettings`` model; None if the teacher has none.

    A teacher that renders demonstrations declares the model of their
    settings as :attr:`Teacher.DemoSettings <asmteach.core.interfaces.Teacher.DemoSettings>`
    (as it declares ``Settings``); a ``demo`` section given to a teacher
    without one is an error, not ignored.
    """
    model = teacher.DemoSettings
    if model is None:
        if demo:
            raise UserError(
                f"demo: the teacher plugin {name!r} takes no demo settings (it renders no "
                "demonstration); remove the demo section"
            )
        return None
    try:
        return model.model_validate(demo)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc, "demo")) from None


def load_run_config(
    path: str | Path, *, check_plugins: bool = True, overrides: dict[str, Any] | None = None
) -> RunConfig:
    """Read and validate a run config: every section, and with ``check_plugins`` every plugin's settings.

    ``overrides`` maps dotted keys (``"detector.settings.voxel_size"``) to
    values applied before validation (used by sweeps).
    """
    p = Path(path)
    raw = read_yaml(p)
    if not isinstance(raw, dict):
        raise UserError(f"{p}: a config must be a YAML mapping at the top level")
    try:
        cfg = _validate_run_config(raw, overrides, check_plugins=check_plugins)
    except UserError as exc:
        raise UserError(f"{p}: {exc}") from None
    cfg.base_dir = p.resolve().parent
    if check_plugins:
        structure = cfg.path(cfg.structure)
        if not structure.is_file():
            raise UserError(f"{p}: structure: no such file {structure}")
    return cfg


def check_overrides(overrides: dict[str, Any], *, where: str = "params.overrides") -> None:
    """Dotted run-config keys (as ``asmteach run --set``) checked against every section, before any run.

    For an experiment whose run configs are made per trial: the keys are set
    on a config of the default plugins (or those the overrides choose), so a
    misspelt key, in any section or plugin's settings, fails here in one line
    naming ``where``.
    """
    try:
        defaults = RunConfig(structure="checked later.yaml").model_dump(mode="json", include=set(ROLE_OF_KEY))
        _validate_run_config({"structure": "checked later.yaml", **defaults}, overrides, check_plugins=True)
    except UserError as exc:
        raise UserError(f"{where}: {exc}") from None


def _validate_run_config(raw: dict[str, Any], overrides: dict[str, Any] | None, *, check_plugins: bool) -> RunConfig:
    """``raw`` with ``overrides`` set, as a :class:`RunConfig`; with ``check_plugins`` each plugin's settings too."""
    raw = copy.deepcopy(raw)
    for key, value in (overrides or {}).items():
        set_dotted(raw, key, value)
    check_finite(raw)
    try:
        cfg = RunConfig.model_validate(raw)
    except ValidationError as exc:
        raise UserError(format_validation_error(exc)) from None
    if check_plugins:
        from asmteach.core import registry

        for key, role in ROLE_OF_KEY.items():
            choice: PluginChoice | None = getattr(cfg, key)
            if choice is None:
                continue
            try:
                cls = registry.get_class(role, choice.plugin)
            except UserError as exc:
                raise UserError(f"{key}.plugin: {exc}") from None
            validate_settings(cls, choice.settings, where=f"{key}.settings")
            if key == "teacher":
                validate_demo(cls, choice.plugin, cfg.demo)
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
