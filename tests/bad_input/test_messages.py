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
