"""Shared helpers of the figures: dataset-kind checks, new axes, slice titles and maps."""

from __future__ import annotations

import inspect
import textwrap
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from harpx.errors import HarpxWarning, SchemaError, user_stacklevel
from harpx.schema import KINDS

# unit of each coordinate a slice is chosen along
_UNITS = {"z": "mm", "y": "mm", "x": "mm", "time": "ms"}

# what to do when a plot gets a dataset of another kind: (expected, actual) -> hint
_KIND_HINTS: dict[tuple[str, str], str] = {
    ("phase/1", "tagged/1"): "compute the phase first with ds.harp.phase()",
    ("tracked/1", "tagged/1"): "compute the phase with ds.harp.phase(), then ds.harp.track(body)",
    ("tracked/1", "phase/1"): "track it first with ds.harp.track(body)",
    ("tagged/1", "phase/1"): "plot a phase dataset with ds.harp.plot.phase()",
}

_F = TypeVar("_F", bound=Callable[..., Any])

# the end of each map's docstring: the ``ax`` parameter, Returns and Raises
_MAP_DOC_TAIL = """
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.

    Returns
    -------
    matplotlib.axes.Axes
        The axes drawn in (a new figure's when ``ax`` is None).

    Raises
    ------
    SchemaError
        If the dataset is not ``{kind}/1`` (the message names the kind it is) or has no
        {names}.
    """
# the ``time, z`` parameters of a map of the image grid that shows the nearest frame and slice
_SLICE_PARAM_DOC = """
    time, z : float, optional
        Frame time (ms, default the last) and slice position (mm, default the middle
        slice); the nearest frame and slice are shown and named in the title."""
# what a map that shows the nearest frame and slice adds to its Raises section
_SLICE_DOC_TAIL = """    ValueError
        If ``time`` or ``z`` is not a finite number.

    Warns
    -----
    HarpxWarning
        If the slice (frame) shown, the nearest to ``z`` (``time``), lies more than half
        the slice spacing (frame interval) away from it: ``z`` (``time``) is outside the
        data.
    """


def _map_doc(
    kind: str,
    *variables: str,
    slices: bool = True,
    slice_params: bool = False,
    value_errors: str = "",
) -> Callable[[_F], _F]:
    """Append the shared ``ax``, Returns and Raises sections to a plot's docstring; the
    Raises entry names the dataset ``kind`` and the ``variables`` the plot needs, and for a
    map that picks the nearest frame and slice (``slices``) what that raises and warns.
    ``slice_params``: also document ``ds`` (first: the ``kind`` dataset with ``variables``)
    and ``time`` and ``z`` as the image-grid maps take them (after the plot's own
    parameters, before ``ax``). ``value_errors``: what else raises ValueError (", or ...")."""
    quoted = [f"``{v}``" for v in variables]
    names = quoted[-1] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]

    def decorate(func: _F) -> _F:
        assert func.__doc__ is not None
        tail = _MAP_DOC_TAIL.format(kind=kind, names=names)
        if slices:
            tail = (
                tail.rstrip()
                + "\n"
                + _SLICE_DOC_TAIL.replace(
                    "not a finite number.", f"not a finite number{value_errors}."
                )
            )
        doc = _indented(func.__doc__).rstrip()
        # the plot's own Examples stay last (numpydoc order), after the shared sections
        doc, examples_header, examples = doc.partition("\n\n    Examples\n    --------\n")
        if slice_params:
            tail = _SLICE_PARAM_DOC + tail
            header = "\n    Parameters\n    ----------\n"
            assert header in doc
            ds = (
                f"    ds : xarray.Dataset\n        ``{kind}/1`` dataset with {', '.join(quoted)}.\n"
            )
            doc = doc.replace(header, header + ds, 1)
        doc += tail
        if examples:
            doc = doc.rstrip() + examples_header + examples + "\n    "
        func.__doc__ = doc
        return func

    return decorate


def _indented(doc: str) -> str:
    """``doc`` with every line after the first indented by four spaces, as in the source.

    Python 3.13 strips the common indentation of docstrings at compile time, 3.11 and 3.12
    keep it; the shared sections are written indented, so the plot's text is brought to the
    same form first.
    """
    first, _, rest = inspect.cleandoc(doc).partition("\n")
    return first + "\n" + textwrap.indent(rest, "    ", lambda line: bool(line.strip())) + "\n"


