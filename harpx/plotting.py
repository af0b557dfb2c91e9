"""Figures (matplotlib): slices of harpx datasets, displacement maps, error against run time.

The functions draw with :mod:`matplotlib.pyplot` and never select or switch the matplotlib
backend: in a notebook the figures show inline, in a script they go wherever the user's
backend sends them (``plt.show()``, ``fig.savefig``). New figures use constrained layout and
sizes that keep every title, label and colour bar inside the figure. Each function names
the dataset kind it draws; any other kind raises :class:`~harpx.errors.SchemaError` naming
the expected and the actual kind.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from harpx._typing import PathLike
from harpx.errors import SchemaError
from harpx.schema import KINDS

# what to do when a plot gets a dataset of another kind: (expected, actual) -> hint
_KIND_HINTS: dict[tuple[str, str], str] = {
    ("phase/1", "tagged/1"): "compute the phase first with ds.harp.phase()",
    ("tracked/1", "tagged/1"): "compute the phase with ds.harp.phase(), then ds.harp.track(body)",
    ("tracked/1", "phase/1"): "track it first with ds.harp.track(body)",
    ("tagged/1", "phase/1"): "plot a phase dataset with ds.harp.plot.phase()",
}


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


def displacement_maps(
    results: Mapping[str, xr.Dataset],
    truth: xr.Dataset,
    *,
    time: float,
    z: float | None = None,
    path: PathLike | None = None,
) -> Any:
    """Displacement magnitude and error maps on one slice, one column per method.

    Like the paper's Fig. 1 c/d: the top row shows ``|u|`` of each method at ``time`` on the
    slice nearest ``z``; the bottom row shows the error ``|u − u_true|`` against the truth.

    Parameters
    ----------
    results : mapping of str to xarray.Dataset
        Method name → ``tracked/1`` dataset with ``displacement_grid``.
    truth : xarray.Dataset
        Dataset with ``displacement_true``.
    time : float
        Frame time, ms (nearest frame).
    z : float, optional
        Slice position, mm (default: the middle slice).
    path : path-like, optional
        Write the figure here (PNG).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    SchemaError
        If the dataset is not ``tracked/1`` (the message names the kind it is) or has no
        ``displacement_grid`` (or ``truth`` has no ``displacement_true``).
    """
    if "displacement_true" not in truth.variables:
        raise SchemaError(
            "displacement_maps needs 'displacement_true' in truth (the images of a scene, "
            "e.g. scene.tagged); this dataset has none"
        )
    for name, ds in results.items():
        _require(ds, "tracked", ["displacement_grid"], f"displacement_maps (results[{name!r}])")
    true = truth["displacement_true"].sel(time=time, method="nearest")
    zsel = float(true.z[true.sizes["z"] // 2]) if z is None else z
    true = true.sel(z=zsel, method="nearest")
    ncol = len(results) + 1
    fig, axes = plt.subplots(
        2, ncol, figsize=(3.6 * ncol, 6.6), squeeze=False, layout="constrained"
    )
    vmax = float(np.nanmax(_magnitude(true)))
    extent = [float(true.x[0]), float(true.x[-1]), float(true.y[0]), float(true.y[-1])]
    axes[0, 0].imshow(_magnitude(true), origin="lower", extent=extent, vmin=0, vmax=vmax)
    axes[0, 0].set_title("truth: |u| (mm)", fontsize=9)
    axes[1, 0].axis("off")
    for col, (name, ds) in enumerate(results.items(), start=1):
        est = ds["displacement_grid"].sel(time=time, method="nearest")
        est = (
            est.interp(z=true.z, y=true.y, x=true.x)
            if est.sizes["x"] != true.sizes["x"]
            else est.sel(z=zsel, method="nearest")
        )
        mag = _magnitude(est)
        im = axes[0, col].imshow(mag, origin="lower", extent=extent, vmin=0, vmax=vmax)
        axes[0, col].set_title(f"{name}: |u| (mm)", fontsize=9)
        err = _magnitude(est - true.values)
        im2 = axes[1, col].imshow(
            err, origin="lower", extent=extent, vmin=0, vmax=2.0, cmap="magma"
        )
        axes[1, col].set_title(
            f"{name}: error (mm)\nslice mean {float(np.nanmean(err)):.2f}", fontsize=9
        )
    fig.colorbar(im, ax=axes[0, :].tolist(), shrink=0.8)
    fig.colorbar(im2, ax=axes[1, 1:].tolist(), shrink=0.8)
    fig.suptitle(f"t = {float(true.time):.0f} ms, z = {zsel:.1f} mm")
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def error_vs_runtime(rows: Sequence[Mapping[str, Any]], *, path: PathLike | None = None) -> Any:
    """Scatter of mean (and 95th percentile) error against wall time, one point per row.

    Parameters
    ----------
    rows : sequence of mappings
        Each with ``method`` (str), ``seconds`` (s), ``mean`` and ``p95`` (mm).
    path : path-like, optional
        Write the figure here (PNG).

    Returns
    -------
    matplotlib.figure.Figure
    """
    rows = list(rows)
    # the legend sits below the axes (one line per row) so it never hides a point
    fig, ax = plt.subplots(figsize=(6.5, 3.8 + 0.2 * len(rows)), layout="constrained")
    for row in rows:
        ax.errorbar(
            row["seconds"],
            row["mean"],
            yerr=[[0], [row["p95"] - row["mean"]]],
            fmt="o",
            capsize=3,
            label=row["method"],
        )
    ax.set_xscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("displacement error (mm): mean, bar to p95")
    ax.grid(alpha=0.3)
    if rows:
        fig.legend(fontsize=8, loc="outside lower center", ncol=1)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


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
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    SchemaError
        If the dataset is not ``tagged/1`` (the message names the kind it is) or has no
        ``image``.
    """
    _require(ds, "tagged", ["image"], "tag_image (ds.harp.plot.tag_image)")
    da = _slice(ds["image"].sel(tag=ds.tag.values[0] if tag is None else tag), time, z)
    return _slice_map(da, _where(da), ax, cmap="gray", label="intensity")


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
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    SchemaError
        If the dataset is not ``phase/1`` (the message names the kind it is) or has no
        ``phase``.
    """
    _require(ds, "phase", ["phase"], "phase_map (ds.harp.plot.phase)")
    da = _slice(ds["phase"].sel(tag=ds.tag.values[0] if tag is None else tag), time, z)
    return _slice_map(
        da, _where(da), ax, cmap="twilight", label="phase (rad)", vmin=-np.pi, vmax=np.pi
    )


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
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    SchemaError
        If the dataset is not ``tracked/1`` (the message names the kind it is) or has no
        ``displacement_grid``.
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
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    SchemaError
        If the dataset is not ``tracked/1`` (the message names the kind it is) or has no
        ``green_strain``, ``points`` or ``cells``.
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


def fiber_stretch_by_region(ds: xr.Dataset, *, time: float | None = None, ax: Any = None) -> Any:
    """Box plot of fibre stretch per region at one frame.

    Parameters
    ----------
    ds : xarray.Dataset
        ``tracked/1`` dataset with ``fiber_stretch`` and ``region`` (``flag_meanings``).
    time : float, optional
        Frame time, ms (default: the last).
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    SchemaError
        If the dataset is not ``tracked/1`` (the message names the kind it is) or has no
        ``fiber_stretch``.
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


