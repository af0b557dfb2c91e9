"""Tests of harpx.schema: the dataset conventions and validate()."""

from __future__ import annotations

from collections.abc import Callable

import dask.array as da
import numpy as np
import pytest
import xarray as xr
from hypothesis import given, settings
from hypothesis import strategies as st

from harpx.errors import SchemaError
from harpx.schema import UNITS, fill_standard_attrs, standard_attrs, validate
from tests._helpers import raise_if_dask_computes


def _attrs(name: str) -> dict[str, str]:
    return standard_attrs(name)


def make_tagged(*, nt: int = 2, nz: int = 2, ny: int = 8, nx: int = 8) -> xr.Dataset:
    """A tiny valid tagged/1 dataset with x and y tags (2 mm voxels, 8 mm tag period)."""
    x = 1.0 + 2.0 * np.arange(nx)
    y = 1.0 + 2.0 * np.arange(ny)
    z = 4.0 * np.arange(nz)
    f = 1.0 / 8.0
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    image = np.stack([1 + np.cos(2 * np.pi * f * xx), 1 + np.cos(2 * np.pi * f * yy)])
    image = np.broadcast_to(image[:, None], (2, nt, nz, ny, nx)).copy()
    ds = xr.Dataset(
        {
            "image": (("tag", "time", "z", "y", "x"), image, _attrs("image")),
            "mask": (("tag", "z", "y", "x"), np.ones((2, nz, ny, nx), bool), _attrs("mask")),
        },
        coords={
            "tag": ("tag", ["x", "y"], _attrs("tag")),
            "axis": ("axis", ["x", "y", "z"], _attrs("axis")),
            "tag_direction": (("tag", "axis"), [[1.0, 0, 0], [0, 1.0, 0]], _attrs("tag_direction")),
            "tag_frequency": ("tag", [f, f], _attrs("tag_frequency")),
            "slice_axis": ("tag", ["z", "z"], _attrs("slice_axis")),
            "time": ("time", 18.0 * np.arange(nt), _attrs("time")),
            "z": ("z", z, _attrs("z")),
            "y": ("y", y, _attrs("y")),
            "x": ("x", x, _attrs("x")),
        },
        attrs={"harpx_schema": "tagged/1", "sequence": "SPAMM"},
    )
    return ds


def make_phase() -> xr.Dataset:
    """A tiny valid phase/1 dataset derived from :func:`make_tagged`."""
    ds = make_tagged()
    k = 2 * np.pi * ds.tag_frequency * ds.tag_direction
    arg = k.sel(axis="x") * ds.x + k.sel(axis="y") * ds.y + k.sel(axis="z") * ds.z
    wrapped = (arg + np.pi) % (2 * np.pi) - np.pi  # W(a) in [-pi, pi)
    phase = (
        wrapped.broadcast_like(ds.image)
        .transpose(*ds.image.dims)
        .drop_vars("tag_direction", errors="ignore")
    )
    out = ds.drop_vars("image").assign(
        phase=phase.assign_attrs(_attrs("phase")),
        magnitude=xr.ones_like(ds.image).assign_attrs(_attrs("magnitude")),
    )
    out.attrs.update(harpx_schema="phase/1", upsample=1, radius=0.5)
    return out


def make_tracked() -> xr.Dataset:
    """A tiny valid tracked/1 dataset: one hex8 cell, two frames."""
    points = np.array(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
        dtype=float,
    )
    cells = xr.Variable(("cell", "vertex"), np.arange(8)[None, :], _attrs("cells"))
    cells.attrs["element"] = "hex8"
    return xr.Dataset(
        {
            "points": (("node", "axis"), points, _attrs("points")),
            "cells": cells,
            "displacement": (("time", "node", "axis"), np.zeros((2, 8, 3)), _attrs("displacement")),
            "epsilon": ("time", [0.0, 0.01], _attrs("epsilon")),
        },
        coords={
            "axis": ("axis", ["x", "y", "z"], _attrs("axis")),
            "time": ("time", [0.0, 18.0], _attrs("time")),
        },
        attrs={"harpx_schema": "tracked/1"},
    )


