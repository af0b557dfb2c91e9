"""Dataset conventions of harpx (schema version 1): kinds, dimensions, units, names.

Three kinds of :class:`xarray.Dataset` flow through harpx. Each carries its kind in
``ds.attrs["harpx_schema"]``:

``tagged/1``
    ``image`` (tag, time, z, y, x): SPAMM magnitude or CSPAMM difference images. Optional
    ``mask`` (tag, z, y, x) bool: where that tag's acquisition has data, i.e. its field of
    view and slice slab. It is a fixed region of space, not the tissue: tissue moving
    within the acquisition stays inside it, so samplers test a point's *current* position
    against it (a short-axis stack's mask is its slab along z, whatever the tissue does).
    The tissue's support at the reference frame (time index 0) is the optional ``body``
    (z, y, x), a voxel-averaged density in [0, 1]; ``displacement_true`` (time, axis, z, y,
    x) is NaN outside it. :func:`harpx.imaging.stacks.tagged_dataset` builds one.
``phase/1``
    ``phase`` (tag, time, z, y, x) wrapped to [-π, π) and ``magnitude`` (same dims) >= 0;
    optional ``harmonic_noise`` (tag): the noise standard deviation of each tag's complex
    harmonic image, in the units of ``magnitude`` (:mod:`harpx.imaging.noise`), from which
    the tracker derives the noise floor of its residual; optional
    ``tag_frequency_measured`` (tag): the tag frequency in cycles/mm of the tag peak in the
    first frame's images, in each tag's acquisition plane, NaN where not measured
    (:mod:`harpx.imaging.tag_frequency`), and ``tag_peak_measured`` (tag, axis): that peak's
    frequency vector (x, y, z) in cycles/mm, whose direction is checked against
    ``tag_direction``.
    Optional slice geometry (either kind of image dataset): ``slice_thickness`` (tag), the
    thickness of each tag's slices along its ``slice_axis`` in mm (boxcar profile; NaN:
    unknown), and ``slice_position`` (tag, slice), their centres along it in mm,
    increasing, NaN-padded. :func:`harpx.imaging.harp.extract_phase` carries them into
    ``phase/1`` (:func:`harpx.imaging.harp.slice_geometry`); the blur correction models the
    slice profile with them and keeps its in-plane model without them.
``tracked/1``
    ``points`` (node, axis), ``cells`` (cell, vertex) and ``displacement`` (time, node, axis),
    plus optional strain and per-frame diagnostics (conventional HARP adds ``valid_points``
    (time), ``harmonic_snr`` (time, tag) and ``faded`` (time): the points with a valid phase,
    the lower quartile of the harmonic magnitude over its noise, and the frames whose tags
    faded to the noise).

Units are mm, ms, rad and kPa; grid coordinates ``z``, ``y``, ``x`` are voxel centres, evenly
spaced and increasing; every variable and coordinate carries ``long_name`` and (unless it holds
strings) ``units`` attributes. :func:`standard_attrs` gives the attributes harpx uses, so every
module labels its output the same way.

:func:`harpx.schema.validate` checks a dataset against these conventions and raises one
:class:`~harpx.errors.SchemaError` that lists every problem it found.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import xarray as xr

__all__ = [
    "AXES",
    "CF_AXES",
    "ELEMENT_VERTICES",
    "GRID_DIMS",
    "IMAGE_DIMS",
    "KINDS",
    "LONG_NAMES",
    "SCHEMAS",
    "SEQUENCES",
    "STANDARD_NAMES",
    "UNITS",
    "VarSpec",
    "fill_standard_attrs",
    "newer_schema",
    "standard_attrs",
]

SCHEMA_TAGGED = "tagged/1"
SCHEMA_PHASE = "phase/1"
SCHEMA_TRACKED = "tracked/1"

#: Short kind name → schema attribute value.
KINDS: dict[str, str] = {"tagged": SCHEMA_TAGGED, "phase": SCHEMA_PHASE, "tracked": SCHEMA_TRACKED}


def newer_schema(attr: Any) -> str:
    """A sentence if ``attr`` names a later version of a schema than this harpx reads.

    Parameters
    ----------
    attr : object
        A ``harpx_schema`` attribute value, e.g. ``"tracked/2"``.

    Returns
    -------
    str
        Empty unless ``attr`` is ``"<kind>/<n>"`` for a known kind with ``n`` above the
        version this harpx reads; then what that means and to upgrade harpx.

    Examples
    --------
    >>> newer_schema("tracked/1")
    ''
    >>> newer_schema("tracked/2")[:54]
    "'tracked/2' is a newer version of the tracked schema t"
    """
    if not isinstance(attr, str):
        return ""
    kind, _, version = attr.strip().partition("/")
    if kind not in KINDS or not version.isdigit():
        return ""
    known = KINDS[kind]
    if int(version) <= int(known.partition("/")[2]):
        return ""
    try:
        from importlib.metadata import version as installed

        release = f"harpx {installed('harpx')}"
    except Exception:  # not installed as a distribution (e.g. a source checkout on sys.path)
        release = "this harpx"
    return (
        f"{attr!r} is a newer version of the {kind} schema than {release} reads "
        f"({known!r}): the file was written by a newer harpx; upgrade harpx "
        "(pip install --upgrade harpx) to read it"
    )


#: Physical axes, in the column order of every (n, 3) point array.
AXES: tuple[str, str, str] = ("x", "y", "z")
#: Image grid dims (voxel centres, mm).
GRID_DIMS: tuple[str, str, str] = ("z", "y", "x")
#: Dims of ``image``, ``phase`` and ``magnitude``.
IMAGE_DIMS: tuple[str, ...] = ("tag", "time", *GRID_DIMS)
#: Allowed values of ``attrs["sequence"]``.
SEQUENCES: frozenset[str] = frozenset({"SPAMM", "CSPAMM"})
#: ``cells.attrs["element"]`` → vertices per cell (``"points"``: a point cloud without cells).
ELEMENT_VERTICES: dict[str, int] = {
    "points": 0,
    "tri3": 3,
    "quad4": 4,
    "tet4": 4,
    "tet10": 10,
    "wedge6": 6,
    "hex8": 8,
    "hex20": 20,
    "hex27": 27,
}
#: ``cells.attrs["element"]`` → corner vertices per cell (they come first in its vertex list).
ELEMENT_CORNERS: dict[str, int] = {
    "tri3": 3,
    "quad4": 4,
    "tet4": 4,
    "tet10": 4,
    "wedge6": 6,
    "hex8": 8,
    "hex20": 8,
    "hex27": 8,
}

#: Units harpx writes for each standard variable/coordinate ("1": dimensionless).
UNITS: dict[str, str] = {
    "x": "mm",
    "y": "mm",
    "z": "mm",
    "time": "ms",
    "tag": "1",
    "axis": "1",
    "tag_direction": "1",
    "tag_frequency": "1/mm",
    "slice_axis": "1",
    "slice_thickness": "mm",
    "slice_position": "mm",
    "image": "1",
    "mask": "1",
    "body": "1",
    "displacement_true": "mm",
    "phase": "rad",
    "magnitude": "1",
    "harmonic_noise": "1",
    "tag_frequency_measured": "1/mm",
    "tag_peak_measured": "1/mm",
    "points": "mm",
    "cells": "1",
    "region": "1",
    "fiber": "1",
    "displacement": "mm",
    "displacement_grid": "mm",
    "green_strain": "1",
    "fiber_stretch": "1",
    "epsilon": "rad",
    "epsilon_cell": "rad",
    "penalty": "1",
    "iterations": "1",
    "wall_time": "s",
    "stages": "1",
    "target_reached": "1",
    "plateau": "1",
    "converged": "1",
    "epsilon_target": "rad",
    "blur_correction": "rad",
    "epsilon_floor": "rad",
    "observed_directions": "1",
    "observed_fraction": "1",
    "valid_points": "1",
    "harmonic_snr": "1",
    "faded": "1",
}

#: Descriptive ``long_name`` of each standard variable/coordinate.
LONG_NAMES: dict[str, str] = {
    "x": "x position of voxel centre",
    "y": "y position of voxel centre",
    "z": "z position of voxel centre",
    "time": "time after tagging",
    "tag": "tag acquisition",
    "axis": "spatial axis",
    "tag_direction": "unit tag wave direction",
    "tag_frequency": "tag spatial frequency (cycles per mm)",
    "slice_axis": "axis normal to the acquisition slices",
    "slice_thickness": "slice thickness along the slice axis",
    "slice_position": "slice centre along the slice axis",
    "image": "tagged image intensity",
    "mask": "acquisition has data",
    "body": "tissue density fraction",
    "displacement_true": "true Lagrangian displacement",
    "phase": "harmonic phase",
    "magnitude": "harmonic image magnitude",
    "harmonic_noise": "noise standard deviation of the complex harmonic image",
    "tag_frequency_measured": "tag spatial frequency of the first frame's tag peak",
    "tag_peak_measured": "frequency vector of the first frame's tag peak in the tag's plane",
    "points": "reference position of node",
    "cells": "cell connectivity",
    "region": "region label of cell",
    "fiber": "unit fiber direction",
    "displacement": "displacement of node",
    "displacement_grid": "displacement resampled on the image grid",
    "green_strain": "Green-Lagrange strain",
    "fiber_stretch": "fiber stretch",
    "epsilon": "mean absolute wrapped phase residual",
    "epsilon_cell": "mean absolute wrapped phase residual per cell",
    "penalty": "tracking penalty relative to stiffness and tag wavenumber",
    "iterations": "iterations",
    "wall_time": "wall-clock time",
    "stages": "penalty stages or multiplier updates",
    "target_reached": (
        "tracking residual met its target or levelled off within the accepted plateau"
    ),
    "plateau": "tracking residual ended above its target, within the accepted plateau",
    "converged": "Gauss-Newton met its increment tolerance",
    "epsilon_target": "target tracking residual",
    "blur_correction": "mean phase removed as the band-pass blur of the tracked motion",
    "epsilon_floor": "noise floor of the tracking residual estimated from the images",
    "observed_directions": "number of independent directions the tags with data in the cell see",
    "observed_fraction": "fraction of each axis seen by the cell's tags, |P e_axis|^2",
    "valid_points": "tracked points with a valid harmonic phase in the frame",
    "harmonic_snr": "lower quartile of the harmonic magnitude at the tracked points over "
    "harmonic_noise",
    "faded": "some tag's harmonic_snr below the fade level",
}

#: CF ``standard_name`` of the standard variables that have one in the CF standard-name
#: table. Only ``time`` does: the image frame is a scanner frame, not a map projection, and
#: tissue displacement, harmonic phase and strain have no CF names.
STANDARD_NAMES: dict[str, str] = {"time": "time"}

#: CF ``axis`` attribute of the coordinate variables (Cartesian image axes and time).
CF_AXES: dict[str, str] = {"x": "X", "y": "Y", "z": "Z", "time": "T"}

# Accepted spellings of units for quantities whose unit matters for the numerics.
_UNIT_ALIASES: dict[str, frozenset[str]] = {
    "mm": frozenset({"mm", "millimeter", "millimetre", "millimeters", "millimetres"}),
    "ms": frozenset({"ms", "millisecond", "milliseconds", "msec"}),
    "rad": frozenset({"rad", "radian", "radians"}),
    "1/mm": frozenset({"1/mm", "mm-1", "mm^-1", "cycles/mm", "cycle/mm", "1 mm-1"}),
}


def standard_attrs(name: str) -> dict[str, str]:
    """``units``, ``long_name`` (and CF ``standard_name``, ``axis``) of a standard variable.

    Parameters
    ----------
    name : str
        Standard harpx variable or coordinate name (a key of :data:`UNITS`), e.g.
        ``"phase"`` or ``"x"``.

    Returns
    -------
    dict of str to str
        A fresh ``{"units": ..., "long_name": ...}`` dict (safe to modify), with
        ``standard_name`` (:data:`STANDARD_NAMES`) and ``axis`` (:data:`CF_AXES`) where the
        variable has them.

    Raises
    ------
    KeyError
        If ``name`` is not a standard harpx name.

    Examples
    --------
    >>> standard_attrs("tag_frequency")
    {'units': '1/mm', 'long_name': 'tag spatial frequency (cycles per mm)'}
    >>> standard_attrs("time")
    {'units': 'ms', 'long_name': 'time after tagging', 'standard_name': 'time', 'axis': 'T'}
    """
    if name not in UNITS:
        raise KeyError(f"{name!r} is not a standard harpx variable; known: {sorted(UNITS)}")
    attrs = {"units": UNITS[name], "long_name": LONG_NAMES[name]}
    if name in STANDARD_NAMES:
        attrs["standard_name"] = STANDARD_NAMES[name]
    if name in CF_AXES:
        attrs["axis"] = CF_AXES[name]
    return attrs


def fill_standard_attrs(ds: xr.Dataset) -> xr.Dataset:
    """Copy of ``ds`` with missing ``units``/``long_name`` of standard variables filled in.

    Existing attributes are kept; variables with non-standard names are left alone.

    Parameters
    ----------
    ds : xarray.Dataset
        Any dataset.

    Returns
    -------
    xarray.Dataset
        A shallow copy (data shared) with the standard attributes added.

    Raises
    ------
    TypeError
        If ``ds`` is not an xarray.Dataset.

    Examples
    --------
    >>> ds = fill_standard_attrs(xr.Dataset(coords={"x": [0.5, 1.5]}))
    >>> ds.x.attrs
    {'units': 'mm', 'long_name': 'x position of voxel centre', 'axis': 'X'}
    """
    if not isinstance(ds, xr.Dataset):
        raise TypeError(
            f"fill_standard_attrs needs an xarray.Dataset, got {type(ds).__name__!r} (for a "
            "DataArray use da.to_dataset())"
        )
    out = ds.copy(deep=False)
    for name, var in out.variables.items():
        if str(name) in UNITS:
            var.attrs = {**standard_attrs(str(name)), **var.attrs}
    return out


@dataclass(frozen=True)
class VarSpec:
    """Expected layout of one variable of a schema.

    Parameters
    ----------
    dims : tuple of str
        Expected dims, in order.
    required : bool
        Whether the variable must be present.
    coord : bool or None
        True: must be a coordinate; False: must be a data variable; None: either.
    """

    dims: tuple[str, ...]
    required: bool = True
    coord: bool | None = None


_COMMON_IMAGE_COORDS: dict[str, VarSpec] = {
    "tag": VarSpec(("tag",), coord=True),
    "axis": VarSpec(("axis",), coord=True),
    "tag_direction": VarSpec(("tag", "axis"), coord=True),
    "tag_frequency": VarSpec(("tag",), coord=True),
    "slice_axis": VarSpec(("tag",), coord=True),
    "time": VarSpec(("time",), coord=True),
    "z": VarSpec(("z",), coord=True),
    "y": VarSpec(("y",), coord=True),
    "x": VarSpec(("x",), coord=True),
    "mask": VarSpec(("tag", *GRID_DIMS), required=False),
    "displacement_true": VarSpec(("time", "axis", *GRID_DIMS), required=False),
    "body": VarSpec(GRID_DIMS, required=False),
    "slice_thickness": VarSpec(("tag",), required=False),
    "slice_position": VarSpec(("tag", "slice"), required=False),
}

#: Variable layout of each schema.
SCHEMAS: dict[str, dict[str, VarSpec]] = {
    SCHEMA_TAGGED: {"image": VarSpec(IMAGE_DIMS, coord=False), **_COMMON_IMAGE_COORDS},
    SCHEMA_PHASE: {
        "phase": VarSpec(IMAGE_DIMS, coord=False),
        "magnitude": VarSpec(IMAGE_DIMS, coord=False),
        "harmonic_noise": VarSpec(("tag",), required=False),
        "tag_frequency_measured": VarSpec(("tag",), required=False),
        "tag_peak_measured": VarSpec(("tag", "axis"), required=False),
        **_COMMON_IMAGE_COORDS,
    },
    SCHEMA_TRACKED: {
        "points": VarSpec(("node", "axis")),
        "cells": VarSpec(("cell", "vertex")),
        "displacement": VarSpec(("time", "node", "axis"), coord=False),
        "axis": VarSpec(("axis",), coord=True),
        "time": VarSpec(("time",), coord=True),
        "region": VarSpec(("cell",), required=False),
        "fiber": VarSpec(("cell", "axis"), required=False),
        "green_strain": VarSpec(("time", "cell", "i", "j"), required=False),
        "fiber_stretch": VarSpec(("time", "cell"), required=False),
        "epsilon": VarSpec(("time",), required=False),
        "epsilon_cell": VarSpec(("time", "cell"), required=False),
        "penalty": VarSpec(("time",), required=False),
        "iterations": VarSpec(("time",), required=False),
        "wall_time": VarSpec(("time",), required=False),
        "displacement_grid": VarSpec(("time", "axis", *GRID_DIMS), required=False),
        "valid_points": VarSpec(("time",), required=False),
        "harmonic_snr": VarSpec(("time", "tag"), required=False),
        "faded": VarSpec(("time",), required=False),
    },
}

#: Required dataset attributes per schema (besides ``harpx_schema``).
_REQUIRED_ATTRS: dict[str, tuple[str, ...]] = {
    SCHEMA_TAGGED: ("sequence",),
    SCHEMA_PHASE: ("sequence", "upsample", "radius"),
    SCHEMA_TRACKED: (),
}

# Relative tolerance on grid spacing (fraction of the mean spacing) and on unit-vector norms.
_SPACING_RTOL = 1e-3
_UNIT_NORM_TOL = 1e-6
# Smallest plausible voxel spacing, mm (10 µm): a grid in metres labelled mm is far below it.
_MIN_SPACING = 1e-2
