"""Fibre stretch per region (muscle, AHA segment) of a tracked result, one row per region."""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from harpx.errors import SchemaError
from harpx.plotting._common import _axes, _map_doc, _nearest, _number, _require

__all__ = ["fiber_stretch_by_region", "region_groups"]


def region_groups(ds: xr.Dataset, regions: Sequence[str] | None = None) -> dict[str, Any]:
    """Cell indices of each named region of a tracked dataset, in the dataset's order.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset; its ``region`` (cell) labels are named by the
        ``flag_values`` and ``flag_meanings`` attributes (CF), in that order. Without
        ``region`` every cell belongs to one region, ``"body"``.
    regions : sequence of str, optional
        Names to keep, in the order to show them (default: every region with cells, in
        natural order of their names: ``aha_2`` before ``aha_10``).

    Returns
    -------
    dict of str to ndarray of int
        Region name -> cell indices (possibly empty for a region named in ``regions``).

    Raises
    ------
    SchemaError
        If ``flag_meanings`` and ``flag_values`` differ in length.
    ValueError
        If ``regions`` names a region the dataset does not have (the message lists them).
    """
    if "region" not in ds:
        groups = {"body": np.arange(ds.sizes["cell"])}
    else:
        labels = np.asarray(ds["region"].values).ravel()
        names = str(ds["region"].attrs.get("flag_meanings", "")).split()
        values = np.asarray(ds["region"].attrs.get("flag_values", np.arange(len(names)))).ravel()
        if len(names) != len(values):
            raise SchemaError(
                f"region: {len(names)} flag_meanings {names!r} for {len(values)} flag_values "
                f"{values.tolist()!r}"
            )
        if not names:  # labels without names
            values = np.unique(labels)
            names = [f"region {int(v)}" for v in values]
        groups = {n: np.flatnonzero(labels == v) for n, v in zip(names, values, strict=True)}
    if regions is None:
        return {n: groups[n] for n in sorted(groups, key=_natural) if groups[n].size}
    unknown = [r for r in regions if r not in groups]
    if unknown:
        raise ValueError(
            f"regions {unknown!r} are not in the dataset, whose regions are {list(groups)!r}"
        )
    return {r: groups[r] for r in regions}


def _natural(name: str) -> list[Any]:
    """Sort key of a name with numbers in it: ``aha_2`` < ``aha_10``."""
    return [(0, int(p), "") if p.isdigit() else (1, 0, p) for p in re.split(r"(\d+)", name) if p]


@_map_doc("tracked", "fiber_stretch", slices=False)
def fiber_stretch_by_region(
    ds: xr.Dataset,
    *,
    time: float | None = None,
    regions: Sequence[str] | None = None,
    ax: Any = None,
) -> Any:
    """Fibre stretch per region at one frame: one horizontal box per region.

    The regions are drawn top to bottom in natural order of their names (``aha_2`` before
    ``aha_10``) or in the order of ``regions``; each is labelled with its name and its
    number of cells. A box spans the quartiles of the cells' fibre stretch, the whiskers
    1.5 times the interquartile range, the white dot the volume-unweighted mean; a grey line
    marks stretch 1 (the fibre at its reference length). Regions without cells are left out
    (a region asked for in ``regions`` is named in the title instead of an empty row). The
    figure's height follows the number of regions.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with ``fiber_stretch`` (time, cell) and ``region`` (cell,
        ``flag_values``/``flag_meanings``); without ``region`` one box, ``"body"``.
    time : float, optional
        Frame time, ms (default: the last); the nearest frame is shown and named.
    regions : sequence of str, optional
        Regions to show, in this order (default: every region with cells).
    """
    plot = "fiber_stretch_by_region (ds.harp.plot.fiber_stretch)"
    _require(ds, "tracked", [], plot)
    if "fiber_stretch" not in ds:
        raise SchemaError(
            "fiber_stretch_by_region: the dataset has no 'fiber_stretch' (the tracked body had "
            "no fibres; give Body(..., fibers=...) to track fibre stretch)"
        )
    stretch = ds["fiber_stretch"]
    note = None
    if "time" in stretch.dims:
        if time is None:
            stretch = stretch.isel(time=-1)
        else:
            shown, note = _nearest(stretch["time"].values, "time", float(time), plot)
            stretch = stretch.sel(time=shown)
    values = np.asarray(stretch.values, dtype=np.float64)
    groups = region_groups(ds, regions)
    empty = [name for name, cells in groups.items() if cells.size == 0]
    shown_groups = {name: values[cells] for name, cells in groups.items() if cells.size}
    data = [v[np.isfinite(v)] for v in shown_groups.values()]
    n = len(shown_groups)
    ax = _axes(ax, (5.2, 1.3 + 0.34 * n))
    positions = np.arange(n)[::-1]  # the first region at the top
    ax.boxplot(
        data,
        positions=positions,
        orientation="horizontal",
        widths=0.6,
        showmeans=True,
        patch_artist=True,
        boxprops={"facecolor": "#c6dbef", "edgecolor": "0.2"},
        medianprops={"color": "0.1"},
        meanprops={"marker": "o", "markerfacecolor": "white", "markeredgecolor": "0.1",
                   "markersize": 4},
        flierprops={"marker": ".", "markersize": 3, "markeredgecolor": "0.5"},
    )  # fmt: skip
    ax.set_yticks(positions, [f"{name} ({v.size})" for name, v in shown_groups.items()])
    ax.set_ylim(-0.6, n - 0.4)
    ax.axvline(1.0, color="0.6", lw=0.8, zorder=0)
    ax.set_xlabel("fibre stretch (1: reference length)")
    ax.set_ylabel("region (cells)")
    when = f"t = {_number(float(stretch['time']))} ms" if "time" in stretch.coords else ""
    lines = [f"fibre stretch per region{', ' + when if when else ''}"]
    if note:
        lines.append(note)
    if empty:
        lines.append(f"no cells: {', '.join(empty)}")
    ax.set_title("\n".join(lines), fontsize=10)
    ax.grid(axis="x", color="0.9", lw=0.6)
    ax.set_axisbelow(True)
    return ax