def test_valid_datasets_pass() -> None:
    validate(make_tagged())
    validate(make_tagged(), kind="tagged")
    validate(make_phase())
    validate(make_tracked())


def test_standard_attrs_cover_every_unit() -> None:
    for name in UNITS:
        cf = {"standard_name", "axis"} if name == "time" else set()
        cf |= {"axis"} if name in ("x", "y", "z") else set()
        assert set(standard_attrs(name)) == {"units", "long_name"} | cf
    # CF names only where the CF table has one; axes are the Cartesian X, Y, Z and T
    assert standard_attrs("time")["standard_name"] == "time"
    assert [standard_attrs(a)["axis"] for a in ("x", "y", "z", "time")] == ["X", "Y", "Z", "T"]
    with pytest.raises(KeyError, match="'velocity' is not a standard harpx variable"):
        standard_attrs("velocity")


def _set(ds: xr.Dataset, name: str, values: object) -> xr.Dataset:
    ds = ds.copy(deep=True)
    ds[name] = ds[name].copy(data=np.asarray(values))
    return ds


def _nan_image(ds: xr.Dataset) -> xr.Dataset:
    ds = ds.copy(deep=True)
    ds["image"][0, 1, 1, 2, 3] = np.nan
    ds["image"][1, 0, 0, 0, 0] = np.inf
    return ds


def _uneven_x(ds: xr.Dataset) -> xr.Dataset:
    x = ds.x.values.copy()
    x[3] += 0.3
    return ds.assign_coords(x=("x", x, ds.x.attrs))


def _decreasing_y(ds: xr.Dataset) -> xr.Dataset:
    return ds.assign_coords(y=("y", ds.y.values[::-1], ds.y.attrs))


def _no_units(ds: xr.Dataset) -> xr.Dataset:
    ds = ds.copy()
    ds["time"].attrs = {"long_name": "time"}
    return ds


def _drop_coord(name: str) -> Callable[[xr.Dataset], xr.Dataset]:
    return lambda ds: ds.drop_vars(name)


