"""Dataset conventions of harpx and :func:`validate`, which checks a dataset against them.

The conventions (the three kinds ``tagged/1``, ``phase/1``, ``tracked/1``, their variables,
units and names) are defined in :mod:`harpx.conventions` and importable from here as well.
:func:`validate` checks a dataset and raises one :class:`~harpx.errors.SchemaError` that
lists every problem it found (``err.problems``), each naming the variable, dimension or
value and how to fix it.
"""

from __future__ import annotations

import numbers
from collections.abc import Hashable, Mapping
from typing import Any

import numpy as np
import xarray as xr

from harpx import conventions
from harpx.conventions import *  # noqa: F403  (re-exported: see __all__)
from harpx.conventions import (
    _MIN_SPACING,
    _REQUIRED_ATTRS,
    _SPACING_RTOL,
    _UNIT_ALIASES,
    _UNIT_NORM_TOL,
    AXES,
    ELEMENT_VERTICES,
    GRID_DIMS,
    KINDS,
    SCHEMA_PHASE,
    SCHEMA_TAGGED,
    SCHEMAS,
    SEQUENCES,
    UNITS,
    VarSpec,
    newer_schema,
)
from harpx.errors import SchemaError

# the conventions are importable from here as well (module docstring)
__all__ = ["grid_step", "validate"]
__all__ += conventions.__all__


def validate(ds: xr.Dataset, kind: str | None = None) -> None:
    """Check a dataset against the harpx conventions (the module docstring lists them).

    Every problem found is collected; if there is any, one :class:`~harpx.errors.SchemaError`
    lists them all, one per line (also available as ``err.problems``).

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset to check.
    kind : {"tagged", "phase", "tracked"} or None, default None
        Schema to check against. None reads it from ``ds.attrs["harpx_schema"]``. The full
        names ``"tagged/1"`` etc. are accepted too.

    Raises
    ------
    SchemaError
        If the dataset breaks any convention: missing or misordered dims, missing
        coordinates or ``units``/``long_name`` attributes, unevenly spaced or decreasing
        ``z``/``y``/``x``, non-finite image or phase values, tag directions that are not unit
        vectors, tag frequencies above the Nyquist limit of their in-plane sampling, a tag
        direction along its own ``slice_axis``, a bad ``sequence``, a ``mask`` that is not
        boolean, phases outside [-π, π) or negative magnitudes.
    ValueError
        If ``kind`` is not one of the known kinds.

    Notes
    -----
    Value checks (non-finite values, phase range, negative magnitudes, cell indices) run only
    on variables held in memory as numpy arrays. Dask-backed variables are checked for
    structure (dims, dtype, attrs) only, so validating a lazy dataset never computes it.
    Coordinates are always loaded (they are small).

    The Nyquist check requires, for every tag ``t`` and every in-plane axis ``a`` (an axis
    other than ``slice_axis[t]`` with more than one sample),

    .. math:: f_t \\, |d_{t,a}| \\le \\frac{1}{2 \\Delta_a}.

    Examples
    --------
    >>> ds = xr.Dataset(attrs={"harpx_schema": "tagged/1", "sequence": "SPAMM"})
    >>> try:
    ...     validate(ds)
    ... except harpx.SchemaError as err:
    ...     print(err.problems[0])
    missing data variable 'image' with dims ('tag', 'time', 'z', 'y', 'x')
    """
    if not isinstance(ds, xr.Dataset):
        raise TypeError(
            f"validate(ds) needs an xarray.Dataset, got {type(ds).__name__!r}; for a "
            "DataArray use da.to_dataset(), for a file harpx.open_dataset(path)"
        )
    schema = _resolve_kind(ds, kind)
    problems: list[str] = []
    attr_schema = ds.attrs.get("harpx_schema")
    if attr_schema is None:
        problems.append(
            f"missing dataset attribute 'harpx_schema'; set ds.attrs['harpx_schema'] = {schema!r}"
        )
    elif not isinstance(attr_schema, str) or attr_schema != schema:
        newer = newer_schema(attr_schema)
        problems.append(
            f"dataset attribute 'harpx_schema' is {attr_schema!r} but {schema!r} was expected"
            + (f": {newer}" if newer else "")
        )
    for attr in _REQUIRED_ATTRS[schema]:
        if attr not in ds.attrs:
            problems.append(f"missing dataset attribute {attr!r} required by {schema!r}")
    sequence = ds.attrs.get("sequence")
    if "sequence" in ds.attrs and not (isinstance(sequence, str) and sequence in SEQUENCES):
        problems.append(
            f"dataset attribute 'sequence' is {sequence!r}; expected one of {sorted(SEQUENCES)} "
            "(a single string)"
        )
    if schema == SCHEMA_PHASE:
        _check_filter_attrs(ds, problems)

    specs = SCHEMAS[schema]
    checks: list[tuple[str, Any]] = [
        ("layout", lambda: _check_layout(ds, specs, problems)),
        ("dtypes", lambda: _check_dtypes(ds, problems)),
        ("attributes", lambda: _check_attrs(ds, problems)),
        ("sizes", lambda: _check_sizes(ds, specs, problems)),
    ]
    if "axis" in ds.variables and "axis" in specs:
        checks.append(("axis", lambda: _check_axis(ds, problems)))
    for dim in GRID_DIMS:
        if dim in ds.coords:
            checks.append((dim, lambda dim=dim: _check_grid_coord(ds, dim, problems)))
    if "time" in ds.coords:
        checks.append(("time", lambda: _check_time(ds, problems)))
    if schema in (SCHEMA_TAGGED, SCHEMA_PHASE):
        checks.append(("tags", lambda: _check_tags(ds, problems)))
        if "mask" in ds.variables and ds["mask"].dtype != bool:
            problems.append(
                f"'mask' has dtype {str(ds['mask'].dtype)!r}; expected bool "
                "(convert with ds['mask'] = ds['mask'].astype(bool))"
            )
        value_vars = ("image",) if schema == SCHEMA_TAGGED else ("phase", "magnitude")
        for name in value_vars:
            if name in ds.variables:
                checks.append((name, lambda name=name: _check_finite(ds, name, problems)))
        if schema == SCHEMA_PHASE:
            checks.append(("phase values", lambda: _check_phase_values(ds, problems)))
        if "body" in ds.variables:
            checks.append(("body", lambda: _check_range(ds, "body", 0.0, 1.0, problems)))
        if "slice_thickness" in ds.variables or "slice_position" in ds.variables:
            checks.append(("slice geometry", lambda: _check_slice_geometry(ds, problems)))
    else:
        checks.append(("tracked", lambda: _check_tracked(ds, problems)))
    for what, check in checks:
        try:
            check()
        except Exception as exc:  # a malformed value must not hide the problems found so far
            problems.append(
                f"could not check the {what} of the dataset ({type(exc).__name__}: {exc}); "
                "fix the problems above first"
            )
    if problems:
        raise SchemaError(problems)


