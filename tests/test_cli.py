"""The harpx command: subcommands, help, exit codes and one-line errors."""

from __future__ import annotations

import pytest

from harpx.cli import main


@pytest.mark.parametrize("command", ["demo", "phase", "track", "report"])
def test_every_subcommand_has_help(command, capsys):
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    assert "usage: harpx" in capsys.readouterr().out


def test_usage_error_exits_2(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["frobnicate"])
    assert exc.value.code == 2


def test_missing_archive_is_one_clear_line(tmp_path, capsys):
    code = main(["report", str(tmp_path / "missing.nc")])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert len(err.splitlines()) == 1 and "missing.nc" in err and err.startswith("harpx report: error:")


def test_demo_small_writes_archives_figures_and_table(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--size", "small", "--output", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "| conventional HARP |" in text and "| FE penalty hex8" in text
    for name in ("phantom_hex8.nc", "phantom_harp.nc", "phantom_displacement_maps.png", "phantom_error_vs_runtime.png"):
        assert (out / name).stat().st_size > 0, name
    # the archive it wrote is a valid tracked/1 result with the same diagnostics
    assert main(["report", str(out / "phantom_hex8.nc")]) == 0
    assert "epsilon" in capsys.readouterr().out
