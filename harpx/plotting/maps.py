"""One slice of a dataset: tag image, harmonic phase, displacement, strain, fibre stretch."""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr

from harpx.errors import SchemaError
from harpx.plotting._common import (
    _axes,
    _magnitude,
    _map_doc,
    _require,
    _slice,
    _slice_map,
    _where,
)


@_map_doc("tagged", "image")
def tag_image(
    ds: xr.Dataset,
    *,
    tag: str | None = None,
    time: float | None = None,
    z: float | None = None,
    ax: Any = None,
) -> Any:
    """One slice of a ``tagged/1`` image (default: first tag, last frame, middle slice).

    Parameters
    ----------
    ds : xarray.Dataset
        ``tagged/1`` dataset.
    tag : str, optional
        Tag label.
    time, z : float, optional
        Frame time (ms) and slice position (mm), nearest.
    """
    _require(ds, "tagged", ["image"], "tag_image (ds.harp.plot.tag_image)")
    da = _slice(ds["image"].sel(tag=ds.tag.values[0] if tag is None else tag), time, z)
    return _slice_map(da, _where(da), ax, cmap="gray", label="intensity")


@_map_doc("phase", "phase")
def phase_map(
    ds: xr.Dataset,
    *,
    tag: str | None = None,
    time: float | None = None,
    z: float | None = None,
    ax: Any = None,
) -> Any:
    """One slice of a ``phase/1`` harmonic phase (rad, cyclic colour map).

    Parameters
    ----------
    ds : xarray.Dataset
        ``phase/1`` dataset.
    tag : str, optional
        Tag label (default: the first).
    time, z : float, optional
        Frame time (ms) and slice position (mm), nearest.
    """
    _require(ds, "phase", ["phase"], "phase_map (ds.harp.plot.phase)")
    da = _slice(ds["phase"].sel(tag=ds.tag.values[0] if tag is None else tag), time, z)
    return _slice_map(
        da, _where(da), ax, cmap="twilight", label="phase (rad)", vmin=-np.pi, vmax=np.pi
    )


@_map_doc("tracked", "displacement_grid")
def displacement_map(
    ds: xr.Dataset,
    *,
    component: str | None = None,
    time: float | None = None,
    z: float | None = None,
    ax: Any = None,
) -> Any:
    """Tracked displacement on one slice of the image grid (magnitude or one component, mm).

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with ``displacement_grid``.
    component : {"x", "y", "z"}, optional
        Component to show; default the magnitude.
    time, z : float, optional
        Frame time (ms) and slice position (mm), nearest.
    """
    _require(ds, "tracked", ["displacement_grid"], "displacement_map (ds.harp.plot.displacement)")
    da = _slice(ds["displacement_grid"], time, z)
    title = _where(da)
    da = _magnitude(da) if component is None else da.sel(axis=component)
    return _slice_map(
        da,
        title,
        ax,
        cmap="viridis" if component is None else "RdBu_r",
        label=f"u{'' if component is None else '_' + component} (mm)",
    )


@_map_doc("tracked", "green_strain", "points", "cells")
def strain_map(
    ds: xr.Dataset,
    *,
    i: int = 0,
    j: int = 0,
    time: float | None = None,
    z: float | None = None,
    ax: Any = None,
) -> Any:
    """Green–Lagrange strain E_ij per cell, at the cell centres near one slice.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with ``green_strain`` and a mesh (``points``, ``cells``).
    i, j : int, default 0
        Strain component (0 = x, 1 = y, 2 = z).
    time, z : float, optional
        Frame time (ms) and slice position (mm); cells whose centre lies within half the
        typical cell height of ``z`` are shown.
    """
    _require(ds, "tracked", ["green_strain", "points", "cells"], "strain_map (ds.harp.plot.strain)")
    centres = ds["points"].values[ds["cells"].values[:, :8]].mean(axis=1)
    strain = ds["green_strain"].sel(time=ds.time[-1] if time is None else time, method="nearest")
    values = strain.values[:, i, j]
    zc = centres[:, 2]
    z = float(np.median(zc)) if z is None else z
    height = np.ptp(ds["points"].values[ds["cells"].values[:, :8], 2], axis=1).mean()
    near = np.abs(zc - z) <= height / 2
    ax = _axes(ax, (4.8, 4.2))
    sc = ax.scatter(centres[near, 0], centres[near, 1], c=values[near], cmap="RdBu_r", s=12)
    ax.figure.colorbar(sc, ax=ax, label=f"E_{'xyz'[i]}{'xyz'[j]}")
    ax.set(xlabel="x (mm)", ylabel="y (mm)", aspect="equal")
    ax.set_title(f"t = {float(strain.time):.0f} ms, z = {z:.1f} mm", fontsize=10)
    return ax


@_map_doc("tracked", "fiber_stretch")
def fiber_stretch_by_region(ds: xr.Dataset, *, time: float | None = None, ax: Any = None) -> Any:
    """Box plot of fibre stretch per region at one frame.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with ``fiber_stretch`` and ``region`` (``flag_meanings``).
    time : float, optional
        Frame time, ms (default: the last).
    """
    _require(ds, "tracked", [], "fiber_stretch_by_region (ds.harp.plot.fiber_stretch)")
    if "fiber_stretch" not in ds:
        raise SchemaError(
            "fiber_stretch_by_region: the dataset has no 'fiber_stretch' (the tracked body had "
            "no fibres; give Body(..., fibers=...) to track fibre stretch)"
        )
    stretch = ds["fiber_stretch"].sel(time=ds.time[-1] if time is None else time, method="nearest")
    if "region" in ds:
        names = ds["region"].attrs.get("flag_meanings", "").split()
        labels = ds["region"].values
    else:
        names, labels = ["body"], np.zeros(ds.sizes["cell"], dtype=int)
    groups = [stretch.values[labels == k] for k in range(len(names))]
    ax = _axes(ax, (max(1.2 * len(names) + 2, 4.0), 4.0))
    ax.boxplot(groups, tick_labels=names)
    ax.axhline(1.0, color="0.6", lw=0.8)
    ax.set_ylabel("fibre stretch")
    ax.set_title(f"t = {float(stretch.time):.0f} ms", fontsize=10)
    return ax
