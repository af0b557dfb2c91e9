"""Messages that used to point at the wrong cause now name the real one."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from harpx.errors import ArchiveError, SchemaError
from harpx.io.netcdf import open_dataset
from harpx.schema import standard_attrs, validate
from tests.test_schema import make_tagged


def test_grid_in_metres_labelled_mm_is_named_not_a_radius_hint() -> None:
    ds = make_tagged()
    coords = {d: (d, ds[d].values / 1000.0, standard_attrs(d)) for d in ("x", "y", "z")}
    f = ("tag", ds.tag_frequency.values * 1000.0, standard_attrs("tag_frequency"))
    ds = ds.assign_coords({**coords, "tag_frequency": f})
    with pytest.raises(SchemaError, match=r"coordinate 'z' has a spacing of 0.004 mm.*in metres"):
        validate(ds)
    assert np.isclose(ds.x.values[1] - ds.x.values[0], 0.002)


def test_directory_passed_to_open_dataset_is_named(tmp_path: Path) -> None:
    with pytest.raises(ArchiveError, match=r"cannot open '.*': it is a directory; pass one \.nc"):
        open_dataset(tmp_path)


def _track(ds) -> None:
    from harpx.mechanics.body import Body
    from harpx.mechanics.materials import NeoHookean
    from harpx.mechanics.mesh import box
    from harpx.tracking.track import track

    body = Body(box((4.0, 4.0, 2.0), (1, 1, 1), origin=(4.0, 4.0, 1.0)), NeoHookean(1, 120))
    track(ds, body, progress=False)


def test_swapped_tag_directions_are_named() -> None:
    from tests.test_schema import make_phase

    ds = make_phase()
    swapped = ds.tag_direction.values[::-1]
    ds = ds.assign_coords(tag_direction=(("tag", "axis"), swapped, ds.tag_direction.attrs))
    with pytest.raises(SchemaError, match=r"tag 'x' has tag_direction \[0.0, 1.0, 0.0\] but its "):
        _track(ds)  # before: tracked without a word


def test_all_false_mask_is_named_not_an_overlap_hint() -> None:
    from tests.test_schema import make_phase

    ds = make_phase()
    ds["mask"] = ds["mask"] & False
    with pytest.raises(SchemaError, match=r"'mask' of tag 'x' is all False"):
        _track(ds)


def test_frame_0_without_tag_pattern_is_named_not_an_overlap_hint() -> None:
    from tests.test_schema import make_phase

    ds = make_phase()
    ds["magnitude"] = ds["magnitude"] * 0.0
    match = (
        r"frame 0 of tag 'x' has no tag pattern \(harmonic magnitude max 0\): its image is blank"
    )
    with pytest.raises(SchemaError, match=match):
        _track(ds)


@pytest.mark.parametrize("value", [5.0, 0.0], ids=["constant", "zero"])
def test_constant_frame_is_called_constant_with_its_value(value: float) -> None:
    # before: a constant image was reported as "all zero (magnitude max 0)", drop it
    from harpx.errors import HarpxWarning
    from harpx.imaging.harp import extract_phase

    ds = make_tagged(nt=3)
    ds["image"][:, 1] = value
    blank = ": a blank frame" if value == 0 else ""
    match = (
        rf"constant images: tag 'x' frame\(s\) \[1\] \(every voxel in its mask is {value:g}"
        rf"{blank}\); tag 'y' frame\(s\) \[1\] .*drop them \(ds.drop_isel\(time=\[1\]\)\)"
    )
    with pytest.warns(HarpxWarning, match=match):
        extract_phase(ds, upsample=1)
    with (
        pytest.warns(HarpxWarning) as caught,
        pytest.raises(
            SchemaError, match=r"frame 1 .*no valid phase.*no tag pattern.*blank or constant"
        ),
    ):
        _track(ds)  # a tagged dataset: extract_phase warns first, the tracker then refuses
    assert any(str(w.message).startswith("constant images: tag 'x'") for w in caught)


def test_points_outside_the_field_of_view_are_named_with_both_extents() -> None:
    from harpx.imaging.coverage import explain_missing_data
    from tests.test_schema import make_phase

    text = explain_missing_data(make_phase(), [[500.0, 5.0, 2.0]])
    assert text.startswith("no point lies inside the field of view (x, y, z from [0.0, 0.0,")
    assert "the points span [500.0, 5.0, 2.0]" in text


def test_archive_of_a_newer_schema_version_says_upgrade_harpx(tmp_path: Path) -> None:
    # before: "'tracked/2'; known schemas: [...]", as if the file were wrong
    import netCDF4

    from harpx.errors import HarpxWarning
    from harpx.imaging.harptrack import track_harp
    from tests.test_schema import make_phase, make_tracked

    newer = r"'tracked/2' is a newer version of the tracked schema than .* reads \('tracked/1'\)"
    upgrade = r".*upgrade harpx \(pip install --upgrade harpx\)"
    ds = make_tracked()
    ds.attrs["harpx_schema"] = "tracked/2"
    with pytest.raises(SchemaError, match=rf"is 'tracked/2'; {newer}{upgrade}"):
        validate(ds)
    with pytest.raises(SchemaError, match=rf"but 'tracked/1' was expected: {newer}"):
        validate(ds, "tracked")
    path = tmp_path / "new.nc"
    make_tracked().to_netcdf(path)
    with netCDF4.Dataset(path, "a") as nc:
        nc.harpx_schema = "tracked/2"
    with pytest.warns(HarpxWarning, match=rf"archive '.*new\.nc': {newer}{upgrade}"):
        open_dataset(path)
    phase = make_phase()
    phase.attrs["harpx_schema"] = "phase/7"
    with pytest.raises(SchemaError, match=r"is 'phase/7': 'phase/7' is a newer version"):
        track_harp(phase)
    phase.attrs["harpx_schema"] = "phase/1x"  # not a version: the list of known schemas
    with pytest.raises(SchemaError, match=r"is 'phase/1x'; known schemas: \['phase/1'"):
        validate(phase)


def test_points_the_tissue_moved_away_from_are_named_not_an_overlap_hint() -> None:
    # before: "check that the mesh (mm) and the image grid (coords x, y, z) overlap", while
    # they did: the tissue had moved a whole tag period, and the tracked body stayed behind
    from harpx.imaging.coverage import explain_missing_data
    from tests.test_schema import make_phase

    ds = make_phase()  # x, y from 0 to 16 mm
    magnitude = ds["magnitude"].values.copy()
    magnitude[:, 1] = np.where(ds.x.values >= 10.0, 1.0, 0.001)  # frame 1: tissue at x > 10
    ds["magnitude"] = ds["magnitude"].copy(data=magnitude)
    points = [[3.0, 5.0, 2.0], [5.0, 9.0, 2.0], [7.0, 3.0, 2.0]]
    text = explain_missing_data(ds, points, time_index=1)
    assert text.startswith(
        "the points lie inside the field of view and the masks but where frame 1 has no "
        "tissue signal (only 0.0 % of them"
    )
    assert "the tissue has moved away from the tracked body" in text
    assert explain_missing_data(ds, points, time_index=0).startswith("check that the mesh")
