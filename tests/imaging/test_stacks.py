"""Tests of harpx.imaging.stacks: slice stacks onto a common grid, the tagged/1 constructor."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from harpx.errors import SchemaError
from harpx.imaging.stacks import (
    SliceStack,
    common_grid,
    resample_stack,
    resample_stacks,
    tagged_dataset,
)
from harpx.schema import validate


def _stack_ds(slice_axis: str, *, n_slices: int = 3, thickness: float = 4.0) -> xr.Dataset:
    """An axis-aligned stack whose image is a linear function of position (exact for lerp)."""
    coords = {"x": np.arange(6.0), "y": np.arange(5.0) - 2.0, "z": np.arange(4.0) + 1.0}
    coords[slice_axis] = 10.0 + thickness * np.arange(n_slices)
    Z, Y, X = np.meshgrid(coords["z"], coords["y"], coords["x"], indexing="ij")
    image = (1.0 + 2.0 * X - 3.0 * Y + 0.5 * Z)[None, None]
    return tagged_dataset(
        image,
        tag=["x"] if slice_axis != "x" else ["y"],
        tag_frequency=0.1,
        slice_axis=[slice_axis],
        time=[0.0],
        z=coords["z"],
        y=coords["y"],
        x=coords["x"],
        sequence="CSPAMM",
        attrs={"slice_thickness": thickness},
        check=False,
    )


@pytest.mark.parametrize("slice_axis", ["x", "y", "z"])
def test_axis_aligned_stack_resamples_a_linear_field_exactly_inside_its_slab(slice_axis):
    ds = _stack_ds(slice_axis)
    stack = SliceStack.axis_aligned(ds, slice_axis)
    np.testing.assert_allclose(stack.normal, np.eye(3)["xyz".index(slice_axis)], atol=0)
    assert stack.slab == (-2.0, 10.0)  # slices at 0, 4, 8 mm from the first, 4 mm thick
    target = {d: np.asarray(ds[d].values) for d in "xyz"}
    target[slice_axis] = np.linspace(6.0, 24.0, 19)  # 1 mm steps, beyond the slab both ways
    image, mask = resample_stack(
        stack, SliceStack.volume(ds["image"], slice_axis), target["x"], target["y"], target["z"]
    )
    along = target[slice_axis]
    inside = (along >= 8.0) & (along <= 20.0)  # slab: 10 - 2 .. 18 + 2 mm
    shape = [1, 1, 1]
    shape["zyx".index(slice_axis)] = along.size
    np.testing.assert_array_equal(mask, np.broadcast_to(inside.reshape(shape), mask.shape))
    Z, Y, X = np.meshgrid(target["z"], target["y"], target["x"], indexing="ij")
    # beyond the outer slice centres (but in the slab) the nearest slice is used
    clamped = {"x": X, "y": Y, "z": Z}
    clamped[slice_axis] = np.clip(clamped[slice_axis], 10.0, 18.0)
    expected = 1.0 + 2.0 * clamped["x"] - 3.0 * clamped["y"] + 0.5 * clamped["z"]
    # linear interpolation of a linear field: exact to rounding (1e-12 of values ~ 30)
    np.testing.assert_allclose(image[0, 0][mask], expected[mask], rtol=0, atol=1e-12)
    assert np.all(image[0, 0][~mask] == 0.0)


def test_oblique_stack_mask_is_its_pixel_hull_and_slab():
    # a stack rotated by 30 degrees about z: columns along (cos, sin, 0), rows along (-sin, cos, 0)
    c, s = np.cos(np.pi / 6), np.sin(np.pi / 6)
    stack = SliceStack(
        origin=np.zeros(3),
        along_row=np.array([c, s, 0.0]),
        along_column=np.array([-s, c, 0.0]),
        pixel_spacing=(1.0, 1.0),
        rows=10,
        columns=10,
        offsets=np.array([0.0, 2.0]),
        slab=(-1.0, 3.0),
    )
    x = y = np.linspace(-8.0, 12.0, 41)
    z = np.linspace(-2.0, 4.0, 13)
    image, mask = resample_stack(stack, np.ones((2, 10, 10)), x, y, z)
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    column = c * X + s * Y
    row = -s * X + c * Y
    expected = (column >= 0) & (column <= 9) & (row >= 0) & (row <= 9) & (Z >= -1.0) & (Z <= 3.0)
    np.testing.assert_array_equal(mask, expected)
    np.testing.assert_allclose(image[mask], 1.0, rtol=1e-12)  # constant stays constant


def test_common_grid_covers_the_slabs_on_the_pixel_lattice():
    ds = _stack_ds("z")  # pixels at x = 0..5, y = -2..2; slices at z = 10, 14, 18 (4 mm)
    x, y, z = common_grid([SliceStack.axis_aligned(ds, "z")], 1.0)
    np.testing.assert_allclose(x, np.arange(6.0), atol=1e-12)
    np.testing.assert_allclose(y, np.arange(5.0) - 2.0, atol=1e-12)
    np.testing.assert_allclose(z, np.arange(8.0, 20.5, 1.0), atol=1e-12)  # slab 8 .. 20 mm


def test_resample_stacks_concatenates_tags_with_their_own_slabs():
    sa, la = _stack_ds("z"), _stack_ds("y")
    x = np.arange(6.0)
    y = np.linspace(-2.0, 24.0, 27)
    z = np.linspace(1.0, 24.0, 24)
    image, mask = resample_stacks([sa, la], x, y, z)
    assert image.shape == (2, 1, z.size, y.size, x.size) and mask.shape == (2, *image.shape[2:])
    # the z stack's slab is 8..20 mm along z, wherever y is (in its hull -2..2) and vice versa
    in_z = (z >= 8) & (z <= 20)
    in_y = (y >= 8) & (y <= 20)
    hull_y = (y >= -2) & (y <= 2)
    hull_z = (z >= 1) & (z <= 4)
    shape = mask.shape[1:]
    expected_z = np.broadcast_to(in_z[:, None, None] & hull_y[None, :, None], shape)
    expected_y = np.broadcast_to(hull_z[:, None, None] & in_y[None, :, None], shape)
    np.testing.assert_array_equal(mask[0], expected_z)
    np.testing.assert_array_equal(mask[1], expected_y)


def test_resample_stack_rejects_a_volume_of_another_shape():
    ds = _stack_ds("z")
    stack = SliceStack.axis_aligned(ds, "z")
    with pytest.raises(ValueError, match=r"expected \(\.\.\., 3, 5, 6\)"):
        resample_stack(stack, np.zeros((3, 6, 5)), [0.0], [0.0], [0.0])


def test_single_slice_needs_a_thickness():
    ds = _stack_ds("z", n_slices=1).drop_attrs()
    with pytest.raises(ValueError, match="single slice along 'z' needs thickness"):
        SliceStack.axis_aligned(ds, "z")
    assert SliceStack.axis_aligned(ds, "z", thickness=8.0).slab == (-4.0, 4.0)


def test_tagged_dataset_is_valid_and_labels_everything():
    ds = tagged_dataset(
        np.zeros((2, 3, 2, 4, 5)),
        tag=["x", "y"],
        tag_frequency=[0.125, 0.125],
        slice_axis=["z", "z"],
        time=[0.0, 20.0, 40.0],
        z=[0.0, 1.0],
        y=np.arange(4.0),
        x=np.arange(5.0),
        sequence="CSPAMM",
        mask=np.ones((2, 4, 5), bool),  # broadcast over tags and z
        body=np.full((2, 4, 5), 0.5),
        displacement_true=np.zeros((3, 3, 2, 4, 5)),
        attrs={"snr": 20.0},
    )
    validate(ds, "tagged")
    assert ds.attrs == {"harpx_schema": "tagged/1", "sequence": "CSPAMM", "snr": 20.0}
    assert ds["mask"].shape == (2, 2, 4, 5) and ds["mask"].dtype == bool
    np.testing.assert_array_equal(ds["tag_direction"].values, np.eye(3)[:2])
    for name in ("image", "mask", "body", "displacement_true", "tag_frequency", "x"):
        assert {"units", "long_name"} <= set(ds[name].attrs), name


def test_tagged_dataset_errors_name_the_problem():
    args = dict(tag=["t0"], tag_frequency=0.1, slice_axis=["z"], time=[0.0], z=[0.0], y=[0.0, 1.0])
    with pytest.raises(ValueError, match=r"tags \['t0'\] are not axis names.*tag_direction="):
        tagged_dataset(np.zeros((1, 1, 1, 2, 2)), x=[0.0, 1.0], sequence="SPAMM", **args)
    with pytest.raises(SchemaError, match="'sequence' is 'FLASH'"):
        tagged_dataset(
            np.zeros((1, 1, 1, 2, 2)),
            x=[0.0, 1.0],
            sequence="FLASH",
            tag_direction=[[1.0, 0.0, 0.0]],
            **args,
        )