def _check_filter_attrs(ds: xr.Dataset, problems: list[str]) -> None:
    """``upsample`` a positive integer, ``radius`` a positive finite number."""
    for name, integer in (("upsample", True), ("radius", False)):
        if name not in ds.attrs:
            continue
        value = ds.attrs[name]
        number = isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
        ok = number and np.isfinite(value) and value > 0
        if ok and integer:
            ok = float(value) == int(value)
        if not ok:
            kind = "a positive integer" if integer else "a positive finite number"
            problems.append(
                f"dataset attribute {name!r} is {value!r}; expected {kind} (the filter "
                "setting extract_phase used)"
            )


def _check_sizes(ds: xr.Dataset, specs: Mapping[str, VarSpec], problems: list[str]) -> None:
    """Every dim of a schema variable must have at least one entry.

    ``cell`` and ``vertex`` may be empty: a point cloud (conventional HARP) has no cells.
    """
    empty = sorted(
        {str(d) for name in specs if name in ds.variables for d in ds.variables[name].dims}
        & {str(d) for d, n in ds.sizes.items() if n == 0} - {"cell", "vertex"}
    )
    for dim in empty:
        problems.append(
            f"dimension {dim!r} has length 0; the dataset holds no data along it (check the "
            "selection or the source files)"
        )