def bullseye(
    values: xr.Dataset | xr.DataArray | Sequence[float],
    *,
    variable: str = "peak_strain",
    component: str = "circumferential",
    ax: Any = None,
    cmap: str = "RdBu_r",
    vmin: float | None = None,
    vmax: float | None = None,
    label: str | None = None,
    annotate: bool = True,
) -> Any:
    """AHA 17-segment bull's-eye plot of one value per segment.

    Rings from outside in: basal (1–6, 60° sectors), mid (7–12), apical (13–16, 90°
    sectors) and the apex (17) in the centre; segment 1 starts at 0° (east) and the
    numbers run counter-clockwise, as in :func:`harpx.cardiac.strain.aha_segments`.

    Parameters
    ----------
    values : xarray.Dataset, xarray.DataArray or sequence of 17 floats
        A dataset from :func:`harpx.cardiac.strain.cardiac_strain` (``variable`` and
        ``component`` select the value), a DataArray with a ``segment`` dim (1..17), or 17
        numbers.
    variable : str, default "peak_strain"
        Variable of a dataset.
    component : str, default "circumferential"
        ``component`` to select when the variable has one.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in.
    cmap : str, default "RdBu_r"
        Colour map.
    vmin, vmax : float, optional
        Colour limits (default symmetric about 0 over the finite values).
    label : str, optional
        Colour-bar label.
    annotate : bool, default True
        Write each segment's value in it.

    Returns
    -------
    matplotlib.axes.Axes

    Raises
    ------
    ValueError
        If there are not 17 values.
    """
    from matplotlib.patches import Wedge

    da: Any = values
    if isinstance(da, xr.Dataset):
        if variable not in da:
            raise ValueError(f"the dataset has no {variable!r}; run cardiac_strain first")
        da = da[variable]
    if isinstance(da, xr.DataArray):
        if "component" in da.dims:
            da = da.sel(component=component)
        if "time" in da.dims:
            raise ValueError("select one frame first (e.g. .isel(time=-1)): values have 'time'")
        label = label or str(da.attrs.get("long_name", variable))
    v = np.asarray(da, dtype=np.float64).ravel()
    if v.size != 17:
        raise ValueError(f"bullseye needs 17 segment values, got {v.size}")
    finite = v[np.isfinite(v)]
    bound = float(np.abs(finite).max()) if finite.size else 1.0
    lo = -bound if vmin is None else vmin
    hi = bound if vmax is None else vmax
    norm = matplotlib.colors.Normalize(lo, hi)
    colours = matplotlib.colormaps[cmap]
    ax = ax or plt.subplots(figsize=(4.6, 4))[1]
    rings = [(0.75, 1.0, range(0, 6), 60.0, 0.0), (0.5, 0.75, range(6, 12), 60.0, 0.0),
             (0.25, 0.5, range(12, 16), 90.0, -45.0)]  # fmt: skip
    for r0, r1, ids, width, start in rings:  # three rings of a few sectors
        for n, k in enumerate(ids):
            a0 = start + n * width
            colour = colours(norm(v[k])) if np.isfinite(v[k]) else "0.85"
            ax.add_patch(Wedge((0, 0), r1, a0, a0 + width, width=r1 - r0, fc=colour, ec="k"))
            if annotate:
                mid = np.deg2rad(a0 + width / 2)
                rm = 0.5 * (r0 + r1)
                ax.text(rm * np.cos(mid), rm * np.sin(mid), f"{v[k]:.3g}", ha="center",
                        va="center", fontsize=7)  # fmt: skip
    colour = colours(norm(v[16])) if np.isfinite(v[16]) else "0.85"
    ax.add_patch(Wedge((0, 0), 0.25, 0, 360, fc=colour, ec="k"))
    if annotate:
        ax.text(0, 0, f"{v[16]:.3g}", ha="center", va="center", fontsize=7)
    ax.set(xlim=(-1.05, 1.05), ylim=(-1.05, 1.05), aspect="equal")
    ax.axis("off")
    mappable = matplotlib.cm.ScalarMappable(norm=norm, cmap=colours)
    plt.colorbar(mappable, ax=ax, label=label or "", shrink=0.8)
    return ax


