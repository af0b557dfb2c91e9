"""NaN and inf never pass: not in time, not in tracked displacement, not in one image block."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from harpx.errors import SchemaError
from harpx.io.mesh import to_meshio
from harpx.io.netcdf import to_netcdf
from harpx.schema import validate
from tests.test_schema import make_tagged, make_tracked


@pytest.mark.parametrize("value", [np.nan, np.inf], ids=["nan", "inf"])
def test_non_finite_time_is_refused_and_never_written(value: float, tmp_path: Path) -> None:
    ds = make_tagged()
    ds = ds.assign_coords(time=("time", [0.0, value], ds.time.attrs))
    match = r"coordinate 'time' has 1 non-finite values \(NaN/inf\) at indices \[1\]"
    with pytest.raises(SchemaError, match=match):
        validate(ds)
    with pytest.raises(SchemaError, match=match):
        to_netcdf(ds, tmp_path / "a.nc")
    assert list(tmp_path.iterdir()) == []


def test_nan_in_tracked_displacement_is_refused_written_nor_exported(tmp_path: Path) -> None:
    ds = make_tracked()
    ds["displacement"][1, 3, 2] = np.nan
    match = r"'displacement' has 1 non-finite values .*first at index \{time=1, node=3, axis=2\}"
    with pytest.raises(SchemaError, match=match):
        validate(ds)
    with pytest.raises(SchemaError, match=match):
        to_netcdf(ds, tmp_path / "a.nc")
    with pytest.raises(SchemaError, match=match):
        to_meshio(ds, tmp_path / "a.xdmf")
    assert list(tmp_path.iterdir()) == []


def test_nan_tag_frequency_is_named_as_a_number() -> None:
    ds = make_tagged()
    ds = ds.assign_coords(tag_frequency=("tag", [np.nan, 0.125], ds.tag_frequency.attrs))
    with pytest.raises(SchemaError, match=r"tag_frequency of tag 'x' is nan; expected a positive"):
        validate(ds)


@pytest.mark.parametrize("order", [1, 3], ids=["linear", "cubic"])
def test_one_nan_block_of_a_lazy_phase_leaves_the_rest_valid(order: int) -> None:
    # before: the 99th-percentile magnitude floor became NaN and every point was invalid
    from harpx.imaging.sample import PhaseSampler
    from tests.test_schema import make_phase

    ds = make_phase()
    for name in ("phase", "magnitude"):
        values = ds[name].values.copy()
        values[:, :, :, :2, :2] = np.nan  # a 2 x 2 voxel corner of every slice (6 % of it)
        ds[name] = ds[name].copy(data=values)
    ds = ds.chunk({"time": 1})  # lazily loaded, as open_dataset(path, chunks={}) gives it
    sampler = PhaseSampler(ds, 0, order=order)
    far = np.array([[9.0, 9.0, 2.0], [13.0, 5.0, 2.0]])  # x, y, z mm, away from the block
    near = np.array([[1.0, 1.0, 2.0]])  # inside the NaN block
    _, _, valid = sampler.sample(np.vstack([far, near]))
    assert valid.tolist() == [True, True, False]


@pytest.mark.parametrize("value", [np.nan, np.inf], ids=["nan", "inf"])
def test_non_finite_harp_points_are_named(value: float) -> None:
    # before: tracked as "no data", NaN in every frame, and points_lost said 0
    from harpx.imaging.harptrack import track_harp
    from tests.test_schema import make_phase

    points = [[5.0, 5.0, 0.0], [5.0, value, 0.0], [7.0, 7.0, 0.0]]
    with pytest.raises(ValueError, match=r"points has 1 rows with NaN or inf \(rows \[1\]\)"):
        track_harp(make_phase(), points=points)
