"""Comparison figures of the benchmarks and papers: methods against truth, run time, stretch."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib.pyplot as plt
import numpy as np
import xarray as xr

from harpx._typing import PathLike
from harpx.errors import SchemaError
from harpx.plotting._common import _magnitude, _nearest, _number, _require

__all__ = [
    "displacement_maps",
    "error_vs_runtime",
    "opening_angle_view",
    "plot_stretch_agreement",
    "run_seconds",
]

# a result's frame matches the truth's when within this fraction of the frame interval
_FRAME_TOLERANCE = 1e-3


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
    Every panel shows the same frame and slice, named in the title (with the time or slice
    asked for when the truth's nearest is another); a result on another grid is
    interpolated to the truth's slice. Each row has one colour scale from 0 to its largest
    value, so no panel saturates.

    Parameters
    ----------
    results : mapping of str to xarray.Dataset
        Method name → ``tracked/1`` dataset with ``displacement_grid``.
    truth : xarray.Dataset
        Dataset with ``displacement_true``.
    time : float
        Frame time, ms: the truth's frame nearest it is shown, and every result must have
        a frame at that time.
    z : float, optional
        Slice position, mm (default: the truth's middle slice; the nearest slice is shown).
    path : path-like, optional
        Write the figure here (PNG).

    Returns
    -------
    matplotlib.figure.Figure
        The figure (also written to ``path`` when given).

    Raises
    ------
    SchemaError
        If the dataset is not ``tracked/1`` (the message names the kind it is) or has no
        ``displacement_grid`` (or ``truth`` has no ``displacement_true``).
    ValueError
        If ``time`` or ``z`` is not a finite number, or a result has no frame at the time
        shown (the message lists its frame times).

    Warns
    -----
    HarpxWarning
        If the truth's frame (slice) nearest ``time`` (``z``) lies more than half the frame
        interval (slice spacing) away from it: ``time`` (``z``) is outside the data.
    """
    if "displacement_true" not in truth.variables:
        raise SchemaError(
            "displacement_maps needs 'displacement_true' in truth (the images of a scene, "
            "e.g. scene.tagged); this dataset has none"
        )
    for name, ds in results.items():
        _require(ds, "tracked", ["displacement_grid"], f"displacement_maps (results[{name!r}])")
    plot = "displacement_maps"
    true = truth["displacement_true"]
    shown_t, t_note = _nearest(true["time"].values, "time", float(time), plot)
    true = true.sel(time=shown_t)
    if z is None:
        true = true.isel(z=true.sizes["z"] // 2)
        z_note = None
    else:
        shown_z, z_note = _nearest(true["z"].values, "z", float(z), plot)
        true = true.sel(z=shown_z)
    zsel = float(true.z)
    estimates = {
        name: _on_slice(ds["displacement_grid"], true, name) for name, ds in results.items()
    }
    ncol = len(results) + 1
    fig, axes = plt.subplots(
        2, ncol, figsize=(3.6 * ncol, 6.6), squeeze=False, layout="constrained"
    )
    true_mag = _magnitude(true)
    mags = {name: _magnitude(est) for name, est in estimates.items()}
    errors = {name: _magnitude(est - true.values) for name, est in estimates.items()}
    # one scale per row, spanning every panel of it: nothing saturates
    vmax = _top([true_mag, *mags.values()])
    emax = _top(list(errors.values()))
    extent = [float(true.x[0]), float(true.x[-1]), float(true.y[0]), float(true.y[-1])]
    im = axes[0, 0].imshow(true_mag, origin="lower", extent=extent, vmin=0, vmax=vmax)
    axes[0, 0].set_title("truth: |u| (mm)", fontsize=9)
    axes[1, 0].axis("off")
    im2 = None
    for col, name in enumerate(results, start=1):
        axes[0, col].imshow(mags[name], origin="lower", extent=extent, vmin=0, vmax=vmax)
        axes[0, col].set_title(f"{name}: |u| (mm)", fontsize=9)
        err = errors[name]
        im2 = axes[1, col].imshow(
            err, origin="lower", extent=extent, vmin=0, vmax=emax, cmap="magma"
        )
        e = np.asarray(err, dtype=np.float64)
        e = e[np.isfinite(e)]
        summary = f"slice mean {e.mean():.2f}, max {e.max():.2f}" if e.size else "no value"
        axes[1, col].set_title(f"{name}: error (mm)\n{summary}", fontsize=9)
    fig.colorbar(im, ax=axes[0, :].tolist(), shrink=0.8, label="|u| (mm)")
    if im2 is not None:
        fig.colorbar(im2, ax=axes[1, 1:].tolist(), shrink=0.8, label="|u − u_true| (mm)")
    notes = [n for n in (t_note, z_note) if n]
    fig.suptitle(
        "\n".join([f"t = {_number(shown_t)} ms, z = {_number(zsel)} mm", *notes]), fontsize=11
    )
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def _top(maps: Sequence[xr.DataArray]) -> float:
    """The largest finite value over ``maps`` (a colour limit; 1 when there is none)."""
    finite = [float(np.nanmax(m)) for m in maps if np.isfinite(np.asarray(m)).any()]
    return max(finite) if finite and max(finite) > 0.0 else 1.0


def _on_slice(grid: xr.DataArray, true: xr.DataArray, name: str) -> xr.DataArray:
    """The displacement ``grid`` of result ``name`` at the frame and on the slice of the
    truth's slice ``true``: the same frame (else ValueError), the truth's slice and pixels
    (interpolated when the result's grid is another)."""
    t = float(true.time)
    times = np.asarray(grid["time"].values, dtype=np.float64)
    step = float(np.median(np.diff(np.sort(times)))) if times.size > 1 else 1.0
    tol = _FRAME_TOLERANCE * max(step, 1e-9)
    hit = np.flatnonzero(np.abs(times - t) <= tol)
    if not hit.size:
        raise ValueError(
            f"displacement_maps: results[{name!r}] has no frame at time = {_number(t)} ms "
            f"(its frames are at {', '.join(_number(v) for v in times)} ms); pass a time "
            "that every result and the truth share"
        )
    est = grid.isel(time=int(hit[0]))
    same = all(
        est.sizes[d] == true.sizes[d] and np.allclose(est[d].values, true[d].values)
        for d in ("y", "x")
    )
    zs = np.asarray(est["z"].values, dtype=np.float64)
    exact = np.flatnonzero(np.isclose(zs, float(true.z), rtol=0.0, atol=1e-6))
    if same and exact.size:
        return est.isel(z=int(exact[0]))
    return est.interp(z=float(true.z), y=true.y, x=true.x)


def run_seconds(result: xr.Dataset) -> float:
    """Wall time, s, that a tracked result records for producing itself.

    ``time_total`` of a ``tracked/1`` dataset from :func:`harpx.tracking.track.track` (the
    whole call, from the phase images to the dataset), else the sum of its per-frame
    ``wall_time`` (conventional HARP's :func:`harpx.imaging.harptrack.track_harp`).

    Parameters
    ----------
    result : xarray.Dataset
        A ``tracked/1`` dataset.

    Returns
    -------
    float
        Wall time in s.

    Raises
    ------
    SchemaError
        If the dataset records neither.
    """
    if "time_total" in result.attrs:
        return float(result.attrs["time_total"])
    if "wall_time" in result.variables:
        return float(np.nansum(np.asarray(result["wall_time"].values, dtype=np.float64)))
    raise SchemaError(
        "the result records no run time (neither a 'time_total' attribute nor a 'wall_time' "
        "variable): pass a dataset from harpx.tracking.track or track_harp"
    )


def _runtime_rows(
    results: Mapping[str, xr.Dataset] | Sequence[Mapping[str, Any]], truth: xr.Dataset | None
) -> list[Mapping[str, Any]]:
    """Rows (method, seconds, mean, p95) from datasets against ``truth``, or as given."""
    if not isinstance(results, Mapping):
        return list(results)
    if truth is None:
        raise TypeError("error_vs_runtime of tracked datasets needs the truth (truth=...)")
    rows: list[Mapping[str, Any]] = []
    for label, result in results.items():
        if not isinstance(result, xr.Dataset):
            raise TypeError(f"results[{label!r}] must be an xarray.Dataset, not {type(result)}")
        err = result.harp.error(truth)  # the accessor: harpx.tracking.results.tracking_error
        rows.append(
            {
                "method": str(label),
                "seconds": run_seconds(result),
                "mean": float(err["mean_all"]),
                "p95": float(err["p95_all"]),
            }
        )
    return rows


def error_vs_runtime(
    results: Mapping[str, xr.Dataset] | Sequence[Mapping[str, Any]],
    truth: xr.Dataset | None = None,
    *,
    path: PathLike | None = None,
) -> Any:
    """Scatter of mean (and 95th percentile) error against wall time, one point per result.

    Parameters
    ----------
    results : mapping of str to xarray.Dataset, or sequence of mappings
        Method name → tracked result (``tracked/1`` from :func:`harpx.tracking.track.track`
        or conventional HARP's result with ``displacement_grid``): its error against
        ``truth`` (:func:`harpx.tracking.results.tracking_error`, frames after the first)
        and the run time it records (:func:`run_seconds`: the tracker's ``time_total``,
        HARP's summed ``wall_time``; phase extraction, shared by both, is not included).
        Or precomputed rows, each with ``method`` (str), ``seconds`` (s), ``mean`` and
        ``p95`` (mm).
    truth : xarray.Dataset, optional
        Dataset with ``displacement_true`` (a synthetic ``tagged/1`` scene); needed with
        datasets.
    path : path-like, optional
        As in :func:`displacement_maps`.

    Returns
    -------
    matplotlib.figure.Figure
        The figure (also written to ``path`` when given).

    Raises
    ------
    TypeError
        If datasets come without ``truth``, or a result is not a dataset.
    SchemaError
        If a result records no run time (:func:`run_seconds`).
    """
    rows = _runtime_rows(results, truth)
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
        The axes drawn in (a new figure's when ``ax`` is None).
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
    if result.planar:
        ax.set_title(f"opening angle {result.degrees:.1f}°")
    else:  # a helix: the in-plane angle does not describe it
        ax.set_title(f"edges {result.gap:.1f} mm apart, out of plane")
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
