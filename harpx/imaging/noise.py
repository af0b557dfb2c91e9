r"""Image noise of a tagged acquisition, and the noise it leaves in the harmonic image.

Thermal noise in a reconstructed MR image is white with standard deviation :math:`\sigma`
per pixel. Along the tag lines of a slice (the in-plane axis across which the tag pattern
does not change) the second difference :math:`I_{i-1} - 2 I_i + I_{i+1}` removes the tags
exactly and smooth anatomy nearly so, and leaves noise of variance :math:`6\sigma^2`;
anatomical edges disturb only the pixels next to them, so the median absolute deviation
(MAD) of the second differences gives :math:`\sigma` (Immerkær's idea of estimating noise
from a compact difference filter, Comput. Vis. Image Underst. 64 (1996) 300–302, turned
along the tags). A spectral estimate (median power away from the tag peaks) was tried and
dropped: an edge's spectrum covers every frequency, and on the short-axis scene it read the
noise 1.4–1.5 times too high.

The band-pass of :func:`harpx.imaging.harp.extract_phase` keeps the :math:`n_d` of the
:math:`N` Fourier coefficients of a slice inside its disk, so the complex harmonic image
:math:`H` carries noise of standard deviation

.. math:: \sigma_H = \sigma \sqrt{n_d / N}

per pixel (upsampling by exact spline interpolation leaves it unchanged), and its phase at
a point of harmonic magnitude :math:`|H|` has the standard deviation
:math:`\sigma_H / (\sqrt 2 |H|)` to first order. The tracker turns that into the noise floor
of its residual (:mod:`harpx.tracking.noise`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from harpx.imaging.bandpass import bandpass_mask
from harpx.schema import GRID_DIMS, standard_attrs

__all__ = ["band_share", "harmonic_noise", "harmonic_noise_block", "slice_noise"]

#: Median absolute deviation of a standard normal variable.
MAD_GAUSS = 0.6744897501960817
#: Largest gain of the second difference on the tag pattern, 2 − 2 cos(2π f_a d_a), for
#: the axis along the tag lines (0.1: the tags tilted ≲ 5° from it in a 7 mm / 1.2 mm
#: acquisition); obliquer tags give no estimate.
MAX_TAG_LEAK = 0.1
#: Fewest second differences for an estimate (the MAD of 1000 samples has ~5 % sd).
MIN_SAMPLES = 1000


def slice_noise(
    slices: NDArray[np.floating],
    spacing: Sequence[float],
    freq: Sequence[float],
) -> float:
    """Standard deviation of white image noise, from second differences along the tags.

    Parameters
    ----------
    slices : ndarray, shape (..., n1, n2)
        2D slices of one acquisition (leading axes are further slices), image units.
    spacing : (float, float)
        Pixel spacing along the two slice axes, mm.
    freq : (float, float)
        Tag frequency vector projected on the slice plane, cycles/mm.

    Returns
    -------
    float
        Noise standard deviation σ per pixel (image units); NaN when neither in-plane axis
        runs along the tag lines (``MAX_TAG_LEAK``) or there are fewer than
        ``MIN_SAMPLES`` differences.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> x = np.arange(96) * 1.2
    >>> tags = 100 * (1 + np.cos(2 * np.pi * x / 7))[None, :] * np.ones((96, 1))
    >>> noisy = tags + rng.normal(0, 3.0, (4, 96, 96))
    >>> bool(abs(slice_noise(noisy, (1.2, 1.2), (0.0, 1 / 7)) - 3.0) < 0.2)
    True
    """
    a = np.asarray(slices, dtype=np.float64)
    d = np.asarray(spacing, dtype=np.float64)
    f = np.abs(np.asarray(freq, dtype=np.float64))
    # along the tag lines the tag pattern is constant: a second difference there removes it
    # and the smooth anatomy, and leaves each edge to the pixels next to it
    along = int(np.argmin(f * d))
    leak = 2.0 - 2.0 * np.cos(2.0 * np.pi * f[along] * d[along])
    if leak > MAX_TAG_LEAK or a.shape[-2 + along] < 3:
        return float("nan")
    second = np.diff(a, n=2, axis=-2 + along)
    if second.size < MIN_SAMPLES:
        return float("nan")
    mad = float(np.median(np.abs(second - np.median(second))))
    return mad / MAD_GAUSS / float(np.sqrt(6.0))


def harmonic_noise_block(
    volume: NDArray[np.floating],
    freq: NDArray[np.float64],
    slice_index: NDArray[np.int64],
    *,
    spacing: Sequence[float],
    radius: float,
) -> NDArray[np.float64]:
    """Harmonic-image noise σ_H per tag of a block (tag, z, y, x); loops over its ≤ 3 tags.

    Parameters
    ----------
    volume : ndarray, shape (ntag, nz, ny, nx)
        One frame of each tag's images on the native grid, image units.
    freq : ndarray, shape (ntag, 3)
        Tag frequency vectors ``f d`` in cycles/mm, components (z, y, x).
    slice_index : ndarray of int, shape (ntag,)
        Axis (0 = z, 1 = y, 2 = x) normal to each tag's acquisition slices.
    spacing : (float, float, float)
        Grid spacing (dz, dy, dx), mm.
    radius : float
        Band-pass radius as a fraction of the tag frequency.

    Returns
    -------
    ndarray, shape (ntag,)
        σ_H (image units; NaN where :func:`slice_noise` has no axis along the tag lines).
    """
    out = np.full(volume.shape[0], np.nan)
    for t in range(volume.shape[0]):
        normal = int(np.asarray(slice_index[t]).ravel()[0])
        plane = [a for a in range(3) if a != normal]
        slices = np.moveaxis(np.asarray(volume[t], dtype=np.float64), normal, 0)
        f_tag = np.asarray(freq[t]).reshape(-1, 3)[0]
        f = [float(f_tag[a]) for a in plane]
        d = [float(spacing[a]) for a in plane]
        share = band_share(volume.shape[1:], spacing, f_tag, normal, radius)
        out[t] = slice_noise(slices, d, f) * np.sqrt(share)
    return out


def band_share(
    shape: Sequence[int],
    spacing: ArrayLike,
    freq: ArrayLike,
    normal: int,
    radius: float,
) -> float:
    r"""Share :math:`n_d / N` of a slice's Fourier coefficients inside a tag's band-pass disk.

    Parameters
    ----------
    shape : (int, int, int)
        Grid shape (nz, ny, nx).
    spacing : (float, float, float)
        Grid spacing (dz, dy, dx), mm.
    freq : (float, float, float)
        The tag's frequency vector ``f d`` in cycles/mm, components (z, y, x).
    normal : int
        Axis (0 = z, 1 = y, 2 = x) normal to the tag's slices.
    radius : float
        Band-pass radius as a fraction of the tag's in-plane frequency.

    Returns
    -------
    float
        :math:`n_d / N` in [0, 1]: :math:`\sigma_H = \sigma \sqrt{n_d / N}` (module notes).
    """
    plane = [a for a in range(3) if a != normal]
    f = [float(v) for v in np.asarray(freq, dtype=np.float64)[plane]]
    d = [float(v) for v in np.asarray(spacing, dtype=np.float64)[plane]]
    n = (int(shape[plane[0]]), int(shape[plane[1]]))
    kept = bandpass_mask(n, d, f, radius * float(np.hypot(f[0], f[1]))).sum()
    return float(kept) / float(n[0] * n[1])


def harmonic_noise(
    image: xr.DataArray,
    freq: xr.Variable,
    slice_index: xr.Variable,
    *,
    spacing: Sequence[float],
    radius: float,
) -> xr.Variable:
    """Noise standard deviation of each tag's complex harmonic image (lazy for dask input).

    Estimated from one frame of the native slices (noise is the same in every frame) and
    scaled by the share of the spectrum the band-pass keeps (module notes); called by
    :func:`harpx.imaging.harp.extract_phase`, which records it as ``harmonic_noise``.

    Parameters
    ----------
    image : xarray.DataArray
        One frame of ``image`` with dims (tag, z, y, x), image units.
    freq, slice_index : xarray.Variable
        :func:`harmonic_noise_block`'s arrays of the same names, with dims
        (tag, component) and (tag).
    spacing : (float, float, float)
        Grid spacing (dz, dy, dx), mm, as for :func:`harmonic_noise_block`.
    radius : float
        Band-pass radius, as for :func:`harmonic_noise_block`.

    Returns
    -------
    xarray.Variable
        ``harmonic_noise`` (tag), image units.
    """
    noise = xr.apply_ufunc(
        harmonic_noise_block,
        image.variable.transpose("tag", *GRID_DIMS),
        freq,
        slice_index,
        input_core_dims=[list(GRID_DIMS), ["component"], []],
        output_core_dims=[[]],
        dask="parallelized",
        output_dtypes=[np.float64],
        kwargs={"spacing": tuple(spacing), "radius": float(radius)},
    )
    noise.attrs = standard_attrs("harmonic_noise")
    return noise
