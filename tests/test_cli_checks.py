"""The harpx command checks its output before the work and prints every schema problem."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from harpx.cli import main
from tests.test_schema import make_tagged


@pytest.fixture
def no_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every step that reads or computes fails the test: the output must be refused first."""

    def work(*args: object, **kwargs: object) -> None:
        raise AssertionError("work started before the output was checked")

    for module, name in [
        ("harpx.io.netcdf", "open_dataset"),
        ("harpx.io.mesh", "read_body"),
        ("harpx.io.dicom", "read_tagged"),
        ("harpx.imaging.harp", "extract_phase"),
        ("harpx.scenes.phantom", "phantom"),  # the module (its package exports the function)
    ]:
        monkeypatch.setattr(importlib.import_module(module), name, work)


def _commands(tmp_path: Path) -> dict[str, list[str]]:
    missing = str(tmp_path / "no-such-folder" / "out.nc")
    return {
        "phase": ["phase", str(tmp_path / "in.nc"), missing],
        "track": ["track", str(tmp_path / "in.nc"), missing, "--mesh", str(tmp_path / "m.vtu")],
        "dicom": ["dicom", str(tmp_path), missing, "--tag", "SA:x:row", "--tag-period", "8"],
    }


@pytest.mark.parametrize("command", ["phase", "track", "dicom"])
def test_missing_output_folder_is_refused_before_any_work(
    command: str, tmp_path: Path, no_work: None, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(_commands(tmp_path)[command])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert err == (
        f"harpx {command}: error: cannot write '{tmp_path}/no-such-folder/out.nc': directory "
        f"'{tmp_path}/no-such-folder' does not exist; create it first"
    )


def test_demo_refuses_an_archive_path_that_is_a_folder_before_any_work(
    tmp_path: Path, no_work: None, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "phantom_hex8.nc").mkdir()
    code = main(["demo", "--size", "small", "--output", str(tmp_path), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert code == 1
    assert err.startswith(f"harpx demo: error: refusing to write '{tmp_path}/phantom_hex8.nc'")
    assert "it is a directory" in err


def test_output_equal_to_input_is_still_named_as_such(
    tmp_path: Path, no_work: None, capsys: pytest.CaptureFixture[str]
) -> None:
    source = tmp_path / "in.nc"
    source.write_bytes(b"")
    assert main(["phase", str(source), str(source)]) == 1
    assert "is the input" in capsys.readouterr().err


def test_every_schema_problem_is_printed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = make_tagged()
    del bad["image"].attrs["long_name"]
    bad["time"].attrs["units"] = "s"
    bad["tag_frequency"].attrs["units"] = "1/m"
    source = tmp_path / "bad.nc"
    bad.to_netcdf(source, engine="netcdf4")  # plain xarray: harpx would refuse to write it
    code = main(["phase", str(source), str(tmp_path / "phase.nc")])
    lines = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert lines[0] == "harpx phase: error: 3 schema problems:"
    assert [line[:4] for line in lines[1:]] == ["  - "] * 3
    text = "\n".join(lines)
    for problem in ("'image' has no 'long_name'", "'time' has units 's'", "'1/m'"):
        assert text.count(problem) == 1, problem
    assert not (tmp_path / "phase.nc").exists()