def _resolve_kind(ds: xr.Dataset, kind: str | None) -> str:
    if kind is None:
        attr = ds.attrs.get("harpx_schema")
        if attr is None:
            raise SchemaError(
                "dataset has no attribute 'harpx_schema', so its kind is unknown; pass "
                "kind='tagged' | 'phase' | 'tracked' or set ds.attrs['harpx_schema'] "
                "(e.g. 'tagged/1')"
            )
        if not isinstance(attr, str) or attr not in SCHEMAS:
            newer = newer_schema(attr)
            raise SchemaError(
                f"dataset attribute 'harpx_schema' is {attr!r}; "
                + (newer if newer else f"known schemas: {sorted(SCHEMAS)}")
            )
        return str(attr)
    if not isinstance(kind, str):
        raise TypeError(f"kind={kind!r} must be a str, one of {sorted(KINDS)}")
    if kind in KINDS:
        return KINDS[kind]
    if kind in SCHEMAS:
        return kind
    raise ValueError(f"kind={kind!r} is not a harpx schema; expected one of {sorted(KINDS)}")


_NUMERIC = (
    "image",
    "phase",
    "magnitude",
    "displacement_true",
    "body",
    "tag_direction",
    "tag_frequency",
    "points",
    "displacement",
    "green_strain",
    "fiber_stretch",
)


def _check_dtypes(ds: xr.Dataset, problems: list[str]) -> None:
    for name in _NUMERIC:
        if name in ds.variables and ds.variables[name].dtype.kind not in "fiu":
            problems.append(
                f"{name!r} has dtype {str(ds.variables[name].dtype)!r}; expected real numbers; "
                f"convert with ds[{name!r}] = ds[{name!r}].astype(float)"
            )


def _check_layout(ds: xr.Dataset, specs: Mapping[str, VarSpec], problems: list[str]) -> None:
    for name, spec in specs.items():
        if name not in ds.variables:
            if spec.required:
                what = "coordinate" if spec.coord else "data variable"
                problems.append(f"missing {what} {name!r} with dims {spec.dims}")
            continue
        var = ds.variables[name]
        if var.dims != spec.dims:
            missing = [d for d in spec.dims if d not in var.dims]
            extra = [d for d in var.dims if d not in spec.dims]
            if missing or extra:
                hint = f"missing {missing}" if missing else ""
                hint += ("; " if hint and extra else "") + (f"unexpected {extra}" if extra else "")
                problems.append(f"{name!r} has dims {var.dims}; expected {spec.dims} ({hint})")
            else:
                problems.append(
                    f"{name!r} has dims {var.dims}; expected order {spec.dims}; fix with "
                    f"ds[{name!r}] = ds[{name!r}].transpose{spec.dims}"
                )
        if spec.coord is True and name not in ds.coords:
            problems.append(
                f"{name!r} is a data variable but must be a coordinate; fix with "
                f"ds = ds.set_coords({name!r})"
            )
        elif spec.coord is False and name in ds.coords:
            problems.append(
                f"{name!r} is a coordinate but must be a data variable; fix with "
                f"ds = ds.reset_coords({name!r})"
            )


def _check_attrs(ds: xr.Dataset, problems: list[str]) -> None:
    for name, var in ds.variables.items():
        fix = _attrs_fix(name)
        if "long_name" not in var.attrs:
            problems.append(f"{name!r} has no 'long_name' attribute; {fix}")
        if var.dtype.kind in "OSU":
            continue
        units = var.attrs.get("units")
        if units is None:
            problems.append(f"{name!r} has no 'units' attribute; {fix}")
            continue
        expected = UNITS.get(str(name))
        aliases = _UNIT_ALIASES.get(expected or "")
        if aliases is not None and str(units) not in aliases:
            problems.append(
                f"{name!r} has units {units!r}; harpx expects {expected!r} "
                "(convert the values and set the units attribute)"
            )


def _attrs_fix(name: Hashable) -> str:
    if str(name) in UNITS:
        return f"set ds[{name!r}].attrs.update(harpx.schema.standard_attrs({name!r}))"
    return f"set ds[{name!r}].attrs['units'] and ['long_name']"


def _check_axis(ds: xr.Dataset, problems: list[str]) -> None:
    values = [str(v) for v in np.asarray(ds["axis"].values).ravel()]
    if tuple(values) != AXES:
        problems.append(f"coordinate 'axis' is {values!r}; expected {list(AXES)!r}")


