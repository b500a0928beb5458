from asmteach.core.cli import main


def test_validate_ok_exits_zero(toy_config, capsys):
    assert main(["validate", str(toy_config)]) == 0
    assert "ok" in capsys.readouterr().out


def test_missing_config_exits_two(tmp_path, capsys):
    assert main(["validate", str(tmp_path / "none.yaml")]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and "Traceback" not in err


def test_plugins_lists_groups_and_errors(toy_dist, capsys):
    assert main(["plugins"]) == 0
    out = capsys.readouterr().out
    assert "asmteach.detectors" in out and "toy_detector" in out and "toy-asmteach-plugin" in out
    assert "broken_detector" in out and "import error" in out


def test_no_command_prints_help_and_exits_two(capsys):
    assert main([]) == 2
    assert "usage" in capsys.readouterr().out


def test_library_contact_sheet(tmp_path, capsys):
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    out = tmp_path / "sheet.png"
    assert main(["library", str(repo / "configs/parts/set1"), "--out", str(out)]) == 0
    assert out.stat().st_size > 10_000 and out.read_bytes()[:4] == b"\x89PNG"
    assert main(["library", str(tmp_path), "--out", str(out)]) == 2


def test_written_files_are_readable_like_ordinary_files(tmp_path):
    import os

    from asmteach.core.io import write_text

    path = write_text(tmp_path / "a.txt", "x")
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


KNOWN_SETTINGS = {
    "aruco": ["teacher.settings.min_frames", "demo.frames"],
    "cvfh_icp": ["detector.settings.refine.icp_iterations"],
    "fpfh_ransac": ["detector.settings.viewpoint"],
    "stable_placements": ["corrector.settings.min_margin"],
    "antipodal": ["grasp_planner.settings.mu"],
    "trrt": ["motion_planner.settings.collision_resolution"],
    "rrtconnect": ["motion_planner.settings.collision_resolution"],
    "nextage_pybullet": ["robot.settings.table_center"],
    "urdf_arm": ["robot.settings.table_center"],
    "regrasp": ["assembly_planner.settings.retract"],
}
"""A setting every built-in plugin is known to have, as ``plugins --settings`` names it."""


def test_plugins_settings_lists_a_known_setting_of_every_builtin_plugin(capsys):
    from asmteach.core import registry

    builtin = {i.name for i in registry.discover(load=False) if i.distribution == "asmteach"}
    assert builtin == set(KNOWN_SETTINGS)  # a new built-in plugin gets a line here
    assert main(["plugins", "--settings"]) == 0
    lines = capsys.readouterr().out.splitlines()
    rows = {line.split()[0]: line.split() for line in lines if line.startswith("  ")}
    for plugin, keys in KNOWN_SETTINGS.items():
        assert any(line.startswith("asmteach.") and f" {plugin} (" in line for line in lines), plugin
        for key in keys:
            assert key in rows, (plugin, key)
            assert len(rows[key]) >= 3  # key, type, default (and the description when the plugin gives one)
    # the run config's own sections, with units in their descriptions
    assert "execution.scene.x_range" in rows and "metres" in " ".join(rows["table.height"])
    assert rows["execution.animation_fps"][1:3] == ["float", "4.0"]


def test_plugins_settings_of_one_role_and_a_broken_plugin(toy_dist, capsys):
    assert main(["plugins", "--settings", "--role", "detectors"]) == 0
    captured = capsys.readouterr()
    assert ["detector.settings.voxel_size", "float", "0.002", "metres"] in [
        line.split() for line in captured.out.splitlines()
    ]
    assert "broken_detector" in captured.out and "import error" in captured.out
    assert "run config" not in captured.out and "teacher.settings" not in captured.out


def test_every_builtin_setting_is_described() -> None:
    """Each setting (a section's own keys are described by theirs) says what it is, as plugins --settings shows."""
    from asmteach.core import registry
    from asmteach.core.settings_listing import describe_settings

    undescribed = []
    for info in registry.discover():
        if info.distribution != "asmteach":
            continue
        assert info.cls is not None, info.error
        for model in (info.cls.Settings, getattr(info.cls, "DemoSettings", None)):
            rows = describe_settings(model) if model is not None else []
            sections = {key for key, *_ in rows if any(r[0].startswith(key + ".") for r in rows)}
            undescribed += [f"{info.name}: {key}" for key, _, _, text in rows if not text and key not in sections]
    assert not undescribed, undescribed