def opening_angle_view(result: Any, ax: Any = None, *, scale: float = 1.0) -> Any:
    """Top view of a cut ring before (grey) and after the cut (black).

    Parameters
    ----------
    result : OpeningAngle
        Output of :func:`harpx.physiology.cut.opening_angle`.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in (default: a new 4 × 4 in figure).
    scale : float, default 1
        Displacement magnification (dimensionless).

    Returns
    -------
    matplotlib.axes.Axes
    """
    if ax is None:
        _, ax = plt.subplots(figsize=(4, 4))
    ring = result.ring
    p0 = ring.nodes
    p1 = ring.nodes + scale * result.u.reshape(-1, 3)[: len(ring.nodes)]
    edges = ring.cells[:, [0, 1, 1, 2, 2, 3, 3, 0]].reshape(-1, 2)
    for pts, colour, lw in ((p0, "0.7", 0.6), (p1, "k", 0.8)):
        seg = pts[edges][:, :, :2]
        ax.plot(seg[:, :, 0].T, seg[:, :, 1].T, color=colour, lw=lw)
    for nodes, colour in zip(result.faces, ("tab:red", "tab:blue"), strict=True):
        ax.plot(p1[nodes, 0], p1[nodes, 1], ".", color=colour, ms=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    ax.set_title(f"opening angle {result.degrees:.1f}°")
    return ax


def plot_stretch_agreement(
    comparison: xr.Dataset,
    *,
    path: PathLike | None = None,
    truth: Mapping[str, float] | None = None,
) -> Any:
    """Tracked against simulated fibre stretch per muscle and per element (paper Fig. 3c).

    Parameters
    ----------
    comparison : xarray.Dataset
        Output of :func:`harpx.inverse.resimulate` with ``tracked=``.
    path : str or Path, optional
        Save the figure there (PNG, 150 dpi).
    truth : dict of str to float, optional
        True mean fibre stretch per region, drawn as a third bar.

    Returns
    -------
    matplotlib.figure.Figure
        Left: bars of the volume-weighted mean fibre strain λ − 1 per muscle in % (error
        bars: sd over the muscle's cells); right: element-by-element scatter of the stretch
        with the identity line.

    Raises
    ------
    ValueError
        If ``comparison`` has no tracked stretch.
    """
    if "stretch_tracked" not in comparison:
        raise ValueError(
            "'comparison' has no tracked stretch; run resimulate(..., tracked=tracked)"
        )
    from matplotlib.figure import Figure

    names = [str(n) for n in comparison["region"].values]
    fig = Figure(figsize=(10.0, 4.0), layout="constrained")
    ax, ax2 = fig.subplots(1, 2)
    x = np.arange(len(names))
    bars: list[tuple[str, Any, Any]] = [
        (
            "tracked (images)",
            comparison["stretch_tracked"].values,
            comparison["stretch_tracked_sd"].values,
        ),
        (
            "simulated (estimate)",
            comparison["stretch_simulated"].values,
            comparison["stretch_simulated_sd"].values,
        ),
    ]
    if truth:
        bars.append(("ground truth", np.array([truth.get(n, np.nan) for n in names]), None))
    width = 0.8 / len(bars)
    for k, (label, mean, sd) in enumerate(bars):  # two or three bar groups
        ax.bar(
            x + width * (k - (len(bars) - 1) / 2),
            100.0 * (mean - 1.0),
            width,
            yerr=None if sd is None else 100.0 * sd,
            capsize=3,
            label=label,
        )
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.set_xticks(x, names)
    ax.set_ylabel("mean fibre strain λ − 1 (%)")
    ax.set_title("fibre stretch per muscle")
    ax.legend(fontsize=8, loc="lower right")
    region_of_cell = comparison["region_label"].values
    tr = comparison["fiber_stretch_tracked"].values
    sim = comparison["fiber_stretch_simulated"].values
    for k, n in enumerate(names):  # one colour per muscle
        sel = region_of_cell == k
        ax2.scatter(tr[sel], sim[sel], s=8, label=n)
    both = np.concatenate([tr, sim])
    lim = (float(np.nanmin(both)) - 0.01, float(np.nanmax(both)) + 0.01)
    ax2.plot(lim, lim, color="0.3", lw=0.8)
    ax2.set_xlim(lim)
    ax2.set_ylim(lim)
    ax2.set_xlabel("tracked fibre stretch")
    ax2.set_ylabel("simulated fibre stretch")
    r = float(comparison["correlation_all"]) if "correlation_all" in comparison else np.nan
    ax2.set_title(f"per element (r = {r:.2f})")
    ax2.legend(fontsize=8, markerscale=2)
    if path is not None:
        fig.savefig(path, dpi=150)
    return fig
