"""Config validation: each error is one line with the key path and the reason."""

import re
import textwrap
from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel

from asmteach.core.cli import main
from asmteach.core.config import (
    ROLE_OF_KEY,
    PluginChoice,
    RunConfig,
    check_overrides,
    load_run_config,
    set_dotted,
)
from asmteach.core.errors import UserError
from asmteach.core.settings_listing import describe_settings, nested_model


def test_valid_config_loads(toy_config):
    cfg = load_run_config(toy_config)
    assert cfg.seed == 3 and cfg.detector.settings == {"voxel_size": 0.004}
    assert cfg.path(cfg.structure).is_file()


BAD = [
    (
        "detector: {plugin: toy_detector, settings: {voxel_size: -1}}",
        "detector.settings.voxel_size: Input should be greater than 0 (got -1)",
    ),
    (
        "detector: {plugin: toy_detectr}",
        "detector.plugin: no detector plugin named 'toy_detectr'; did you mean 'toy_detector'?",
    ),
    ("detector: {plugin: toy_detector, settings: {voxl_size: 0.1}}", "detector.settings.voxl_size: unknown key"),
    ("seed: -4", "seed: Input should be greater than or equal to 0 (got -4)"),
    ("colour: red", "colour: unknown key"),
    ("table: {height: high}", "table.height: Input should be a valid number"),
    ("robot: {settings: {}}", "robot.plugin: required key is missing"),
    ("structure: nowhere.yaml", "structure: no such file"),
]


