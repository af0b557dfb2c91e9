"""One slice of an image dataset: tag image, harmonic phase, tracked displacement.

Every map shows the frame and slice nearest the ones asked for and names them in its title;
when they differ from what was asked, the title says so ("nearest slice to z = 0 mm"), and a
slice more than half a slice spacing away (outside the data) also warns with
:class:`~harpx.errors.HarpxWarning`.

The harmonic phase is drawn only where the tissue is: where the harmonic magnitude exceeds
half its typical value in the tissue (the band-pass blurs the tissue's edge into a ramp
whose midpoint is the edge) and stands out of its noise (``harmonic_noise``), so the noise
phase outside the tissue is not shown.

Strain on a slice is in :mod:`harpx.plotting.strain`, fibre stretch by region in
:mod:`harpx.plotting.regions`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr

from harpx.plotting._common import (
    _magnitude,
    _map_doc,
    _require,
    _slice,
    _slice_map,
    _where,
)

__all__ = ["NOISE_FRACTION", "TISSUE_EDGE", "TISSUE_NOISE_FACTOR", "displacement_map",
           "phase_map", "tag_image"]  # fmt: skip

#: Harmonic magnitude, in units of its noise standard deviation (``harmonic_noise``),
#: that tissue must exceed: noise alone exceeds k σ with probability exp(-k²)
TISSUE_NOISE_FACTOR = 3.0
#: Tissue is where the harmonic magnitude exceeds this fraction of the slice's typical
#: tissue magnitude (the median over the pixels above the noise level)
TISSUE_EDGE = 0.5
#: Without ``harmonic_noise``, the noise level is taken as this fraction of the slice's
#: 99th percentile of the magnitude
NOISE_FRACTION = 0.1


@_map_doc("tagged", "image", slice_params=True)
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
    tag : str, optional
        Tag label.
    """
    plot = "tag_image (ds.harp.plot.tag_image)"
    _require(ds, "tagged", ["image"], plot)
    da, notes = _slice(ds["image"].sel(tag=ds.tag.values[0] if tag is None else tag), time, z, plot)
    return _slice_map(da, _where(da, notes), ax, cmap="gray", label="intensity")


@_map_doc("phase", "phase", slice_params=True)
def phase_map(
    ds: xr.Dataset,
    *,
    tag: str | None = None,
    mask: str | xr.DataArray | None = "tissue",
    time: float | None = None,
    z: float | None = None,
    ax: Any = None,
) -> Any:
    """One slice of a ``phase/1`` harmonic phase (rad, cyclic colour map).

    Parameters
    ----------
    tag : str, optional
        Tag label (default: the first).
    mask : {"tissue"} or xarray.DataArray or None, default "tissue"
        Where to show the phase. ``"tissue"``: pixels whose harmonic ``magnitude`` exceeds
        :data:`TISSUE_EDGE` times the median magnitude of the pixels above the noise level
        (:data:`TISSUE_NOISE_FACTOR` times the tag's ``harmonic_noise``; without a finite
        one :data:`NOISE_FRACTION` of the slice's 99th percentile of ``magnitude``), and the
        noise level itself, within the acquisition's ``mask`` where the dataset has one.
        A boolean DataArray on the grid (``z, y, x`` or ``y, x``, true inside) gives the
        mask; None shows every pixel. Pixels outside are NaN (blank).

    Examples
    --------
    The harmonic phase of a still, tagged block (one tag along x), on its middle slice:

    >>> import matplotlib.pyplot as plt
    >>> from harpx.imaging.harp import extract_phase
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: 0 * X, shape=(2, 32, 32), spacing=(2.0, 1.5, 1.5), times=[0.0],
    ...     tags=("x",), snr=20.0, oversample=1, rng=0)
    >>> ax = phase_map(extract_phase(tagged))
    >>> ax.get_title(), ax.collections[0].get_clim()
    ('tag x, t = 0 ms, z = 1 mm', (-3.141592653589793, 3.141592653589793))
    >>> plt.close(ax.figure)
    """
    plot = "phase_map (ds.harp.plot.phase)"
    _require(ds, "phase", ["phase"], plot)
    label = ds.tag.values[0] if tag is None else tag
    da, notes = _slice(ds["phase"].sel(tag=label), time, z, plot)
    inside = _tissue(ds, da, label, mask)
    if inside is not None:
        da = da.where(inside)
    return _slice_map(
        da, _where(da, notes), ax, cmap="twilight", label="phase (rad)", vmin=-np.pi, vmax=np.pi
    )


def _tissue(ds: xr.Dataset, da: xr.DataArray, tag: Any, mask: Any) -> xr.DataArray | None:
    """Boolean (y, x) mask of the pixels of the phase slice ``da`` to show (phase_map)."""
    if mask is None or mask is False:
        return None
    where = {d: da[d].item() for d in ("time", "z") if d in da.coords and da[d].ndim == 0}
    if isinstance(mask, xr.DataArray):
        given = mask.sel({d: v for d, v in where.items() if d in mask.dims})
        if set(given.dims) != {"y", "x"}:
            raise ValueError(
                f"phase_map: mask must be a boolean DataArray on (z, y, x) or (y, x); got dims "
                f"{mask.dims}"
            )
        return given.astype(bool)
    if mask != "tissue":
        raise ValueError(f"phase_map: mask must be 'tissue', a DataArray or None; got {mask!r}")
    inside = xr.ones_like(da, dtype=bool)
    if "magnitude" in ds:
        magnitude = ds["magnitude"].sel(tag=tag).sel(where)
        m = np.asarray(magnitude.values, dtype=np.float64)
        sigma = float(ds["harmonic_noise"].sel(tag=tag)) if "harmonic_noise" in ds else np.nan
        if np.isfinite(sigma):
            noise = TISSUE_NOISE_FACTOR * sigma
        else:  # no estimate (extract_phase gives NaN for images too small to measure it)
            noise = NOISE_FRACTION * float(np.nanpercentile(m, 99.0))
        above = m[m > noise]
        level = max(noise, TISSUE_EDGE * float(np.median(above))) if above.size else noise
        inside = inside & (magnitude > level)
    if "mask" in ds.variables:
        acquired = ds["mask"].sel(tag=tag)
        inside = inside & acquired.sel({d: v for d, v in where.items() if d in acquired.dims})
    return inside


@_map_doc("tracked", "displacement_grid", slice_params=True)
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
    component : {"x", "y", "z"}, optional
        Component to show, on a diverging colour map with limits symmetric about 0;
        default the magnitude.
    """
    plot = "displacement_map (ds.harp.plot.displacement)"
    _require(ds, "tracked", ["displacement_grid"], plot)
    da, notes = _slice(ds["displacement_grid"], time, z, plot)
    title = _where(da, notes)
    if component is None:
        return _slice_map(_magnitude(da), title, ax, cmap="viridis", label="u (mm)")
    da = da.sel(axis=component)
    # a signed component: limits symmetric about 0, the diverging map's centre
    values = np.abs(np.asarray(da.values, dtype=np.float64))
    bound = float(values[np.isfinite(values)].max()) if np.isfinite(values).any() else 0.0
    bound = bound or 1.0
    return _slice_map(
        da, title, ax, cmap="RdBu_r", label=f"u_{component} (mm)", vmin=-bound, vmax=bound
    )
