"""Config validation: each error is one line with the key path and the reason."""

import textwrap

import pytest

from asmteach.core.cli import main
from asmteach.core.config import load_run_config
from asmteach.core.errors import UserError


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