@pytest.mark.parametrize("override, message", BAD, ids=[b[1].split(":")[0] for b in BAD])
def test_bad_configs_name_key_and_reason(tmp_path, toy_config, override, message, capsys):
    text = toy_config.read_text()
    key = override.split(":")[0]
    kept = [line for line in text.splitlines() if not line.startswith(key + ":")]
    bad = tmp_path / "bad.yaml"
    bad.write_text("\n".join(kept) + "\n" + override + "\n")
    with pytest.raises(UserError) as err:
        load_run_config(bad)
    assert message in str(err.value)
    assert "\n" not in str(err.value)
    assert main(["validate", str(bad)]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and "Traceback" not in captured.err


def test_invalid_yaml_gives_line_and_column(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text(textwrap.dedent("seed: 1\ndetector: {plugin: x\n"))
    with pytest.raises(UserError, match=r"invalid YAML at line \d+, column \d+"):
        load_run_config(bad)


def test_top_level_must_be_mapping(tmp_path):
    bad = tmp_path / "list.yaml"
    bad.write_text("- 1\n- 2\n")
    with pytest.raises(UserError, match="YAML mapping"):
        load_run_config(bad)


def test_overrides_apply_dotted_keys(toy_config):
    cfg = load_run_config(toy_config, overrides={"detector.settings.voxel_size": 0.008, "seed": 11})
    assert cfg.detector.settings["voxel_size"] == 0.008 and cfg.seed == 11


# ---------------------------------------------------------------- a misspelt key in every section
REPO = Path(__file__).resolve().parents[3]
DEMO = REPO / "configs/demo.yaml"
SECTIONS = [
    "", "table", "execution", "execution.scene", "demo",
    "teacher", "teacher.settings", "detector", "detector.settings", "detector.settings.refine",
    "corrector", "corrector.settings", "grasp_planner", "grasp_planner.settings", "motion_planner",
    "motion_planner.settings", "robot", "robot.settings", "robot.settings.ik", "assembly_planner",
    "assembly_planner.settings",
]  # fmt: skip
"""Every section of configs/demo.yaml's run (plugin settings and their nested sections included)."""


def _section_model(raw: dict, path: str) -> type[BaseModel]:
    """The model that validates the section at ``path`` of the run config ``raw``."""
    from asmteach.core import registry

    model: type[BaseModel] = RunConfig
    keys = path.split(".") if path else []
    for i, key in enumerate(keys):
        if key == "settings":
            model = registry.get_class(ROLE_OF_KEY[keys[i - 1]], raw[keys[i - 1]]["plugin"]).Settings
        elif key == "demo":
            model = registry.get_class("teachers", raw["teacher"]["plugin"]).DemoSettings
        elif keys[i + 1 : i + 2] != ["settings"]:
            field = model.model_fields[key]
            model = nested_model(field.annotation)
        else:
            model = PluginChoice
    return model


def _misspelt(model: type[BaseModel]) -> str:
    """One of ``model``'s keys with its last two letters swapped (``height`` -> ``heigth``)."""
    name = next(n for n in model.model_fields if len(n) > 2 and n[-1] != n[-2])
    return name[:-2] + name[-1] + name[-2]


def test_every_section_of_the_run_config_is_in_the_list() -> None:
    """A new section of RunConfig gets a misspelt-key case: each model-typed key is listed."""
    nested = {key for key, kind, _, _ in describe_settings(RunConfig) if nested_model(_annotation(key))}
    assert nested <= set(SECTIONS), nested - set(SECTIONS)


def _annotation(dotted: str) -> object:
    model: type[BaseModel] | None = RunConfig
    ann: object = None
    for key in dotted.split("."):
        ann = model.model_fields[key].annotation if model is not None else None
        model = nested_model(ann)
    return ann


@pytest.mark.parametrize("section", SECTIONS, ids=[s or "top" for s in SECTIONS])
def test_a_misspelt_key_in_any_section_exits_2_naming_its_path(section, tmp_path, capsys) -> None:
    raw = yaml.safe_load(DEMO.read_text())
    raw["structure"] = str(DEMO.parent / raw["structure"])
    key = _misspelt(_section_model(raw, section))
    dotted = f"{section}.{key}" if section else key
    set_dotted(raw, dotted, 1)
    bad = tmp_path / "typo.yaml"
    bad.write_text(yaml.safe_dump(raw))
    assert main(["validate", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{dotted}: unknown key" in err and "Traceback" not in err and err.count("\n") == 1


def test_every_setting_of_the_run_config_is_described() -> None:
    """``plugins --settings`` shows a description for each key of the run config's own sections."""
    undescribed = [key for key, _, _, text in describe_settings(RunConfig) if not text]
    assert not undescribed, undescribed


def test_check_overrides_names_a_misspelt_key_in_any_section() -> None:
    check_overrides({"execution.animation": False, "robot.settings.start_tolerance": 0.1})
    for key in ("execution.animaton", "robot.settings.start_tolerence", "table.hieght", "demo.framez"):
        with pytest.raises(UserError, match=rf"^params\.overrides: {re.escape(key)}: unknown key"):
            check_overrides({key: 1})


PEG = REPO / "configs/parts/set1/peg_in_hole.yaml"
EXPERIMENT_TYPOS = [
    (f"experiment: end_to_end\nparams: {{run_config: {DEMO}, overrides: {{execution.animaton: false}}}}\n",
     "execution.animaton: unknown key"),
    ("experiment: structures_corpus\nparams: {family: hex_peg, overrides: {execution.animaton: false}}\n",
     "params.overrides: execution.animaton: unknown key"),
    (f"experiment: teaching_precision\nparams: {{structure: {PEG}, demo: {{framez: 3}}}}\n",
     "params.demo.framez: unknown key"),
    (f"experiment: teaching_breakdown\nparams: {{structure: {PEG}, teacher: {{min_frame: 3}}}}\n",
     "params.teacher.min_frame: unknown key"),
    (f"experiment: detection_precision\nparams: {{parts: [{{structure: {PEG}, placements: [0]}}], "
     "detector_settings: {refine: {icp_iteration: 3}}}\n", "params.detector_settings.refine.icp_iteration: unknown"),
    ("experiment: detection_precision\nparams: {parts: [{structure: x.yaml, placements: [0]}], corrector: stable}\n",
     "params.corrector: no corrector plugin named 'stable'"),
    ("experiment: grasp_hold\nparams: {part: round_peg, planner: {samples: 10, muu: 0.5}}\n",
     "params.planner.muu: unknown key"),
    ("experiment: reachability\nparams: {robot_settings: {table_hieght: 0.1}}\n",
     "params.robot_settings.table_hieght: unknown key"),
    (f"experiment: assembly_planning\nparams: {{structure: {PEG}, motion_settings: {{rang: 0.1}}}}\n",
     "params.motion_settings.rang: unknown key"),
]  # fmt: skip


@pytest.mark.parametrize("experiment, says", EXPERIMENT_TYPOS, ids=[e[0].split()[1] for e in EXPERIMENT_TYPOS])
def test_validate_checks_the_run_settings_an_experiment_carries(experiment, says, tmp_path, capsys) -> None:
    """Settings an experiment hands to a run or a plugin later (dicts in its params) are checked up front."""
    path = tmp_path / "exp.yaml"
    path.write_text(experiment)
    assert main(["validate", str(path)]) == 2
    assert says in capsys.readouterr().err
