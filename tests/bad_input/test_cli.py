"""The command line: every failure is one line and a non-zero exit code, inputs are never
overwritten, and an interrupted run leaves nothing behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harpx.cli import main
from harpx.io.netcdf import to_netcdf
from tests.test_schema import make_phase, make_tagged


def _one_error_line(capsys: pytest.CaptureFixture[str], command: str, match: str) -> None:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    assert err.startswith(f"harpx {command}: error: "), err
    assert match in err, err


def test_phase_onto_its_own_input_is_refused_and_the_input_kept(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = to_netcdf(make_tagged(), tmp_path / "a.nc")
    before = source.read_bytes()
    assert main(["phase", str(source), str(source)]) == 1
    _one_error_line(capsys, "phase", "is the input")
    assert source.read_bytes() == before
    # the same file by another spelling
    assert main(["phase", str(source), str(tmp_path / "." / "a.nc")]) == 1
    assert source.read_bytes() == before


def test_report_of_a_tagged_archive_is_an_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    source = to_netcdf(make_tagged(), tmp_path / "a.nc")
    assert main(["report", str(source)]) == 1
    _one_error_line(capsys, "report", "is a 'tagged/1' archive; report needs a 'tracked/1' archive")


@pytest.mark.parametrize(
    ("content", "match"),
    [
        pytest.param("garbage", "cannot read mesh", id="garbage-mesh"),
        pytest.param(None, "no such file", id="missing-mesh"),
    ],
)
def test_track_with_a_bad_mesh_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | None, match: str
) -> None:
    source = to_netcdf(make_phase(), tmp_path / "p.nc")
    mesh = tmp_path / "m.vtu"
    if content is not None:
        mesh.write_text(content)
    code = main(["track", str(source), str(tmp_path / "t.nc"), "--mesh", str(mesh)])
    assert code == 1
    _one_error_line(capsys, "track", match)
    assert not (tmp_path / "t.nc").exists()


def test_an_unexpected_error_is_one_line_naming_its_type(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    def boom(*args: object, **kwargs: object) -> None:
        raise KeyError("phase")

    monkeypatch.setattr("harpx.imaging.harp.extract_phase", boom)
    source = to_netcdf(make_tagged(), tmp_path / "a.nc")
    assert main(["phase", str(source), str(tmp_path / "b.nc")]) == 1
    _one_error_line(capsys, "phase", "KeyError: 'phase'")


_SLOW_PHASE = """
import sys, time
import harpx.imaging.harp as harp
real = harp.extract_phase
def slow(*args, **kwargs):
    out = real(*args, **kwargs)
    print("computed", flush=True)
    time.sleep(30)
    return out
harp.extract_phase = slow
from harpx.cli import main
sys.exit(main(sys.argv[1:]))
"""


def test_sigterm_exits_143_with_one_line_and_no_output(tmp_path: Path) -> None:
    source = to_netcdf(make_tagged(), tmp_path / "a.nc")
    child = subprocess.Popen(
        [sys.executable, "-c", _SLOW_PHASE, "phase", str(source), str(tmp_path / "b.nc")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).parents[2],
    )
    assert child.stdout is not None and child.stdout.readline().strip() == "computed"
    time.sleep(0.2)
    os.kill(child.pid, signal.SIGTERM)
    _, err = child.communicate(timeout=30)
    assert child.returncode == 143, err
    assert err.strip() == "harpx phase: terminated; no partial output was written"
    assert sorted(os.listdir(tmp_path)) == ["a.nc"]


def test_dicom_without_tag_in_a_folder_without_dicom_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "notes.txt").write_text("not DICOM")
    assert main(["dicom", str(tmp_path), str(tmp_path / "o.nc")]) == 1
    _one_error_line(capsys, "dicom", "no DICOM images found")  # nothing to list


def test_warnings_of_a_failing_run_come_before_its_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    import warnings

    from harpx.errors import HarpxWarning

    def warn_then(fail: bool):
        def phase(*args: object, **kwargs: object) -> object:
            warnings.warn("tag 'x' looks odd\nsecond line", HarpxWarning, stacklevel=2)
            if fail:
                raise ValueError("bad phase")
            return make_phase()

        return phase

    source = to_netcdf(make_tagged(), tmp_path / "a.nc")
    monkeypatch.setattr("harpx.imaging.harp.extract_phase", warn_then(True))
    assert main(["phase", str(source), str(tmp_path / "b.nc")]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err[:2] == ["harpx phase: warning: tag 'x' looks odd", "second line"]
    assert err[2:] == ["harpx phase: error: bad phase"]
    monkeypatch.setattr("harpx.imaging.harp.extract_phase", warn_then(False))
    assert main(["phase", str(source), str(tmp_path / "b.nc")]) == 0
    captured = capsys.readouterr()
    assert captured.err.startswith("harpx phase: warning: tag 'x' looks odd")
    assert captured.out.strip() == f"wrote {tmp_path / 'b.nc'}"
