"""Anatomy input that used to give a plausible wrong ventricle or mesh now refuses, by name.

Before: four mid-ventricular slices gave a long axis in the slice plane and c_endo of
4940 mm; a solid cylinder gave an axis 90 degrees off; two blobs were fitted as one
ventricle; ``mesh_from_labels`` ran for minutes on an intensity image, tried to allocate
18.7 GiB for a 160³ mask at 0.5 mm, and stopped with numpy's "need at least one array to
stack" on an empty mask; ``Fixed("base")`` on a boundary without facets constrained nothing.
"""

from __future__ import annotations

import re
import tracemalloc

import numpy as np
import pytest
import xarray as xr

from harpx.anatomy.segmentation import SegmentationError, mesh_from_labels
from harpx.anatomy.ventricle_fit import (
    VentricleFitError,
    VentricleTemplate,
    fit_ventricle_to_mask,
)
from harpx.errors import HarpxWarning
from harpx.mechanics.body import Body
from harpx.mechanics.loads import EmptyBoundaryError, Fixed, Prescribed, Pressure
from harpx.mechanics.materials import NeoHookean
from tests.anatomy._lv_masks import (
    MID_SLICES,
    TRUTH,
    short_axis_stack,
    volume,
    with_rv,
)

GIVEN = {"base_side": "high", "base_level": 10.0}


def _cylinder() -> xr.DataArray:
    stack = short_axis_stack()
    Z, Y, X = np.meshgrid(stack.z, stack.y, stack.x, indexing="ij")
    return stack.copy(data=((X - 2.0) ** 2 + (Y + 3.0) ** 2 < 30.0**2).astype(np.int64))


def _two_blobs() -> xr.DataArray:
    left = VentricleTemplate(TRUTH.geometry, centre=(-30.0, 0.0, 0.0))
    right = VentricleTemplate(TRUTH.geometry, centre=(45.0, 0.0, 0.0))
    return short_axis_stack(template=left, half=80.0) | short_axis_stack(template=right, half=80.0)


def _nan() -> xr.DataArray:
    stack = short_axis_stack().astype(np.float64)
    stack.values[0, 0, 0] = np.nan
    return stack


def _far_rv() -> xr.DataArray:
    stack = short_axis_stack()
    stack.values[:, :3, :3] = 2  # a corner far from the ventricle
    return stack


@pytest.mark.parametrize(
    ("mask", "kwargs", "match"),
    [
        pytest.param(_cylinder, GIVEN, r"no short-axis slice \(normal z\) of the mask encloses "
                     r"a cavity: its 4 slices", id="cylinder-without-cavity"),
        pytest.param(_two_blobs, GIVEN, r"in 2 separate pieces of \[2955, 2955\] voxels",
                     id="two-blobs"),
        pytest.param(short_axis_stack, {"axis": [1.0, 0.0, 0.3], "base_level": 10.0},
                     r"73\.3 degrees off the normal of a short-axis stack", id="axis-hint"),
        pytest.param(lambda: short_axis_stack() * 0, GIVEN, r"no myocardium \(no voxel >= 0\.5 "
                     r"among 16900\)", id="empty"),
        pytest.param(short_axis_stack, {}, "cannot tell the base from the apex",
                     id="no-sense"),
        pytest.param(short_axis_stack, {"base_side": "high"},
                     r"base level is unknown.*top of the stack \(z = -18 mm\)", id="no-base"),
        pytest.param(volume, {"base_side": "low"}, r"apical cap of the mask .* lies at that end",
                     id="base-side-contradicts-the-apex"),
        pytest.param(lambda: with_rv(short_axis_stack(), 150.0, 270.0), GIVEN,
                     r"holds labels \[1, 2\]; say which", id="which-label"),
        pytest.param(_far_rv, {**GIVEN, "myocardium": 1, "rv": 2},
                     "right-ventricle label 2 does not touch the left-ventricular myocardium",
                     id="rv-apart"),
        pytest.param(lambda: short_axis_stack((-10.0, 6.0)), GIVEN,
                     "2 ring slices cannot place it", id="apex-unlocatable"),
        pytest.param(lambda: short_axis_stack() * 0.7, {**GIVEN, "myocardium": 1},
                     "tissue fraction, not integer labels", id="labels-of-a-fraction"),
        pytest.param(_nan, GIVEN, "the mask contains NaN or inf", id="nan"),
        pytest.param(short_axis_stack, {**GIVEN, "myocardium": 3},
                     r"labels \[3\] are not in the mask \(present: \[1\]\)", id="label-missing"),
        pytest.param(short_axis_stack, {**GIVEN, "slice_axis": "w"}, "slice_axis='w' must be",
                     id="slice-axis"),
        pytest.param(short_axis_stack, {"base_side": "up", "base_level": 10.0},
                     "base_side='up' must be", id="base-side"),
        pytest.param(short_axis_stack, {**GIVEN, "rv": 2, "anterior": 0.0},
                     "either rv=.* or anterior=, not both", id="rv-and-anterior"),
        pytest.param(short_axis_stack, {**GIVEN, "axis": "tilted"}, "axis='tilted' must be",
                     id="axis-name"),
        pytest.param(short_axis_stack, {**GIVEN, "axis": [0.0, 0.0, 0.0]},
                     "must be a finite non-zero vector", id="axis-zero"),
        pytest.param(short_axis_stack, {"base_side": "high", "axis": [0.0, 0.0, -1.0]},
                     r"base_side='high' contradicts axis=\[0\.0, 0\.0, -1\.0\]",
                     id="base-side-contradicts-axis"),
        pytest.param(volume, {"apex_level": -70.0}, "this mask is fitted in 3-D",
                     id="apex-level-in-3d"),
        pytest.param(volume, {"axis": [1.0, 0.0, 0.9]},
                     r"48\.0 degrees off the normal of the slices \(z, limit 45\)",
                     id="axis-hint-3d-far"),
        pytest.param(volume, {"base_level": 200.0},
                     r"base plane from base_level=200 mm lies .* outside the cavity",
                     id="base-beyond-the-cavity"),
    ],
)  # fmt: skip
def test_untrustworthy_fits_refuse(mask, kwargs, match):
    with pytest.raises(VentricleFitError, match=match):
        fit_ventricle_to_mask(mask(), **kwargs)


