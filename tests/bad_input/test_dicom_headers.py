"""DICOM headers that used to give LinAlgError, a wrong geometry or a misleading message."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

pytest.importorskip("pydicom")

from harpx.errors import HarpxError, HarpxWarning  # noqa: E402
from harpx.io.dicom import read_tagged  # noqa: E402
from tests.io.test_dicom import (  # noqa: E402
    READ,
    SA,
    StackSpec,
    edit_attribute,
    write_classic,
)

SA_ONLY = {**READ, "tag_directions": {"SA tagged": ("x", "row")}}
FIVE = StackSpec(**{**SA.__dict__, "offsets": (0.0, 5.0, 10.0, 15.0, 20.0)})


@pytest.mark.parametrize(
    ("name", "value", "match"),
    [
        pytest.param(
            "PixelSpacing", ["0", "1"], r"PixelSpacing of .* is \[0.0, 1.0\] mm", id="zero-spacing"
        ),
        pytest.param(
            "ImageOrientationPatient",
            ["0"] * 6,
            r"must be unit vectors at right angles",
            id="zero-cosines",
        ),
        pytest.param(
            "ImageOrientationPatient",
            ["1", "0", "0", "1", "0", "0"],
            r"dot product 1",
            id="parallel-cosines",
        ),
        pytest.param(
            "ImageOrientationPatient",
            ["2", "0", "0", "0", "2", "0"],
            r"norms \[2.0, 2.0\]",
            id="non-unit-cosines",
        ),
    ],
)
def test_degenerate_geometry_is_named(tmp_path: Path, name: str, value: object, match: str) -> None:
    write_classic(tmp_path, SA, edit=edit_attribute(name, value))
    with pytest.raises(HarpxError, match=match):
        read_tagged(tmp_path, **SA_ONLY)


def test_slice_far_off_the_stack_is_refused(tmp_path: Path) -> None:
    far = StackSpec(**{**SA.__dict__, "offsets": (0.0, 5.0, 10.0, 200.0)})
    write_classic(tmp_path, far)
    with pytest.raises(
        HarpxError, match=r"is 190 mm from its neighbour .*38 times the stack's 5 mm"
    ):
        read_tagged(tmp_path, **SA_ONLY)


def test_missing_middle_slice_warns(tmp_path: Path) -> None:
    write_classic(tmp_path, FIVE)
    for path in tmp_path.glob("*.dcm"):  # drop the slice at 10 mm
        import pydicom

        if float(pydicom.dcmread(path, stop_before_pixels=True).ImagePositionPatient[2]) == 10.0:
            path.unlink()
    with pytest.warns(HarpxWarning, match=r"gap of 10 mm .*2 times its 5 mm slice gap.*missing"):
        ds = read_tagged(tmp_path, **SA_ONLY)
    assert ds.sizes["time"] == 3


def test_regular_stack_does_not_warn(tmp_path: Path) -> None:
    write_classic(tmp_path, FIVE)
    with warnings.catch_warnings():
        warnings.simplefilter("error", HarpxWarning)
        read_tagged(tmp_path, **SA_ONLY)


def test_two_different_images_at_one_position_are_still_a_pair_message(tmp_path: Path) -> None:
    written = write_classic(tmp_path, SA)
    import pydicom

    source = next(p for p, kt in written.items() if kt == (0, 0))
    twin = pydicom.dcmread(source)
    twin.SOPInstanceUID = twin.file_meta.MediaStorageSOPInstanceUID = pydicom.uid.generate_uid()
    twin.save_as(tmp_path / "twin.dcm")
    with pytest.raises(HarpxError, match="two images at the same slice position.*CSPAMM A and B"):
        read_tagged(tmp_path, **SA_ONLY)


def test_missing_series_uid_is_named(tmp_path: Path) -> None:
    write_classic(tmp_path, SA, edit=edit_attribute("SeriesInstanceUID", None))
    with pytest.raises(HarpxError, match=r"9 DICOM images have no SeriesInstanceUID.*add it"):
        read_tagged(tmp_path, **SA_ONLY)


def test_non_numeric_trigger_time_is_named_not_missing(tmp_path: Path) -> None:
    from pydicom.dataelem import DataElement

    def late(ds, k: int, t: int) -> None:
        if (k, t) == (1, 2):  # a text where a decimal string belongs (pydicom refuses DS)
            ds[0x00181060] = DataElement(0x00181060, "LO", "late")

    write_classic(tmp_path, SA, edit=late)
    with pytest.raises(HarpxError, match=r"'TriggerTime' of .* is 'late', which is not a finite"):
        read_tagged(tmp_path, **SA_ONLY)


@pytest.fixture(scope="module")
def sa_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("sa")
    write_classic(folder, SA)
    return folder


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        pytest.param({"spacing": "1"}, r"spacing is '1'; expected a positive", id="spacing"),
        pytest.param(
            {"time_tolerance": float("nan")}, r"time_tolerance is nan; expected a finite", id="nan"
        ),
        pytest.param({"time_tolerance": -1.0}, r"time_tolerance is -1.0; expected", id="negative"),
        pytest.param({"tag_directions": "SA"}, r"tag_directions is the string 'SA'", id="str"),
        pytest.param(
            {"tag_directions": {"SA tagged": "row"}},
            r"tag_directions\['SA tagged'\] is 'row'; expected a \(label, direction\) pair",
            id="direction-str",
        ),
    ],
)
def test_read_tagged_arguments_are_named(sa_folder: Path, kwargs: dict, match: str) -> None:
    # before: a raw TypeError (spacing), no check at all (NaN tolerance: every frame
    # "matched"), or a message about the first character of a string
    with pytest.raises(HarpxError, match=match):
        read_tagged(sa_folder, **{**SA_ONLY, **kwargs})


def test_read_tagged_refuses_a_grid_larger_than_memory_before_allocating(
    sa_folder: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # before: a warning above 2 GiB, then the allocation (83 GiB at spacing=0.01 here)
    import harpx.io.dicom

    monkeypatch.setattr(harpx.io.dicom, "_available_memory", lambda: 2**14)  # 16 KiB
    with pytest.raises(HarpxError, match=r"would need .* GiB .*more than half the memory"):
        read_tagged(sa_folder, spacing=0.5, **SA_ONLY)


def test_read_tagged_and_voxel_positions_name_wrong_types() -> None:
    from harpx.io.dicom import voxel_positions

    with pytest.raises(TypeError, match=r"paths_or_folder must be a folder, a DICOM file"):
        read_tagged(None, **SA_ONLY)  # type: ignore[arg-type]
    with pytest.raises(HarpxError, match=r"paths_or_folder is an empty list"):
        read_tagged([], **SA_ONLY)
    with pytest.raises(TypeError, match=r"needs pydicom datasets .*got 'str': read the file"):
        voxel_positions("a.dcm")
    with pytest.raises(HarpxError, match=r"voxel_positions got no images"):
        voxel_positions([])
