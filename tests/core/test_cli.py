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
