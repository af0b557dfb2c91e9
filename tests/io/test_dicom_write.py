"""write_tagged → read_tagged reproduces a tagged/1 dataset (grid, masks, images, times)."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

pytest.importorskip("pydicom")

from harpx.errors import HarpxWarning, SchemaError  # noqa: E402
from harpx.io.dicom import read_tagged  # noqa: E402
from harpx.io.dicom_write import write_tagged  # noqa: E402
from harpx.schema import fill_standard_attrs  # noqa: E402


def _tagged(rng) -> xr.Dataset:
    # a small grid so the test is fast: 2 frames of 6 x 8 x 7 voxels of 2 mm
    z, y, x = np.arange(6) * 2.0 - 5.0, np.arange(8) * 2.0 - 7.0, np.arange(7) * 2.0 - 6.0
    image = rng.normal(size=(3, 2, z.size, y.size, x.size))
    mask = np.ones((3, z.size, y.size, x.size), dtype=bool)
    mask[:2, :1] = False  # the short-axis slab leaves out the lowest plane
    mask[2, :, :2] = False  # the long-axis slab leaves out two y planes
    image = np.where(mask[:, None], image, 0.0)
    ds = xr.Dataset(
        {"image": (("tag", "time", "z", "y", "x"), image),
         "mask": (("tag", "z", "y", "x"), mask)},
        coords={
            "tag": ["x", "y", "z"], "axis": ["x", "y", "z"],
            "tag_direction": (("tag", "axis"), np.eye(3)),
            "tag_frequency": ("tag", [0.125] * 3),
            "slice_axis": ("tag", ["z", "z", "y"]),
            "time": ("time", [0.0, 30.0]), "z": z, "y": y, "x": x,
        },
        attrs={"harpx_schema": "tagged/1", "sequence": "CSPAMM"},
    )  # fmt: skip
    return fill_standard_attrs(ds)


def test_written_series_read_back_on_the_same_grid(tmp_path, rng):
    ds = _tagged(rng)
    described = write_tagged(ds, tmp_path)
    assert described == {"x": "tagged x", "y": "tagged y", "z": "tagged z"}
    directions = {described[t]: [(t, tuple(np.eye(3)[i]))] for i, t in enumerate("xyz")}
    back = read_tagged(tmp_path, tag_period=8.0, tag_directions=directions)
    for d in ("z", "y", "x", "time"):
        np.testing.assert_allclose(back[d], ds[d], atol=1e-9)  # decimal strings, 10 digits
    assert back.attrs["sequence"] == "CSPAMM"
    np.testing.assert_array_equal(back["mask"].values, ds["mask"].values)
    # uint16 with one slope per series: at most half a slope = range / 131070 off
    bound = 0.5 * float(ds.image.max() - ds.image.min()) / 65535 + 1e-9
    assert float(np.abs(back.image - ds.image).max()) <= bound


def test_planes_without_slice_geometry_are_recorded_as_slices(tmp_path, rng):
    # no slice geometry in the dataset: the grid planes are the slices, as thick as the grid
    # spacing, and the reader records them
    ds = _tagged(rng)
    described = write_tagged(ds, tmp_path)
    directions = {described[t]: [(t, tuple(np.eye(3)[i]))] for i, t in enumerate("xyz")}
    back = read_tagged(tmp_path, tag_period=8.0, tag_directions=directions)
    np.testing.assert_allclose(back.slice_thickness, [2.0, 2.0, 2.0], rtol=1e-12)
    np.testing.assert_allclose(back.slice_position.sel(tag="x")[:5], ds.z[1:], atol=1e-9)
    assert np.isnan(back.slice_position.sel(tag="x")[5])  # padding: 5 planes, the z tag 6
    np.testing.assert_allclose(back.slice_position.sel(tag="z")[:6], ds.y[2:], atol=1e-9)


def _stack_dataset(rng, centres=(-6.0, 4.0, 14.0), thickness=10.0) -> xr.Dataset:
    """Thick short-axis slices (2 tags) resampled onto a 2 mm grid, with their geometry."""
    from harpx.imaging.stacks import SliceStack, resample_stack, tagged_dataset

    centres = np.asarray(centres)
    y, x = np.arange(6) * 2.0 - 5.0, np.arange(7) * 2.0 - 6.0
    stack = SliceStack(
        origin=np.array([x[0], y[0], centres[0]]),
        along_row=np.array([1.0, 0, 0]),
        along_column=np.array([0, 1.0, 0]),
        pixel_spacing=(2.0, 2.0),
        rows=y.size,
        columns=x.size,
        offsets=centres - centres[0],
        slab=(-0.5 * thickness, float(centres[-1] - centres[0]) + 0.5 * thickness),
    )
    z = np.arange(centres[0] - 0.5 * thickness + 1.0, centres[-1] + 0.5 * thickness, 2.0)
    slices = rng.normal(size=(2, 3, centres.size, y.size, x.size))  # (tag, time, slice, ...)
    image, mask = resample_stack(stack, slices, x, y, z)
    return tagged_dataset(
        image, tag=["x", "y"], tag_frequency=0.125, slice_axis=["z", "z"],
        time=[0.0, 30.0, 60.0], z=z, y=y, x=x, sequence="CSPAMM", mask=mask,
        slice_thickness=thickness, slice_position=[centres, centres],
    )  # fmt: skip


def test_slice_geometry_round_trip(tmp_path, rng):
    ds = _stack_dataset(rng)
    described = write_tagged(ds, tmp_path)
    # one file per slice centre and frame (not per grid plane), SliceThickness as given
    import pydicom

    files = sorted((tmp_path / "x").glob("*.dcm"))
    assert len(files) == 3 * 3
    headers = [pydicom.dcmread(f, stop_before_pixels=True) for f in files]
    assert {float(h.SliceThickness) for h in headers} == {10.0}
    assert sorted({float(h.ImagePositionPatient[2]) for h in headers}) == [-6.0, 4.0, 14.0]
    back = read_tagged(
        tmp_path, tag_period=8.0,
        tag_directions={described["x"]: ("x", (1, 0, 0)), described["y"]: ("y", (0, 1, 0))},
    )  # fmt: skip
    np.testing.assert_array_equal(back.slice_thickness, ds.slice_thickness)
    np.testing.assert_array_equal(back.slice_position, ds.slice_position)
    for d in ("z", "y", "x"):
        np.testing.assert_allclose(back[d], ds[d], atol=1e-9)
    np.testing.assert_array_equal(back.mask, ds.mask)
    # the written slices are the ones the grid was resampled from, so the read-back grid
    # images are those of the dataset up to the uint16 step: at most half a slope of the
    # slices' range (a convex combination of slices keeps that bound)
    bound = 0.5 * 2 * float(np.abs(ds.image).max()) / 65535 * 1.01
    assert float(np.abs(back.image - ds.image).max()) <= bound


def test_images_that_do_not_match_their_slice_geometry(tmp_path, rng):
    ds = _stack_dataset(rng)
    bumped = ds.copy(deep=True)
    bumped["image"][0, 0, 2] += 1.0  # one grid plane away from the slices' interpolation
    with pytest.warns(HarpxWarning, match=r"tag 'x'.*not linear between the slice centres"):
        write_tagged(bumped, tmp_path / "bumped")
    # a mask holding only the planes beyond the outer slice centres leaves the middle slice
    # without a plane in its reach
    outer = ds.copy(deep=True)
    outer["mask"].values &= ((ds.z < -6.0) | (ds.z > 14.0)).values[:, None, None]
    with pytest.raises(SchemaError, match=r"tag 'x': its 3 slices .* not resolved"):
        write_tagged(outer, tmp_path / "outer")
