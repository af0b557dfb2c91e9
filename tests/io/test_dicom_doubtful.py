"""Doubtful DICOM input: repeated acquisitions, mixed or odd clocks, inconsistent rescaling
and slice thickness, and the CLI's --time-tolerance.

The synthetic series of tests.io.test_dicom are edited header by header, so every expected
time, value and file name follows from the construction.
"""

from __future__ import annotations

from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest

pydicom = pytest.importorskip("pydicom")

from harpx.cli import main  # noqa: E402
from harpx.errors import HarpxError, HarpxWarning  # noqa: E402
from harpx.io.dicom import read_tagged  # noqa: E402
from tests.io.test_dicom import (  # noqa: E402
    INTERCEPT,
    LA,
    SA,
    SLOPE,
    StackSpec,
    ds_str,
    edit_attribute,
    write_classic,
    write_enhanced,
)

SA_X = {"tag_period": 8.0, "tag_directions": {"SA tagged": ("x", "row")}, "sequence": "CSPAMM"}
LA_L = {"tag_period": 8.0, "tag_directions": {"LA tagged": ("l", "row")}, "sequence": "SPAMM"}


# --- 1. repeated acquisitions and irregular frame intervals ----------------------------------


def _repeat(folder: Path, shift: float) -> None:
    """SA, and a second acquisition of it in the same series ``shift`` ms later."""
    write_classic(folder / "a", SA)

    def later(ds, k, t):
        ds.TriggerTime = ds_str(SA.times[t] + shift)

    write_classic(folder / "b", SA, edit=later)  # other file names: other SOPInstanceUIDs


def test_repeat_within_time_tolerance_is_a_duplicate(tmp_path: Path) -> None:
    _repeat(tmp_path, 0.5)
    match = r"two images at the same slice position 0\.5 ms apart \(TriggerTime 0 and 0\.5 ms"
    with pytest.raises(HarpxError, match=match + r"(.|\n)*separate series"):
        read_tagged(tmp_path, **SA_X)


def test_interleaved_repeat_beyond_tolerance_warns_irregular_intervals(tmp_path: Path) -> None:
    # With time_tolerance below the 0.5 ms offset the images are distinct frames: the times
    # alternate 0.5 and 39.5 ms apart, which the result must flag.
    _repeat(tmp_path, 0.5)
    with pytest.warns(
        HarpxWarning, match=r"irregular: 39\.5 ms between frames 1 and 2 .* median of 0\.5 ms"
    ):
        ds = read_tagged(tmp_path, **SA_X, time_tolerance=0.2)
    np.testing.assert_allclose(ds.time, [0.0, 0.5, 40.0, 40.5, 80.0, 80.5], atol=1e-9)
    assert "irregular frame intervals (0.5 to 39.5 ms)" in ds.attrs["dicom_caveats"]


def test_missing_frame_warns_irregular_intervals(tmp_path: Path) -> None:
    spec = StackSpec(**{**SA.__dict__, "times": (0.0, 40.0, 80.0, 160.0)})  # 120 missing
    write_classic(tmp_path, spec)
    with pytest.warns(HarpxWarning, match=r"80 ms between frames 2 and 3 .* median of 40 ms"):
        ds = read_tagged(tmp_path, **SA_X)
    assert "irregular frame intervals (40 to 80 ms)" in ds.attrs["dicom_caveats"]


def test_regular_frames_have_no_caveat(tmp_path: Path) -> None:
    write_classic(tmp_path, LA)  # intervals 40.1 and 39.2 ms: regular within 25 %
    ds = read_tagged(tmp_path, **LA_L)
    assert ds.attrs["dicom_caveats"] == ""


# --- 2. enhanced multi-frame: a frame without a trigger delay ---------------------------------


def test_one_frame_without_trigger_delay_is_named(tmp_path: Path) -> None:
    path = write_enhanced(tmp_path, LA)
    ds = pydicom.dcmread(path)
    for index, item in enumerate(ds.PerFrameFunctionalGroupsSequence):
        # an acquisition clock a heartbeat (900 ms) per frame: not the trigger delay
        stamp = datetime(2024, 6, 11, 12) + timedelta(milliseconds=900 * index)
        item.FrameContentSequence[0].FrameAcquisitionDateTime = stamp.strftime("%Y%m%d%H%M%S.%f")
    del ds.PerFrameFunctionalGroupsSequence[3].CardiacSynchronizationSequence
    ds.save_as(path)
    match = rf"{path.name} \(frame 4\) has no readable NominalCardiacTriggerDelayTime but other"
    with pytest.raises(HarpxError, match=match + r" frames of the file have one \(1 of 6"):
        read_tagged(tmp_path, **LA_L)


def test_files_mixing_delays_and_acquisition_times_are_refused(tmp_path: Path) -> None:
    write_enhanced(tmp_path / "a", LA, timing="datetime")
    second = StackSpec(**{**LA.__dict__, "offsets": (12.0, 18.0)})  # further slices
    path = write_enhanced(tmp_path / "b", second)
    with pytest.raises(HarpxError, match=rf"mixes clocks(.|\n)*{path.name} \(frame 1\) has a"):
        read_tagged(tmp_path, **LA_L)


