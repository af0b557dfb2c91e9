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


def test_all_zero_frame_0_is_named_not_an_overlap_hint() -> None:
    from tests.test_schema import make_phase

    ds = make_phase()
    ds["magnitude"] = ds["magnitude"] * 0.0
    with pytest.raises(SchemaError, match=r"frame 0 of tag 'x' is all zero \(magnitude max 0\)"):
        _track(ds)


def test_points_outside_the_field_of_view_are_named_with_both_extents() -> None:
    from harpx.imaging.coverage import explain_missing_data
    from tests.test_schema import make_phase

    text = explain_missing_data(make_phase(), [[500.0, 5.0, 2.0]])
    assert text.startswith("no point lies inside the field of view (x, y, z from [0.0, 0.0,")
    assert "the points span [500.0, 5.0, 2.0]" in text