def _check_grid_coord(ds: xr.Dataset, dim: str, problems: list[str]) -> None:
    values = np.asarray(ds[dim].values)
    if values.dtype.kind not in "fiu":
        problems.append(f"coordinate {dim!r} has dtype {str(values.dtype)!r}; expected float mm")
        return
    values = values.astype(np.float64)
    if not np.all(np.isfinite(values)):
        problems.append(f"coordinate {dim!r} has non-finite values; expected voxel centres in mm")
        return
    if values.size < 2:
        return
    steps = np.diff(values)
    if np.any(steps <= 0):
        first = int(np.argmax(steps <= 0))
        problems.append(
            f"coordinate {dim!r} is not increasing (step {steps[first]:.6g} mm at index "
            f"{first}); sort with ds.sortby({dim!r}) or flip the axis"
        )
        return
    mean_step = (values[-1] - values[0]) / (values.size - 1)
    if mean_step < _MIN_SPACING:
        problems.append(
            f"coordinate {dim!r} has a spacing of {mean_step:.3g} mm, below the "
            f"{_MIN_SPACING:g} mm of any MRI voxel: are the coordinates in metres labelled "
            f"mm? convert with ds = ds.assign_coords({dim}=ds[{dim!r}] * 1000) (and the tag "
            "frequencies / 1000)"
        )
        return
    ideal = values[0] + mean_step * np.arange(values.size)
    deviation = float(np.max(np.abs(values - ideal)))
    if deviation > _SPACING_RTOL * mean_step:
        problems.append(
            f"coordinate {dim!r} is not evenly spaced (max deviation {deviation:.3g} mm > "
            f"{_SPACING_RTOL:g} of d{dim}={mean_step:.4g} mm); resample with "
            f"ds.interp({dim}=np.linspace(...))"
        )


def _check_time(ds: xr.Dataset, problems: list[str]) -> None:
    values = np.asarray(ds["time"].values)
    if values.dtype.kind not in "fiu":
        problems.append(
            f"coordinate 'time' has dtype {str(values.dtype)!r}; expected float ms after tagging"
        )
        return
    if not np.all(np.isfinite(values)):
        bad = np.flatnonzero(~np.isfinite(values))
        problems.append(
            f"coordinate 'time' has {bad.size} non-finite values (NaN/inf) at indices "
            f"{bad[:10].tolist()}; expected finite ms after tagging"
        )
        return
    if values.size > 1 and np.any(np.diff(values.astype(np.float64)) <= 0):
        problems.append("coordinate 'time' is not strictly increasing; sort with ds.sortby('time')")


def grid_step(ds: xr.Dataset | xr.DataArray, dim: str) -> float | None:
    """Mean step of a grid coordinate, mm (or the coordinate's unit).

    The one place harpx reads a grid's voxel spacing from its coordinates.

    Parameters
    ----------
    ds : xarray.Dataset or xarray.DataArray
        Data with the coordinate ``dim`` (e.g. ``"x"``).
    dim : str
        The grid dimension.

    Returns
    -------
    float or None
        ``(last - first) / (n - 1)``; None where the coordinate is missing or has fewer
        than two values (no step to speak of).
    """
    if dim not in ds.coords or ds.sizes.get(dim, 0) < 2:
        return None
    values = np.asarray(ds[dim].values, dtype=np.float64)
    return float((values[-1] - values[0]) / (values.size - 1))


def _check_slice_geometry(ds: xr.Dataset, problems: list[str]) -> None:
    """``slice_thickness`` and ``slice_position`` together; thickness positive or NaN;
    positions increasing, NaN only after the last slice of a tag."""
    if ("slice_thickness" in ds.variables) != ("slice_position" in ds.variables):
        problems.append(
            "'slice_thickness' and 'slice_position' come together (either alone cannot "
            "place the slabs); add the other or drop both"
        )
        return
    thickness = np.asarray(ds["slice_thickness"].values, dtype=np.float64)
    bad = np.isfinite(thickness) & ~(thickness > 0) | np.isinf(thickness)
    if bad.any():
        problems.append(
            f"'slice_thickness' has values {thickness[bad].tolist()}; expected positive mm "
            "(NaN where unknown)"
        )
    positions = np.asarray(ds["slice_position"].transpose("tag", ...).values, np.float64)
    known = np.isfinite(positions)
    count = known.sum(axis=1)
    padded = known == (np.arange(positions.shape[1])[None, :] < count[:, None])
    steps = np.diff(positions, axis=1)  # NaN where padding starts: not a decrease
    decreasing = np.zeros(steps.shape, dtype=bool)
    np.less_equal(steps, 0.0, out=decreasing, where=known[:, 1:])
    if not padded.all() or decreasing.any():
        problems.append(
            "'slice_position' must hold each tag's slice centres increasing (mm), NaN-padded "
            "after the last"
        )


