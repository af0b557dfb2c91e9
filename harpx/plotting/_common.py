"""Shared helpers of the figures: dataset-kind checks, new axes, slice titles and maps."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import matplotlib.pyplot as plt
import xarray as xr

from harpx.errors import SchemaError
from harpx.schema import KINDS

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

    Raises
    ------
    SchemaError
        If the dataset is not ``{kind}/1`` (the message names the kind it is) or has no
        {names}.
    """


def _map_doc(kind: str, *variables: str) -> Callable[[_F], _F]:
    """Append the shared ``ax``, Returns and Raises sections to a plot's docstring; the
    Raises entry names the dataset ``kind`` and the ``variables`` the plot needs."""
    quoted = [f"``{v}``" for v in variables]
    names = quoted[-1] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]

    def decorate(func: _F) -> _F:
        assert func.__doc__ is not None
        func.__doc__ = func.__doc__.rstrip() + _MAP_DOC_TAIL.format(kind=kind, names=names)
        return func

    return decorate


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


def _where(da: xr.DataArray) -> str:
    """Short title naming the frame and slice of a 2-D selection, e.g. ``t = 36 ms, z = 0.0 mm``."""
    parts = []
    if "tag" in da.coords and da["tag"].ndim == 0:
        parts.append(f"tag {da['tag'].item()}")
    if "time" in da.coords and da["time"].ndim == 0:
        parts.append(f"t = {float(da['time']):.0f} ms")
    if "z" in da.coords and da["z"].ndim == 0:
        parts.append(f"z = {float(da['z']):.1f} mm")
    return ", ".join(parts)


def _magnitude(da: xr.DataArray) -> xr.DataArray:
    return (da**2).sum("axis", skipna=False) ** 0.5


def _slice(da: xr.DataArray, time: float | None, z: float | None) -> xr.DataArray:
    if "time" in da.dims:
        da = da.sel(time=da.time[-1] if time is None else time, method="nearest")
    if "z" in da.dims:
        da = da.sel(z=da.z[da.sizes["z"] // 2] if z is None else z, method="nearest")
    return da


def _slice_map(da: xr.DataArray, title: str, ax: Any, *, label: str, **kwargs: Any) -> Any:
    """Draw a (y, x) slice with a colour bar ``label``, equal aspect and a short ``title``."""
    ax = _axes(ax, (4.8, 4.2))
    da.plot.pcolormesh(ax=ax, cbar_kwargs={"label": label}, **kwargs)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_aspect("equal")
    return ax
