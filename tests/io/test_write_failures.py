"""Failed archive writes leave nothing behind; attributes netCDF cannot hold as such."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import dask.array as da
import numpy as np
import pytest
import xarray as xr

from harpx.errors import ArchiveError
from harpx.io.netcdf import open_dataset, to_netcdf

FAILING_BLOCK = 2


def _hiccup(block: np.ndarray, block_info: dict[Any, Any] | None = None) -> np.ndarray:
    """One frame fails, the others take a little while (so they are still running)."""
    assert block_info is not None
    if block_info[0]["chunk-location"][0] == FAILING_BLOCK:
        raise RuntimeError("disk hiccup")
    time.sleep(0.005)
    return block


def _lazy_failing() -> xr.Dataset:
    frames = da.ones((16, 4000), chunks=(1, 4000))
    return xr.Dataset({"a": (("time", "x"), da.map_blocks(_hiccup, frames, dtype=float))})


def test_failed_lazy_write_leaves_only_the_untouched_target(tmp_path: Path) -> None:
    # dask's threaded scheduler raises the failing frame's error while the other frames
    # are still being written; a write task left running used to re-create the deleted
    # temporary file (in ~all runs). Several targets, each written over once.
    targets = []
    for k in range(4):
        target = tmp_path / f"a{k}.nc"
        to_netcdf(xr.Dataset({"a": ("time", np.arange(4.0))}), target)
        before = target.read_bytes()
        with pytest.raises(ArchiveError, match=r"RuntimeError: disk hiccup"):
            to_netcdf(_lazy_failing(), target)
        assert target.read_bytes() == before
        targets.append(target.name)
    # a stray task would finish within a few ms of the error: give it far longer
    time.sleep(0.2)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(targets)
    np.testing.assert_array_equal(open_dataset(tmp_path / "a0.nc")["a"].values, np.arange(4.0))


def test_lazy_write_still_writes_every_frame(tmp_path: Path) -> None:
    frames = da.arange(16 * 50, dtype=float, chunks=50).reshape(16, 50).rechunk((1, 50))
    ds = xr.Dataset({"a": (("time", "x"), frames)})
    path = to_netcdf(ds, tmp_path / "lazy.nc")
    back = open_dataset(path)
    np.testing.assert_array_equal(back["a"].values, np.arange(800.0).reshape(16, 50))
    assert [p.name for p in tmp_path.iterdir()] == ["lazy.nc"]


@pytest.mark.parametrize(
    "value",
    [
        pytest.param(np.array([[True], [False]]), id="2-D"),
        pytest.param(np.array([[True, False, True], [False, False, True]]), id="2x3"),
        pytest.param(np.array(True), id="0-D"),
        pytest.param(np.array([False]), id="one"),
        pytest.param(np.array([True, False]), id="1-D"),
    ],
)
def test_boolean_array_attributes_round_trip_with_their_shape(
    tmp_path: Path, value: np.ndarray
) -> None:
    ds = xr.Dataset({"a": ("x", [1.0, 2.0], {"flags": value})}, attrs={"flags": value})
    back = open_dataset(to_netcdf(ds, tmp_path / "a.nc"))
    for attrs in (back.attrs, back["a"].attrs):
        assert attrs["flags"].dtype == bool and attrs["flags"].shape == value.shape
        np.testing.assert_array_equal(attrs["flags"], value)
    xr.testing.assert_identical(back, ds)


def test_unstorable_attribute_names_itself(tmp_path: Path) -> None:
    ds = xr.Dataset({"a": ("x", [1.0, 2.0])}, attrs={"weird": {"a": 1}})
    with pytest.raises(ArchiveError, match=r"attribute 'weird' of the dataset"):
        to_netcdf(ds, tmp_path / "a.nc")
    assert list(tmp_path.iterdir()) == []