def _check_tags(ds: xr.Dataset, problems: list[str]) -> None:
    if "tag" not in ds.coords:
        return
    tags = [str(t) for t in np.asarray(ds["tag"].values).ravel()]
    if len(set(tags)) != len(tags):
        problems.append(f"coordinate 'tag' has duplicate labels {tags!r}; labels must be unique")
    raw = np.asarray(ds["tag"].values).ravel()
    if ds["tag"].dtype.kind not in "OU" or not all(isinstance(t, str) for t in raw):
        problems.append(
            f"coordinate 'tag' has dtype {str(ds['tag'].dtype)!r} (labels {tags!r}); expected "
            "str labels such as 'x', 'y', 'z'"
        )
    have_dir = "tag_direction" in ds.coords and ds["tag_direction"].dims == ("tag", "axis")
    have_dir = have_dir and ds.sizes.get("axis") == 3
    have_dir = have_dir and ds["tag_direction"].dtype.kind in "fiu"  # else _check_dtypes says
    direction = np.asarray(ds["tag_direction"].values, dtype=np.float64) if have_dir else None
    freq = None
    if (
        "tag_frequency" in ds.coords
        and ds["tag_frequency"].dims == ("tag",)
        and ds["tag_frequency"].dtype.kind in "fiu"
    ):
        freq = np.asarray(ds["tag_frequency"].values, dtype=np.float64)
    slice_axes: list[str] | None = None
    if "slice_axis" in ds.coords and ds["slice_axis"].dims == ("tag",):
        slice_axes = [str(s) for s in np.asarray(ds["slice_axis"].values).ravel()]
    for i, tag in enumerate(tags):
        d = direction[i] if direction is not None else None
        if d is not None:
            norm = float(np.linalg.norm(d))
            if not np.isfinite(norm) or abs(norm - 1.0) > _UNIT_NORM_TOL:
                problems.append(
                    f"tag_direction of tag {tag!r} has norm {norm:.6g}; expected a unit vector "
                    "(divide by its norm)"
                )
                d = None
        f = freq[i] if freq is not None else None
        if f is not None and not (np.isfinite(f) and f > 0):
            problems.append(
                f"tag_frequency of tag {tag!r} is {float(f)!r}; expected a positive frequency "
                "in cycles/mm"
            )
            f = None
        s = slice_axes[i] if slice_axes is not None else None
        if s is not None and s not in AXES:
            problems.append(f"slice_axis of tag {tag!r} is {s!r}; expected one of {list(AXES)!r}")
            s = None
        if d is not None and s is not None and abs(d[AXES.index(s)]) > 0.5:
            problems.append(
                f"tag {tag!r} has direction {np.round(d, 4).tolist()} mostly along its "
                f"slice_axis {s!r}; tags must lie in the acquisition plane (choose a slice_axis "
                "normal to the tag direction)"
            )
        if d is None or f is None:
            continue
        for a, axis in enumerate(AXES):
            if axis == s:
                continue
            step = grid_step(ds, axis)
            if step is None or step <= 0:  # a decreasing axis has its own problem line
                continue
            component = float(f * abs(d[a]))
            limit = 1.0 / (2.0 * step)
            if component > limit:
                problems.append(
                    f"tag_frequency of tag {tag!r} is above the Nyquist limit along {axis!r}: "
                    f"{f:.4g} cycles/mm x |d_{axis}|={abs(d[a]):.3g} gives {component:.4g} "
                    f"cycles/mm > 1/(2 d{axis}) = {limit:.4g} cycles/mm; use a longer tag "
                    f"period or a finer {axis!r} spacing"
                )


def _numpy_data(var: xr.Variable) -> np.ndarray | None:
    """The variable's values if held in memory as a numpy array, else None (dask: skip)."""
    data: Any = var.data
    if isinstance(data, np.ndarray):
        return data
    return None


def _check_finite(ds: xr.Dataset, name: str, problems: list[str]) -> None:
    var = ds.variables[name]
    data = _numpy_data(var)
    if data is None or data.dtype.kind not in "fc":
        return
    # NaN and inf show in the extremes: two streaming passes instead of a mask of every
    # value in the common, all-finite case
    if data.dtype.kind == "f" and data.size and np.isfinite(data.min()) and np.isfinite(data.max()):
        return
    finite = np.isfinite(data)
    if finite.all():
        return
    bad = ~finite
    first = np.unravel_index(int(np.argmax(bad)), data.shape)
    where = ", ".join(f"{dim}={int(i)}" for dim, i in zip(var.dims, first, strict=True))
    problems.append(
        f"{name!r} has {int(bad.sum())} non-finite values (NaN/inf), first at index "
        f"{{{where}}}; fill or mask them (e.g. ds[{name!r}].fillna(0)) before processing"
    )