# Each row: (mutation of a valid tagged dataset, text the error must contain).
BAD_TAGGED = [
    pytest.param(
        lambda ds: ds.assign(image=ds.image.transpose("tag", "time", "y", "z", "x")),
        r"'image' has dims \('tag', 'time', 'y', 'z', 'x'\); expected order",
        id="dims-order",
    ),
    pytest.param(
        lambda ds: ds.assign(image=ds.image.isel(z=0)),
        r"'image' has dims .*missing \['z'\]",
        id="dims-missing",
    ),
    pytest.param(lambda ds: ds.drop_vars("image"), "missing data variable 'image'", id="no-image"),
    pytest.param(
        _drop_coord("tag_frequency"), "missing coordinate 'tag_frequency'", id="no-frequency"
    ),
    pytest.param(_drop_coord("slice_axis"), "missing coordinate 'slice_axis'", id="no-slice-axis"),
    pytest.param(
        lambda ds: ds.reset_coords("tag_direction"),
        "'tag_direction' is a data variable but must be a coordinate",
        id="direction-not-coord",
    ),
    pytest.param(_no_units, "'time' has no 'units' attribute", id="no-units"),
    pytest.param(
        lambda ds: ds.assign_coords(x=ds.x.assign_attrs(units="m")),
        "'x' has units 'm'; harpx expects 'mm'",
        id="wrong-units",
    ),
    pytest.param(
        _uneven_x,
        r"coordinate 'x' is not evenly spaced \(max deviation .* mm.*ds.interp\(x=",
        id="uneven-x",
    ),
    pytest.param(_decreasing_y, "coordinate 'y' is not increasing", id="decreasing-y"),
    pytest.param(
        _nan_image,
        r"'image' has 2 non-finite values \(NaN/inf\), first at index "
        r"\{tag=0, time=1, z=1, y=2, x=3\}",
        id="nan-image",
    ),
    pytest.param(
        lambda ds: _set(ds, "tag_direction", [[1.0, 0.1, 0], [0, 1, 0]]),
        "tag_direction of tag 'x' has norm 1.00499",
        id="direction-not-unit",
    ),
    pytest.param(
        # 2 mm voxels: Nyquist 0.25 cycles/mm; 0.3 cycles/mm (3.3 mm period) is above it
        lambda ds: _set(ds, "tag_frequency", [0.125, 0.3]),
        r"tag_frequency of tag 'y' is above the Nyquist limit along 'y': 0.3 .* > .*0.25",
        id="above-nyquist",
    ),
    pytest.param(
        lambda ds: _set(ds, "slice_axis", ["w", "z"]),
        "slice_axis of tag 'x' is 'w'",
        id="slice-axis-unknown",
    ),
    pytest.param(
        lambda ds: _set(ds, "slice_axis", ["x", "z"]),
        "tag 'x' has direction .* mostly along its slice_axis 'x'",
        id="slice-axis-along-tag",
    ),
    pytest.param(
        lambda ds: ds.assign_attrs(sequence="GRE"),
        "'sequence' is 'GRE'; expected one of",
        id="sequence",
    ),
    pytest.param(
        lambda ds: ds.assign(mask=ds.mask.astype(np.int8)),
        "'mask' has dtype 'int8'; expected bool",
        id="mask-not-bool",
    ),
    pytest.param(
        lambda ds: ds.assign(mask=ds.mask.isel(tag=0)),
        r"'mask' has dims \('z', 'y', 'x'\); expected \('tag', 'z', 'y', 'x'\)",
        id="mask-dims",
    ),
    pytest.param(
        lambda ds: ds.assign_attrs(harpx_schema="phase/1"),
        "'harpx_schema' is 'phase/1' but 'tagged/1' was expected",
        id="schema-mismatch",
    ),
]


@pytest.mark.parametrize(("mutate", "match"), BAD_TAGGED)
def test_validate_rejects_bad_tagged(
    mutate: Callable[[xr.Dataset], xr.Dataset], match: str
) -> None:
    ds = mutate(make_tagged())
    with pytest.raises(SchemaError, match=match):
        validate(ds, kind="tagged")


def test_a_decreasing_axis_is_one_problem_not_also_a_false_nyquist_one() -> None:
    # a flipped y used to add "0 cycles/mm > 1/(2 dy) = -0.25" lines for every tag
    with pytest.raises(SchemaError) as err:
        validate(_decreasing_y(make_tagged()), kind="tagged")
    assert err.value.problems == [
        "coordinate 'y' is not increasing (step -2 mm at index 0); sort with ds.sortby('y') "
        "or flip the axis"
    ]


def _phase_at_pi(ds: xr.Dataset) -> xr.Dataset:
    ds = ds.copy(deep=True)
    ds["phase"][0, 0, 0, 0, 0] = np.pi
    return ds


def _negative_magnitude(ds: xr.Dataset) -> xr.Dataset:
    ds = ds.copy(deep=True)
    ds["magnitude"][0, 0, 0, 0, 0] = -0.5
    return ds


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        pytest.param(_phase_at_pi, r"expected the wrapped range \[-pi, pi\)", id="phase-range"),
        pytest.param(_negative_magnitude, "'magnitude' has 1 negative values", id="neg-magnitude"),
        pytest.param(
            lambda ds: ds.drop_vars("magnitude"),
            "missing data variable 'magnitude'",
            id="no-magnitude",
        ),
        pytest.param(
            lambda ds: ds.drop_attrs(deep=False).assign_attrs(harpx_schema="phase/1"),
            "missing dataset attribute 'upsample'",
            id="no-upsample",
        ),
    ],
)
def test_validate_rejects_bad_phase(mutate: Callable[[xr.Dataset], xr.Dataset], match: str) -> None:
    with pytest.raises(SchemaError, match=match):
        validate(mutate(make_phase()))


