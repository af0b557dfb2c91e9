"""Figures (matplotlib): displacement maps and error against run time."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402

from harpx._typing import PathLike  # noqa: E402


def _magnitude(da: xr.DataArray) -> xr.DataArray:
    return np.sqrt((da**2).sum("axis", skipna=False))


def displacement_maps(
    results: Mapping[str, xr.Dataset],
    truth: xr.Dataset,
    *,
    time: float,
    z: float | None = None,
    path: PathLike | None = None,
) -> Any:
    """Displacement magnitude and error maps on one slice, one column per method.

    Like the paper's Fig. 1 c/d: the top row shows |u| of each method at ``time`` on the
    slice nearest ``z``; the bottom row shows the error |u − u_true| against the truth.

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
    """
    true = truth["displacement_true"].sel(time=time, method="nearest")
    zsel = float(true.z[true.sizes["z"] // 2]) if z is None else z
    true = true.sel(z=zsel, method="nearest")
    ncol = len(results) + 1
    fig, axes = plt.subplots(2, ncol, figsize=(3.6 * ncol, 6.6), squeeze=False, layout="constrained")
    vmax = float(np.nanmax(_magnitude(true)))
    extent = [float(true.x[0]), float(true.x[-1]), float(true.y[0]), float(true.y[-1])]
    axes[0, 0].imshow(_magnitude(true), origin="lower", extent=extent, vmin=0, vmax=vmax)
    axes[0, 0].set_title("truth: |u| (mm)", fontsize=9)
    axes[1, 0].axis("off")
    for col, (name, ds) in enumerate(results.items(), start=1):
        est = ds["displacement_grid"].sel(time=time, method="nearest")
        est = est.interp(z=true.z, y=true.y, x=true.x) if est.sizes["x"] != true.sizes["x"] else est.sel(z=zsel, method="nearest")
        mag = _magnitude(est)
        im = axes[0, col].imshow(mag, origin="lower", extent=extent, vmin=0, vmax=vmax)
        axes[0, col].set_title(f"{name}: |u| (mm)", fontsize=9)
        err = _magnitude(est - true.values)
        im2 = axes[1, col].imshow(err, origin="lower", extent=extent, vmin=0, vmax=2.0, cmap="magma")
        axes[1, col].set_title(f"{name}: error (mm)\nslice mean {float(np.nanmean(err)):.2f}", fontsize=9)
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
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for row in rows:
        ax.errorbar(
            row["seconds"], row["mean"], yerr=[[0], [row["p95"] - row["mean"]]], fmt="o", capsize=3,
            label=row["method"],
        )
    ax.set_xscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("displacement error (mm): mean, bar to p95")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