def _check_range(ds: xr.Dataset, name: str, low: float, high: float, problems: list[str]) -> None:
    data = _numpy_data(ds.variables[name])
    if data is None or data.dtype.kind not in "fiu" or data.size == 0:
        return
    finite = data[np.isfinite(data)]
    if finite.size and (finite.min() < low or finite.max() > high):
        problems.append(
            f"{name!r} has values in [{finite.min():.4g}, {finite.max():.4g}]; "
            f"expected [{low:g}, {high:g}]"
        )


def _finite_extremes(data: np.ndarray | None) -> tuple[float, float] | None:
    """Smallest and largest finite value of a float array (None if it has none).

    Two streaming passes when every value is finite (the common case); only arrays with
    NaN or inf pay for the compaction of their finite values.
    """
    if data is None or data.dtype.kind != "f" or data.size == 0:
        return None
    low, high = data.min(), data.max()
    if np.isfinite(low) and np.isfinite(high):
        return float(low), float(high)
    finite = data[np.isfinite(data)]
    return (float(finite.min()), float(finite.max())) if finite.size else None


def _check_phase_values(ds: xr.Dataset, problems: list[str]) -> None:
    if "phase" in ds.variables:
        data = _numpy_data(ds.variables["phase"])
        extremes = _finite_extremes(data)
        if extremes is not None:
            low, high = extremes
            if low < -np.pi or high >= np.pi:
                problems.append(
                    f"'phase' has values in [{low:.6g}, {high:.6g}]; expected the wrapped range "
                    "[-pi, pi) (wrap with np.angle(np.exp(1j * phase)) and map pi to -pi)"
                )
    if "magnitude" in ds.variables:
        data = _numpy_data(ds.variables["magnitude"])
        extremes = _finite_extremes(data)
        if data is not None and extremes is not None:
            low = extremes[0]
            if low < 0:
                count = int(np.sum(data < 0))
                problems.append(
                    f"'magnitude' has {count} negative values (min {low:.4g}); expected "
                    "|harmonic image| >= 0"
                )


def _check_tracked(ds: xr.Dataset, problems: list[str]) -> None:
    if "cells" in ds.variables:
        cells = ds.variables["cells"]
        element = cells.attrs.get("element")
        if element is None:
            problems.append(
                "'cells' has no 'element' attribute; set ds['cells'].attrs['element'] "
                f"to one of {sorted(ELEMENT_VERTICES)}"
            )
        elif element not in ELEMENT_VERTICES:
            problems.append(
                f"'cells' element {element!r} is unknown; expected one of "
                f"{sorted(ELEMENT_VERTICES)}"
            )
        elif cells.ndim == 2 and cells.shape[1] != ELEMENT_VERTICES[element]:
            problems.append(
                f"'cells' has {cells.shape[1]} vertices per cell but element {element!r} "
                f"needs {ELEMENT_VERTICES[element]}"
            )
        if cells.dtype.kind not in "iu":
            problems.append(f"'cells' has dtype {str(cells.dtype)!r}; expected integer node ids")
        else:
            data = _numpy_data(cells)
            nnode = ds.sizes.get("node")
            if data is not None and data.size and nnode is not None:
                if data.min() < 0 or data.max() >= nnode:
                    problems.append(
                        f"'cells' refers to node ids in [{data.min()}, {data.max()}] but there "
                        f"are {nnode} nodes"
                    )
    if "points" in ds.variables:
        _check_finite(ds, "points", problems)
    # a point cloud (conventional HARP) marks points without valid phase by NaN; a mesh
    # result must be finite everywhere (NaN there means the solver failed)
    mesh = "cells" in ds.variables and ds.variables["cells"].attrs.get("element") != "points"
    if mesh and "displacement" in ds.variables:
        _check_finite(ds, "displacement", problems)
    if "displacement_grid" in ds.variables:
        for dim in GRID_DIMS:
            if dim not in ds.coords:
                problems.append(
                    f"'displacement_grid' needs coordinate {dim!r} (voxel centres in mm)"
                )