def test_fit_errors_are_value_errors():
    assert issubclass(VentricleFitError, ValueError)
    assert issubclass(SegmentationError, ValueError)
    assert issubclass(EmptyBoundaryError, ValueError)


@pytest.mark.parametrize(
    "labels",
    [
        pytest.param(np.zeros((4, 5, 6), dtype=np.int64), id="all-zero"),
        pytest.param(np.zeros((4, 5, 6), dtype=bool), id="all-false"),
        pytest.param(np.zeros((4, 5, 6)), id="zero-fraction"),
    ],
)
def test_empty_label_volume_is_named(labels):
    coords = {"z": np.arange(4.0), "y": np.arange(5.0), "x": np.arange(6.0)}
    da = xr.DataArray(labels, dims=("z", "y", "x"), coords=coords)
    with pytest.raises(SegmentationError, match="hold no foreground"):
        mesh_from_labels(da, element_size=2.0)


def test_intensity_image_as_labels_is_refused():
    rng = np.random.default_rng(0)
    image = rng.integers(0, 3000, size=(20, 20, 20))  # about 2900 distinct values
    c = np.arange(20.0)
    da = xr.DataArray(image, dims=("z", "y", "x"), coords={"z": c, "y": c, "x": c})
    distinct = len(np.unique(image)) - int((image == 0).any())
    with pytest.raises(SegmentationError, match=f"hold {distinct} distinct non-zero values"):
        mesh_from_labels(da, element_size=2.0)
    # choosing labels does not help when the chosen ones touch thousands of others
    with pytest.raises(SegmentationError, match="touch .* other distinct values"):
        mesh_from_labels(da, element_size=2.0, mesh_labels=[int(image[10, 10, 10])])


def test_huge_mesh_is_refused_before_allocating():
    # a 160³ mask of 1 mm voxels (a shell 40 .. 60 mm) at 0.5 mm elements: 5e6 cells
    c = np.arange(160.0)
    Z, Y, X = np.meshgrid(c, c, c, indexing="ij")
    r = np.sqrt((X - 80.0) ** 2 + (Y - 80.0) ** 2 + (Z - 80.0) ** 2)
    da = xr.DataArray(((r < 60) & (r > 40)).astype(np.int8), dims=("z", "y", "x"),
                      coords={"z": c, "y": c, "x": c})  # fmt: skip
    tracemalloc.start()
    with pytest.raises(SegmentationError, match=r"needs about 2\d\.\d GiB .* choose "
                                                 r"element_size >= 0\.\d+ mm"):  # fmt: skip
        mesh_from_labels(da, element_size=0.5)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 0.5 * 2**30  # the refusal allocates the mask's indices at most (measured)


def test_suggested_element_size_fits_the_budget():
    c = np.arange(-20.0, 20.5, 1.0)
    Z, Y, X = np.meshgrid(c, c, c, indexing="ij")
    ball = xr.DataArray((np.sqrt(X**2 + Y**2 + Z**2) < 15).astype(int), dims=("z", "y", "x"),
                        coords={"z": c, "y": c, "x": c})  # fmt: skip
    budget = 50e6
    with pytest.raises(SegmentationError) as info:
        mesh_from_labels(ball, element_size=0.5, max_bytes=budget)
    found = re.search(r"element_size >= ([0-9.]+) mm", str(info.value))
    assert found is not None
    size = float(found.group(1))
    tracemalloc.start()
    result = mesh_from_labels(ball, element_size=size, max_bytes=budget)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    # the estimate is an upper bound: measured peak 41 MB for the 50 MB budget at 1.22 mm
    assert peak <= budget
    assert result.quality.inverted == 0


def _body_with_empty_base() -> Body:
    with pytest.warns(HarpxWarning, match="boundary 'base' selects none of the"):
        spec = mesh_from_labels(
            short_axis_stack(), element_size=4.0,
            boundaries={"base": lambda centres, normals: centres[:, 2] > 100.0},
        ).spec  # fmt: skip
    return Body(spec, NeoHookean(c1=1.0, kappa=10.0))


def test_conditions_on_an_empty_boundary_are_refused():
    body = _body_with_empty_base()
    assert len(body.boundaries["base"]) == 0 and len(body.boundaries["exterior"]) > 0
    named = r"'base', which has no facets .* Non-empty boundaries: \['exterior'\]"
    with pytest.raises(EmptyBoundaryError, match="Fixed on boundary " + named):
        Fixed("base").dofs(body)
    with pytest.raises(EmptyBoundaryError, match="Prescribed on boundary " + named):
        Prescribed("base", lambda X, s: 0.0 * X).dofs(body)
    with pytest.raises(EmptyBoundaryError, match="Pressure on boundary " + named):
        Pressure("base", 1.0).residual_tangent(body, np.zeros(body.ndof), 1.0)
    # a non-empty boundary still works
    assert Fixed("exterior").dofs(body).size > 0


def test_mid_stack_defaults_no_longer_invent_a_ventricle():
    # the user's call on the mid-ventricular stack: a named refusal, not an axis in plane
    with pytest.raises(VentricleFitError, match="base_side="):
        fit_ventricle_to_mask(short_axis_stack(MID_SLICES))