# --- 3. rescaling ----------------------------------------------------------------------------


def _edit_one(keyword: str, value: str | None):
    """Set (or delete, for None) ``keyword`` in the file of slice 1, frame 2 only."""
    return edit_attribute(keyword, value, where=lambda k, t: (k, t) == (1, 2))


@pytest.mark.parametrize(
    ("keyword", "value", "match"),
    [
        ("RescaleSlope", "0", r"'RescaleSlope' of .*{name} is '0': a zero slope"),
        ("RescaleIntercept", None, r"'RescaleIntercept' is missing in .*{name} but present"),
        ("RescaleSlope", None, r"'RescaleSlope' is missing in .*{name} but present in"),
    ],
)
def test_bad_rescale_is_named(tmp_path: Path, keyword: str, value, match: str) -> None:
    written = write_classic(tmp_path, SA, edit=_edit_one(keyword, value))
    victim = next(p for p, kt in written.items() if kt == (1, 2))
    with pytest.raises(HarpxError, match=match.format(name=victim.name)):
        read_tagged(tmp_path, **SA_X)


def test_unreadable_rescale_slope_is_named(tmp_path: Path) -> None:
    written = write_classic(tmp_path, SA, edit=_edit_one("RescaleSlope", "77777777"))
    victim = next(p for p, kt in written.items() if kt == (1, 2))
    victim.write_bytes(victim.read_bytes().replace(b"77777777", b"abc     "))  # not a DS
    match = rf"'RescaleSlope' of .*{victim.name} is 'abc', which is not a finite number"
    with pytest.raises(HarpxError, match=match):
        read_tagged(tmp_path, **SA_X)


def test_series_without_any_rescale_reads_stored_values(tmp_path: Path) -> None:
    def bare(ds, k, t):
        del ds.RescaleSlope, ds.RescaleIntercept

    write_classic(tmp_path / "with", SA)
    write_classic(tmp_path / "bare", SA, edit=bare)
    scaled = read_tagged(tmp_path / "with", **SA_X)
    stored = read_tagged(tmp_path / "bare", **SA_X)
    inside = np.broadcast_to(scaled.mask.values[:, None], scaled.image.shape)
    assert inside.sum() > 100
    # resampling is linear in the values, so undoing the rescale of one gives the other
    expected = (scaled.image.values - INTERCEPT) / SLOPE
    np.testing.assert_allclose(stored.image.values[inside], expected[inside], rtol=1e-12, atol=1e-7)


# --- 4. TriggerTime in seconds ---------------------------------------------------------------


def test_trigger_time_in_seconds_warns(tmp_path: Path) -> None:
    write_classic(tmp_path, StackSpec(**{**SA.__dict__, "times": (0.0, 0.04, 0.08)}))
    with pytest.warns(HarpxWarning, match=r"0\.04 ms apart on average .* most likely in seconds"):
        ds = read_tagged(tmp_path, **SA_X)
    np.testing.assert_allclose(ds.time, [0.0, 0.04, 0.08], atol=1e-12)  # kept as read
    assert "mean frame interval 0.04 ms (TriggerTime in s?)" in ds.attrs["dicom_caveats"]


# --- 5. SliceThickness -----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("8", r"SliceThickness differs within .* 5 mm in .* but 8 mm in .*{name}"),
        (None, r"'SliceThickness' is missing or unreadable in .*{name} but is 5 mm in"),
    ],
)
def test_slice_thickness_must_agree(tmp_path: Path, value: str | None, match: str) -> None:
    written = write_classic(tmp_path, SA, edit=_edit_one("SliceThickness", value))
    victim = next(p for p, kt in written.items() if kt == (1, 2))
    with pytest.raises(HarpxError, match=match.format(name=victim.name)):
        read_tagged(tmp_path, **SA_X)


def test_slice_thickness_rounding_is_tolerated(tmp_path: Path) -> None:
    write_classic(tmp_path, SA, edit=_edit_one("SliceThickness", "5.0000004"))
    ds = read_tagged(tmp_path, **SA_X)
    assert float(ds.slice_thickness.sel(tag="x")) == 5.0  # the first image's value


# --- 6. CLI --time-tolerance -----------------------------------------------------------------


def test_cli_time_tolerance(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from harpx.io.netcdf import open_dataset

    def late(ds, k, t):
        if (k, t) == (2, 1):
            ds.TriggerTime = ds_str(42.0)  # 2 ms off the other slices

    write_classic(tmp_path / "sa", SA, edit=late)
    argv = ["dicom", str(tmp_path / "sa"), str(tmp_path / "o.nc"), "--tag", "SA tagged:x:row"]
    argv += ["--tag-period", "8", "--sequence", "CSPAMM"]
    assert main(argv) == 1  # the library's default (1 ms) applies
    assert "time_tolerance=1 ms" in capsys.readouterr().err
    assert main([*argv, "--time-tolerance", "3"]) == 0, capsys.readouterr().err
    time = open_dataset(tmp_path / "o.nc").time.values
    np.testing.assert_allclose(time, [0.0, (40 + 40 + 42) / 3, 80.0], atol=1e-9)
