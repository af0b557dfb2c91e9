"""The slice geometry a tagged/1 dataset assembled from stacks records (harpx.imaging.stacks)."""

from __future__ import annotations

import numpy as np
import pytest

from harpx.errors import SchemaError
from harpx.imaging.harp import slice_geometry
from harpx.imaging.stacks import (
    SliceStack,
    resample_stacks,
    stacks_slice_geometry,
    tagged_dataset,
)
from harpx.schema import validate
from tests.imaging.test_stacks import _stack_ds


def _assembled(thickness, positions, **kwargs):
    return tagged_dataset(
        np.zeros((2, 1, 3, 2, 2)), tag=["x", "z"], tag_frequency=0.1, slice_axis=["z", "y"],
        time=[0.0], z=[0.0, 2.0, 4.0], y=[0.0, 2.0], x=[0.0, 2.0], sequence="CSPAMM",
        slice_thickness=thickness, slice_position=positions, **kwargs,
    )  # fmt: skip


def test_stacks_give_their_slice_geometry_to_the_dataset():
    # a z stack of 3 slices 4 mm thick at z = 10, 14, 18 and a y stack of 2 slices 6 mm thick
    sa, la = _stack_ds("z"), _stack_ds("y", n_slices=2, thickness=6.0)
    thickness, positions = stacks_slice_geometry([sa, la])
    np.testing.assert_array_equal(thickness, [4.0, 6.0])
    np.testing.assert_array_equal(positions[0], [10.0, 14.0, 18.0])
    np.testing.assert_array_equal(positions[1], [10.0, 16.0])
    x, y, z = np.arange(6.0), np.linspace(-2.0, 24.0, 27), np.linspace(1.0, 24.0, 24)
    image, mask = resample_stacks([sa, la], x, y, z)
    ds = tagged_dataset(
        image, tag=["x", "z"], tag_frequency=0.1, slice_axis=["z", "y"], time=[0.0], z=z,
        y=y, x=x, sequence="CSPAMM", mask=mask, slice_thickness=thickness,
        slice_position=positions,
    )  # fmt: skip
    validate(ds, "tagged")
    # NaN-padded to the longest stack; slice_geometry (what the tracker reads) takes them
    np.testing.assert_array_equal(ds.slice_position.values, [[10, 14, 18], [10, 16, np.nan]])
    geometry = slice_geometry(ds)
    np.testing.assert_array_equal(geometry["slice_thickness"].values, [4.0, 6.0])
    assert ds.slice_position.attrs["units"] == "mm"


def test_oblique_stack_has_no_centres_along_an_axis():
    stack = SliceStack.axis_aligned(_stack_ds("z"), "z")
    np.testing.assert_array_equal(stack.centres_along("z"), [10.0, 14.0, 18.0])
    assert stack.centres_along("x") is None  # the slices are not planes normal to x
    b = np.deg2rad(0.5)  # half a degree off z: 0.9 mm over a 100 mm field of view
    tilted = SliceStack(
        origin=stack.origin, along_row=np.array([np.cos(b), 0.0, np.sin(b)]),
        along_column=stack.along_column, pixel_spacing=stack.pixel_spacing, rows=stack.rows,
        columns=stack.columns, offsets=stack.offsets, slab=stack.slab,
    )  # fmt: skip
    assert tilted.centres_along("z") is None
    with pytest.raises(ValueError, match="axis='w'"):
        stack.centres_along("w")


def test_slice_geometry_arguments_are_checked():
    with pytest.raises(ValueError, match="come together"):
        _assembled(4.0, None)
    with pytest.raises(ValueError, match="one thickness and one 1-D row"):
        _assembled([4.0, 4.0, 4.0], [[0.0], [0.0]])
    with pytest.raises(SchemaError, match="increasing"):
        _assembled(4.0, [[4.0, 0.0], [1.0]])
    with pytest.raises(SchemaError, match="expected positive mm"):
        _assembled([-1.0, 2.0], [[0.0], [1.0]])
    # unknown for one tag: NaN thickness and no centres
    ds = _assembled([np.nan, 2.0], [[], [1.0]])
    assert np.isnan(ds.slice_position.values[0]).all()
