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
    assert (
        len(err.splitlines()) == 1
        and "missing.nc" in err
        and err.startswith("harpx report: error:")
    )


def test_demo_small_writes_archives_figures_and_table(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", "--size", "small", "--output", str(out), "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "| conventional HARP |" in text and "| FE penalty hex8" in text
    for name in (
        "phantom_hex8.nc",
        "phantom_harp.nc",
        "phantom_displacement_maps.png",
        "phantom_error_vs_runtime.png",
    ):
        assert (out / name).stat().st_size > 0, name
    # the archive it wrote is a valid tracked/1 result with the same diagnostics
    figure = tmp_path / "map.png"
    assert main(["report", str(out / "phantom_hex8.nc"), "--figure", str(figure)]) == 0
    assert "epsilon" in capsys.readouterr().out
    assert figure.stat().st_size > 0


def test_dicom_subcommand_writes_a_tagged_archive(tmp_path, capsys):
    from harpx.io.netcdf import open_dataset
    from tests.io.test_dicom import SA, write_classic

    write_classic(tmp_path / "sa", SA)
    out = tmp_path / "tagged.nc"
    code = main(
        [
            "dicom",
            str(tmp_path / "sa"),
            str(out),
            "--tag",
            f"{SA.uid}:x:row",
            "--tag",
            f"{SA.uid}:y:column",
            "--tag-period",
            "8",
            "--sequence",
            "CSPAMM",
        ]
    )
    assert code == 0, capsys.readouterr().err
    ds = open_dataset(out)
    assert ds.attrs["harpx_schema"] == "tagged/1" and list(ds.tag.values) == ["x", "y"]


def test_dicom_subcommand_bad_tag_is_one_line(tmp_path, capsys):
    code = main(
        ["dicom", str(tmp_path), str(tmp_path / "o.nc"), "--tag", "nonsense", "--tag-period", "8"]
    )
    err = capsys.readouterr().err.strip()
    assert code == 1 and "SERIES:LABEL:DIRECTION" in err and len(err.splitlines()) == 1