def _cells_attr(ds: xr.Dataset, **attrs: str) -> xr.Dataset:
    ds = ds.copy()
    ds["cells"].attrs.update(attrs)
    return ds


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        pytest.param(
            lambda ds: _cells_attr(ds, element="hex20"),
            "'cells' has 8 vertices per cell but element 'hex20' needs 20",
            id="vertices",
        ),
        pytest.param(
            lambda ds: _cells_attr(ds, element="brick"),
            "'cells' element 'brick' is unknown",
            id="element",
        ),
        pytest.param(
            lambda ds: _set(ds, "cells", np.arange(1, 9)[None, :]),
            r"node ids in \[1, 8\] but there are 8 nodes",
            id="cell-index",
        ),
        pytest.param(
            lambda ds: ds.drop_vars("displacement"),
            "missing data variable 'displacement'",
            id="no-displacement",
        ),
    ],
)
def test_validate_rejects_bad_tracked(
    mutate: Callable[[xr.Dataset], xr.Dataset], match: str
) -> None:
    with pytest.raises(SchemaError, match=match):
        validate(mutate(make_tracked()))


def test_tracked_point_cloud_allowed() -> None:
    ds = make_tracked()
    cells = xr.Variable(("cell", "vertex"), np.zeros((0, 0), np.int64), _attrs("cells"))
    cells.attrs["element"] = "points"
    validate(ds.drop_vars("cells").assign(cells=cells))


def test_validate_reports_every_problem_at_once() -> None:
    ds = _uneven_x(_nan_image(make_tagged())).assign_attrs(sequence="GRE")
    ds = _set(ds, "tag_direction", [[2.0, 0, 0], [0, 1, 0]])
    with pytest.raises(SchemaError) as info:
        validate(ds)
    assert len(info.value.problems) == 4, info.value.problems
    assert str(info.value).count("\n") == 3


def test_missing_schema_attr_is_a_clear_error() -> None:
    ds = make_tagged()
    ds.attrs.pop("harpx_schema")
    with pytest.raises(SchemaError, match="no attribute 'harpx_schema'.*pass kind="):
        validate(ds)
    with pytest.raises(SchemaError, match="missing dataset attribute 'harpx_schema'"):
        validate(ds, kind="tagged")
    with pytest.raises(ValueError, match="kind='pahse' is not a harpx schema"):
        validate(make_tagged(), kind="pahse")


def test_validate_dask_is_lazy() -> None:
    ds = make_tagged()
    ds["image"] = ds.image.copy(data=da.from_array(ds.image.values, chunks=1))
    ds["image"][0, 0, 0, 0, 0] = np.nan  # value checks are skipped for dask (documented)
    with raise_if_dask_computes():
        validate(ds)


@settings(max_examples=25, deadline=None)
@given(
    index=st.tuples(
        st.integers(0, 1),
        st.integers(0, 1),
        st.integers(0, 1),
        st.integers(0, 7),
        st.integers(0, 7),
    ),
    value=st.sampled_from([np.nan, np.inf, -np.inf]),
)
def test_validate_never_accepts_nonfinite_image(index: tuple[int, ...], value: float) -> None:
    ds = make_tagged()
    ds["image"].values[index] = value
    with pytest.raises(SchemaError, match="'image' has 1 non-finite values"):
        validate(ds)


def test_fill_standard_attrs_keeps_existing_and_copies() -> None:
    bare = xr.Dataset(
        {"phase": ("x", [0.0, 1.0])}, coords={"x": ("x", [0.5, 1.5], {"units": "mm", "note": "k"})}
    )
    filled = fill_standard_attrs(bare)
    assert filled.phase.attrs == standard_attrs("phase")
    assert filled.x.attrs == {**standard_attrs("x"), "note": "k"}
    assert bare.phase.attrs == {}  # the input is not modified
