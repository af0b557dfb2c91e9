r"""numpy kernels of the harmonic-phase pipeline (no xarray).

Every kernel works on trailing axes, takes its options as keywords and is vectorised over
leading (time, slice, tag) axes.

Grid-aligned refinement
-----------------------
Upsampling by an integer factor ``m`` subdivides every native voxel into ``m`` voxels of
spacing ``d/m`` along that axis, so the refined grid covers the same field of view
``[c_0 - d/2, c_{n-1} + d/2]`` as the native one. With native voxel centres
``c_i = c_0 + i d`` (i = 0 … n-1) the refined centres are

.. math:: c'_j = c_0 - \frac{d}{2} + \left(j + \frac12\right)\frac{d}{m},
          \qquad j = 0 \dots m n - 1,

i.e. the first refined centre is ``c_0 - (m-1) d / (2m)`` and the last is
``c_{n-1} + (m-1) d / (2m)``. In native index units the refined centre ``j`` sits at
``p_j = (j + 1/2)/m - 1/2`` (:func:`refine_positions`). This is scipy's
``ndimage.zoom(..., grid_mode=True)`` convention. It keeps the period of the DFT (the field of
view) unchanged, so native and refined spectra share the same frequency samples
``q / (n d)``.

The spectral cubic-spline upsampling, the band-pass and the harmonic phase of a volume
live in :mod:`harpx.imaging.bandpass`.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from harpx.imaging.fft import default_threads

__all__ = [
    "linear_weights",
    "refine_linear",
    "refine_positions",
    "upsample_slices",
    "wrap",
]

TWO_PI = 2.0 * np.pi
#: The largest float32 below π (float32(π) itself is 8.7e-8 above π).
_PI32_INSIDE = np.nextafter(np.float32(np.pi), np.float32(0.0))


# --------------------------------------------------------------------------------------------
# wrapping and grid refinement
# --------------------------------------------------------------------------------------------
def wrap(a: ArrayLike) -> NDArray[np.float64]:
    r"""Wrap angles to ``[-π, π)``: :math:`W(a) = \mathrm{angle}(e^{ia})`.

    Parameters
    ----------
    a : array_like
        Angles in rad.

    Returns
    -------
    ndarray of float64
        ``a + 2πk`` in ``[-π, π)`` for the integer ``k`` that puts it there (same shape).

    Examples
    --------
    >>> from harpx.imaging._kernels import wrap
    >>> wrap([np.pi, -np.pi, 3 * np.pi / 2]).round(4)
    array([-3.1416, -3.1416, -1.5708])
    """
    a = np.asarray(a, dtype=np.float64)
    # a − 2πk with k = floor((a + π) / 2π): two to four times faster than np.mod (fmod),
    # equal to it within a few ulp of |a| (4e-14 rad at |a| = 400)
    out = np.asarray(a - TWO_PI * np.floor((a + np.pi) * (1.0 / TWO_PI)))
    # rounding can leave a result a hair outside [-π, π): fold it back
    np.copyto(out, out - TWO_PI, where=out >= np.pi)
    np.copyto(out, out + TWO_PI, where=out < -np.pi)
    return out


def refine_positions(n: int, factor: int) -> NDArray[np.float64]:
    """Positions of grid-aligned refined voxel centres in native index units.

    Parameters
    ----------
    n : int
        Number of native voxels along the axis.
    factor : int
        Integer refinement factor ``m >= 1``.

    Returns
    -------
    ndarray of float64, shape (m n,)
        ``p_j = (j + 1/2)/m - 1/2``; native centre ``i`` is at ``p = i``. Multiply by the
        native spacing and add the first native centre to get mm.

    Examples
    --------
    >>> from harpx.imaging._kernels import refine_positions
    >>> refine_positions(2, 2)
    array([-0.25,  0.25,  0.75,  1.25])
    """
    m = _check_factor(factor, "factor")
    return (np.arange(n * m, dtype=np.float64) + 0.5) / m - 0.5


def linear_weights(
    n: int, factor: int
) -> tuple[NDArray[np.intp], NDArray[np.intp], NDArray[np.float64]]:
    """Neighbours and weights of linear interpolation onto the refined grid.

    Refined centres outside ``[0, n-1]`` (the outer half voxels) take the value of the
    nearest native centre (constant extrapolation).

    Parameters
    ----------
    n : int
        Number of native voxels.
    factor : int
        Integer refinement factor ``m >= 1``.

    Returns
    -------
    i0, i1 : ndarray of intp, shape (m n,)
        Native neighbours; ``i1 == i0`` wherever the weight ``w`` is 0, so that a NaN
        neighbour with zero weight does not leak into the result.
    w : ndarray of float64, shape (m n,)
        Weight of ``i1``; the value is ``(1 - w) a[i0] + w a[i1]``.
    """
    p = np.clip(refine_positions(n, factor), 0.0, n - 1.0)
    i0 = np.floor(p).astype(np.intp)
    w = p - i0
    i1 = np.where(w > 0.0, np.minimum(i0 + 1, n - 1), i0)
    return i0, i1, w


def _check_factor(factor: int, name: str) -> int:
    if isinstance(factor, bool) or not isinstance(factor, int | np.integer) or factor < 1:
        raise ValueError(f"{name!r} must be an integer >= 1, got {factor!r}")
    return int(factor)


def _pair(value: int | Sequence[int], name: str) -> tuple[int, int]:
    if isinstance(value, int | np.integer):
        value = (int(value), int(value))
    if len(value) != 2:
        raise ValueError(f"{name!r} needs one value per in-plane axis (2), got {value!r}")
    return _check_factor(value[0], name), _check_factor(value[1], name)


# --------------------------------------------------------------------------------------------
# cubic B-spline pieces
# --------------------------------------------------------------------------------------------
def _bspline3(t: ArrayLike) -> NDArray[np.float64]:
    """Centred cubic B-spline β³(t), support (-2, 2)."""
    t = np.abs(np.asarray(t, dtype=np.float64))
    inner = 2.0 / 3.0 - t**2 + 0.5 * t**3
    outer = (2.0 - t) ** 3 / 6.0
    return np.where(t < 1.0, inner, np.where(t < 2.0, outer, 0.0))


def _spline_transfer(q: NDArray[np.int64], n: int, m: int) -> NDArray[np.complex128]:
    """Refined-DFT transfer ``K_m(q) / B_d(q/n)`` of grid-aligned cubic-spline upsampling."""
    sigma = -(m - 1) / (2.0 * m)
    lmin = int(np.ceil((-2.0 - sigma) * m))
    lmax = int(np.floor((2.0 - sigma) * m))
    ell = np.arange(lmin, lmax + 1)
    taps = _bspline3(sigma + ell / m)
    phase = np.exp(-2j * np.pi * np.outer(q, ell) / (m * n))
    k = phase @ taps
    bd = (2.0 + np.cos(2.0 * np.pi * q / n)) / 3.0
    return k / bd


def upsample_slices(
    slices: ArrayLike, factor: int | Sequence[int], *, mode: str = "reflect"
) -> NDArray[np.float64]:
    """Cubic-spline upsampling of a stack of 2D slices on the grid-aligned refined grid.

    Parameters
    ----------
    slices : array_like of float, shape (..., n1, n2)
        Image slices; leading axes are independent (time, slice, ...).
    factor : int or (int, int)
        Integer refinement factor per in-plane axis (dimensionless).
    mode : str, default "reflect"
        Boundary extension of the spline (scipy.ndimage names): "reflect" (half-sample
        symmetric), "mirror", "grid-wrap" (periodic), "nearest".

    Returns
    -------
    ndarray of float64, shape (..., m1 n1, m2 n2)
        Samples of the cubic interpolating spline at the refined centres
        ``p_j = (j + 1/2)/m - 1/2`` (native index units, see :func:`refine_positions`).

    Notes
    -----
    Separable: along each axis the samples are prefiltered to B-spline coefficients
    (``ndimage.spline_filter1d``), then each of the ``m`` refined phases is a 5-tap
    correlation with ``β³(δ_p - k)``, ``δ_p = (p + 1/2)/m - 1/2``. It equals
    ``ndimage.zoom(order=3, grid_mode=True)`` per slice, without looping over slices.

    Examples
    --------
    >>> from harpx.imaging._kernels import upsample_slices
    >>> upsample_slices(np.ones((3, 4, 4)), 2).shape
    (3, 8, 8)
    """
    out = np.asarray(slices, dtype=np.float64)
    if out.ndim < 2:
        raise ValueError(f"'slices' needs at least 2 dimensions, got shape {out.shape!r}")
    for axis, m in zip((-2, -1), _pair(factor, "factor"), strict=True):
        if m == 1:
            continue
        coef = ndimage.spline_filter1d(out, order=3, axis=axis, mode=mode)
        shape = list(out.shape)
        shape[axis] *= m
        refined = np.empty(shape)
        k = np.arange(-2, 3)
        for p in range(m):
            delta = (p + 0.5) / m - 0.5
            index = [slice(None)] * refined.ndim
            index[axis] = slice(p, None, m)
            ndimage.correlate1d(
                coef, _bspline3(delta - k), axis=axis, mode=mode, output=refined[tuple(index)]
            )
        out = refined
    return out


# --------------------------------------------------------------------------------------------
# shared worker pool, phase and magnitude, linear refinement
# --------------------------------------------------------------------------------------------
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def _pool() -> ThreadPoolExecutor:
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max(1, os.cpu_count() or 1), thread_name_prefix="harpx")
        return _POOL


def _phase_magnitude(
    h: NDArray[np.complex128],
    phase: NDArray[np.float64],
    magnitude: NDArray[np.float64],
    re: NDArray[np.float64],
    im: NDArray[np.float64],
) -> None:
    """Write angle(h) in [-π, π) and |h| (``re``/``im`` are contiguous scratch of h's shape)."""
    # -atan2(0 - Im, Re) is angle(h) with range [-π, π): the subtraction turns every signed
    # zero into +0, atan2 then returns +π (never -π) on the negative real axis, and the
    # negation maps it to -π. The copies also make the atan2 inputs contiguous (3x faster
    # than atan2 on the interleaved real/imaginary views).
    np.subtract(0.0, h.imag, out=im)
    np.copyto(re, h.real)
    np.arctan2(im, re, out=phase)
    np.negative(phase, out=phase)
    if phase.dtype == np.float32:
        # float32(π) exceeds π: angles within rounding of ±π come out as ±float32(π), outside
        # [-π, π) in exact arithmetic; wrap +float32(π) and clamp -float32(π) to the float32
        # just inside -π (an error of at most 2e-7 rad)
        np.copyto(phase, -_PI32_INSIDE, where=phase > _PI32_INSIDE)
        np.maximum(phase, -_PI32_INSIDE, out=phase)
    np.abs(h, out=magnitude)


def _interp_rows(
    h: NDArray[np.float64], out: NDArray[np.float64], diff: NDArray[np.float64], m: int
) -> None:
    """Linear interpolation along axis 0 onto the refined positions.

    ``h`` is (n, ...), ``out`` is (m n, ...) and ``diff`` is (n - 1, ...) scratch (float
    views of complex arrays work too). Refined row ``m i + r`` sits at native position
    ``i + δ_r`` with ``δ_r = (r + 1/2)/m - 1/2``, so each phase ``r`` is one strided slice of
    ``out`` with a constant weight: two vectorised operations per refined row and no gathers.
    Rows beyond the end centres are copies. A NaN spreads only to rows that weight it.
    """
    _interp_axis(h, out, diff, m, 0)


def _interp_axis(
    h: NDArray[np.float64], out: NDArray[np.float64], diff: NDArray[np.float64], m: int, axis: int
) -> None:
    """:func:`_interp_rows` along any ``axis`` (slicing, no copies of ``h``)."""
    if m == 1:
        np.copyto(out, h)
        return

    def sl(s: slice) -> tuple[slice, ...]:
        index = [slice(None)] * h.ndim
        index[axis] = s
        return tuple(index)

    if h.shape[axis] == 1:
        for r in range(m):
            np.copyto(out[sl(slice(r, r + 1))], h)
        return
    np.subtract(h[sl(slice(1, None))], h[sl(slice(None, -1))], out=diff)
    for r in range(m):
        delta = (r + 0.5) / m - 0.5
        rows = out[sl(slice(r, None, m))]
        if delta == 0.0:
            np.copyto(rows, h)
            continue
        inner = sl(slice(None, -1)) if delta > 0.0 else sl(slice(1, None))
        edge = sl(slice(-1, None)) if delta > 0.0 else sl(slice(0, 1))
        target = rows[inner]
        np.multiply(diff, delta if delta > 0.0 else 1.0 + delta, out=target)
        np.add(target, h[sl(slice(None, -1))], out=target)
        np.copyto(rows[edge], h[edge])


def refine_linear(
    volume: ArrayLike, factors: Sequence[int], *, threads: int | None = None
) -> NDArray[np.float64]:
    """Separable linear interpolation of volumes onto the grid-aligned refined grid.

    Parameters
    ----------
    volume : array_like of float, shape (..., nz, ny, nx)
        Values at the native voxel centres (any units); NaN allowed.
    factors : (int, int, int)
        Refinement factor per trailing axis.
    threads : int or None
        Volumes (leading index) are spread over this many worker threads; None means
        ``os.cpu_count()``.

    Returns
    -------
    ndarray of float64, shape (..., mz nz, my ny, mx nx)
        Values at the refined centres (:func:`refine_positions`); constant beyond the outer
        native centres; a refined value is NaN iff a native neighbour with non-zero weight is.

    Examples
    --------
    >>> from harpx.imaging._kernels import refine_linear
    >>> refine_linear(np.array([[[0.0, 1.0]]]), (1, 1, 2))
    array([[[0.  , 0.25, 0.75, 1.  ]]])
    """
    v = np.asarray(volume, dtype=np.float64)
    if v.ndim < 3:
        raise ValueError(f"'volume' needs at least 3 dimensions, got shape {v.shape!r}")
    mz, my, mx = (_check_factor(f, "factors") for f in factors)
    nz, ny, nx = v.shape[-3:]
    lead = v.shape[:-3]
    count = int(np.prod(lead, dtype=np.int64))
    big = (nz * mz, ny * my, nx * mx)
    out = np.empty((count, *big))
    flat = v.reshape(count, nz, ny, nx)
    i0, i1, w = linear_weights(nz, mz)

    def work(items: Sequence[int]) -> None:
        # z is refined plane by plane from in-plane refined planes kept in cache, so the
        # output is written once: x first (strided slices on the smallest array), then y
        wide = np.empty((ny, big[2]))
        diff_x = np.empty((ny, max(nx - 1, 0)))
        diff_y = np.empty((max(ny - 1, 0), big[2]))
        diff_z = np.empty(big[1:])
        planes: dict[int, NDArray[np.float64]] = {}

        def plane(i: int, k: int) -> NDArray[np.float64]:
            if k not in planes:
                if len(planes) == 2:
                    buffer = planes.pop(min(planes))
                else:
                    buffer = np.empty(big[1:])
                _interp_axis(flat[i, k], wide, diff_x, mx, 1)
                _interp_axis(wide, buffer, diff_y, my, 0)
                planes[k] = buffer
            return planes[k]

        for i in items:
            planes.clear()
            pair = (-1, -1)
            for j in range(big[0]):
                low = plane(i, int(i0[j]))
                if w[j] == 0.0:
                    np.copyto(out[i, j], low)
                    continue
                high = plane(i, int(i1[j]))
                if pair != (i0[j], i1[j]):
                    np.subtract(high, low, out=diff_z)
                    pair = (i0[j], i1[j])
                np.multiply(diff_z, w[j], out=out[i, j])
                np.add(out[i, j], low, out=out[i, j])

    workers = max(1, min(default_threads(threads), count))
    if workers == 1:
        work(range(count))
    else:
        jobs = [_pool().submit(work, range(k, count, workers)) for k in range(workers)]
        for job in jobs:
            job.result()
    return out.reshape(*lead, *big)


def percentile_99(values: NDArray[np.floating], inside: NDArray[np.bool_] | None) -> float:
    """``np.percentile(v, 99)`` (0 if empty) of the finite values ``v`` of ``values[inside]``.

    The same number as numpy's (linear method), found without partitioning all the values:
    the two order statistics it interpolates lie above the 98th percentile of an evenly
    strided subsample (checked by counting; otherwise every value is partitioned), so only
    the few values above that are partitioned.
    """
    keep = np.isfinite(values)  # one NaN block must not make the floor NaN
    if inside is not None:
        keep &= inside
    n = int(np.count_nonzero(keep))
    if n == 0:
        return 0.0
    virtual = (n - 1) * 0.99  # numpy's linear method
    below = int(np.floor(virtual))
    gamma = virtual - below
    below = min(max(below, 0), n - 1)
    above = min(below + 1, n - 1)
    flat = values.ravel()
    stride = max(1, flat.size // 20000)
    probe = flat[::stride][keep.ravel()[::stride]]
    candidates: NDArray[np.floating] | None = None
    skipped = 0
    if n > 50000 and probe.size > 100:
        threshold = np.percentile(probe, 98)
        selected = keep & (values >= threshold)
        skipped = n - int(np.count_nonzero(selected))
        if skipped <= below:
            candidates = values[selected]
    if candidates is None:
        candidates, skipped = values[keep], 0
    part = np.partition(candidates, [below - skipped, above - skipped])
    a, b = part[below - skipped], part[above - skipped]
    # numpy's _lerp, in the values' precision
    diff = b - a
    result = b - diff * (1.0 - gamma) if gamma >= 0.5 else a + diff * gamma
    return float(result)