def _require(ds: xr.Dataset, kind: str, variables: Sequence[str], plot: str) -> None:
    """Raise :class:`SchemaError` unless ``ds`` is a ``kind`` dataset holding ``variables``."""
    if not isinstance(ds, xr.Dataset):
        raise SchemaError(
            f"{plot} draws a {KINDS[kind]!r} xarray.Dataset; got a {type(ds).__name__}"
        )
    expected = KINDS[kind]
    actual = ds.attrs.get("harpx_schema")
    if actual is not None and actual != expected:
        hint = _KIND_HINTS.get((expected, str(actual)))
        raise SchemaError(
            f"{plot} draws a {expected!r} dataset; got a {actual!r} dataset"
            + (f" ({hint})" if hint else "")
        )
    missing = [name for name in variables if name not in ds.variables]
    if missing:
        what = f"this {actual!r} dataset" if actual else "this dataset (no 'harpx_schema')"
        raise SchemaError(
            f"{plot} needs {', '.join(repr(m) for m in missing)} of a {expected!r} dataset; "
            f"{what} has no {' or '.join(repr(m) for m in missing)}"
        )


def _axes(ax: Any, figsize: tuple[float, float]) -> Any:
    """``ax``, or the axes of a new constrained-layout figure of ``figsize`` inches."""
    if ax is not None:
        return ax
    return plt.subplots(figsize=figsize, layout="constrained")[1]


def _number(value: float) -> str:
    """A coordinate as written in a title: at most 3 decimals, no trailing zeros."""
    text = f"{value:.3f}".rstrip("0").rstrip(".")
    return "0" if text == "-0" else text


def _where(da: xr.DataArray, notes: Sequence[str] = ()) -> str:
    """Short title naming the tag, frame and slice of a 2-D selection, e.g. ``t = 36 ms,
    z = 0.375 mm``, then ``notes`` (e.g. which slice was asked for)."""
    parts = []
    if "tag" in da.coords and da["tag"].ndim == 0:
        parts.append(f"tag {da['tag'].item()}")
    if "time" in da.coords and da["time"].ndim == 0:
        parts.append(f"t = {_number(float(da['time']))} ms")
    if "z" in da.coords and da["z"].ndim == 0:
        parts.append(f"z = {_number(float(da['z']))} mm")
    title = ", ".join(parts)
    return "\n".join([title, *notes]) if notes else title


def _magnitude(da: xr.DataArray) -> xr.DataArray:
    return (da**2).sum("axis", skipna=False) ** 0.5


def _nearest(coord: Any, dim: str, value: float, plot: str) -> tuple[float, str | None]:
    """The value of coordinate ``coord`` (1-D) nearest ``value``, and a note for the title
    when it is not ``value``. Warns (:class:`HarpxWarning`) when it lies more than half a
    spacing of the coordinate away (``value`` outside the data, or an uneven coordinate)."""
    values = np.asarray(coord, dtype=np.float64).ravel()
    if not np.isfinite(value):
        raise ValueError(f"{plot}: {dim} must be a finite number, got {value!r}")
    shown = float(values[int(np.argmin(np.abs(values - value)))])
    unit = _UNITS.get(dim, "")
    if np.isclose(shown, value, rtol=0.0, atol=1e-6 * max(1.0, abs(value))):
        return shown, None
    what = "frame" if dim == "time" else "slice"
    note = f"(nearest {what} to {dim} = {_number(value)} {unit})".replace(" )", ")")
    spacing = float(np.median(np.diff(np.sort(values)))) if values.size > 1 else np.nan
    if np.isfinite(spacing) and abs(shown - value) > 0.5 * spacing * (1.0 + 1e-6):
        warnings.warn(
            f"{plot}: there is no {dim} = {_number(value)} {unit}; showing the nearest, "
            f"{dim} = {_number(shown)} {unit} ({_number(abs(shown - value))} {unit} away, more "
            f"than half the spacing {_number(spacing)} {unit}; {dim} spans "
            f"{_number(values.min())} to {_number(values.max())} {unit})",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return shown, note


def _slice(
    da: xr.DataArray, time: float | None, z: float | None, plot: str = "plot"
) -> tuple[xr.DataArray, list[str]]:
    """The frame nearest ``time`` (default the last) and the slice nearest ``z`` (default
    the middle one) of ``da``, with title notes naming what was asked for when the shown
    frame or slice differs from it (see :func:`_nearest`)."""
    notes = []
    for dim, value, default in (("time", time, -1), ("z", z, None)):
        if dim not in da.dims:
            continue
        if value is None:
            index = da.sizes[dim] // 2 if default is None else default
            da = da.isel({dim: index})
            continue
        shown, note = _nearest(da[dim].values, dim, float(value), plot)
        da = da.sel({dim: shown})
        if note:
            notes.append(note)
    return da, notes


def _slice_map(da: xr.DataArray, title: str, ax: Any, *, label: str, **kwargs: Any) -> Any:
    """Draw a (y, x) slice with a colour bar ``label``, equal aspect and a short ``title``."""
    ax = _axes(ax, (4.8, 4.2))
    da.plot.pcolormesh(ax=ax, cbar_kwargs={"label": label}, **kwargs)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal")
    return ax
