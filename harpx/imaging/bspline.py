r"""Cubic B-spline machinery of the phase sampler: prefilter, taps, tensor weights.

The sampler (:class:`harpx.imaging.sample.PhaseSampler`) interpolates demodulated complex
harmonic images with cubic B-splines. Their coefficients come from the recursive
prefilter of Unser, Aldroubi & Eden (IEEE Trans. Signal Process. 41:821-833, 1993) with
the pole :math:`z = \sqrt 3 - 2` and mirror boundaries, applied along each axis (a dense
inverse of the filter matrix for short axes); the tap weights are the cubic B-spline
basis values :math:`\beta^3` and their derivatives at the fractional positions. Arrays
keep the data's precision (float32 taps for float32 phase).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from harpx._blas import column_block

# Voxels of smooth extension beyond the field of view before cubic prefiltering.
_EDGE = 4
#: A leading grid axis at most this long is prefiltered by a matrix product (see _prefilter).
_MATRIX_MAX = 64
#: The cubic B-spline prefilter's pole, √3 − 2.
_POLE = float(np.sqrt(3.0) - 2.0)


def _tap_dtype(*arrays: NDArray[np.floating]) -> np.dtype[np.floating]:
    """Precision of the spline coefficients: that of the data (float32 or float64).

    float32 data (the :func:`~harpx.imaging.harp.extract_phase` default) holds ~7 digits, so
    coefficients in float32 lose nothing it has (phase rounding ~1e-7 rad, far below any
    tracking tolerance) and halve the memory traffic of the prefilter and of every gather.
    """
    return np.result_type(*arrays)


def _tap_array(
    shape: tuple[int, ...], buffer: NDArray[np.floating] | None, dtype: np.dtype[np.floating]
) -> NDArray[np.floating]:
    """An uninitialised ``dtype`` array of ``shape``, a view of ``buffer`` where it fits.

    Reusing one buffer across frames avoids allocating (and the kernel zero-filling) some
    hundred MB of fresh pages per frame.
    """
    size = int(np.prod(shape))
    if buffer is not None and buffer.size >= size and buffer.dtype == dtype:
        return buffer.reshape(-1)[:size].reshape(shape)
    return np.empty(shape, dtype=dtype)


def _demodulated_taps(
    phase: NDArray[np.floating],
    magnitude: NDArray[np.floating],
    carrier: NDArray[np.floating],
    squeeze: tuple[int, ...],
    buffer: NDArray[np.floating] | None = None,
) -> NDArray[np.floating]:
    """Real and imaginary parts of ``|H| exp(i(φ − k·x))`` per tag, padded by one voxel.

    Returns an array of shape ``(*active grid shape + 2, 2 ntag)``: channels ``0..ntag-1``
    hold the real parts, ``ntag..2 ntag-1`` the imaginary parts, and every active axis has
    one reflected voxel (``mode="reflect"``: index −1 mirrors index 1) at each end.
    """
    ntag = phase.shape[0]
    keep = [a for a in range(3) if a + 1 not in squeeze]
    shape = tuple(phase.shape[a + 1] for a in keep)
    out = _tap_array(
        tuple(n + 2 for n in shape) + (2 * ntag,), buffer, _tap_dtype(phase, magnitude)
    )
    inner: tuple[slice | int, ...] = (slice(1, -1),) * len(shape)
    _write_demodulated(phase, magnitude, carrier, squeeze, lambda c: out[(*inner, c)])
    if not _finite(phase, magnitude):
        np.nan_to_num(out[inner], copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    _reflect_border(out, shape)
    return out


def _finite(*arrays: NDArray[np.floating]) -> bool:
    """Whether every value of every array is finite."""
    return all(bool(np.isfinite(a).all()) for a in arrays)


def _write_demodulated(
    phase: NDArray[np.floating],
    magnitude: NDArray[np.floating],
    carrier: NDArray[np.floating],
    squeeze: tuple[int, ...],
    channel: Callable[[int], NDArray[np.floating]],
) -> None:
    """Write Re and Im of ``|H| exp(i(φ − k·x))`` of tag ``t`` into channels ``t``, ``ntag + t``."""
    ntag = phase.shape[0]
    # scratch in the phase's precision, allocated once; |H| cos and |H| sin are formed in
    # the channel's precision (that of the data, see _tap_dtype)
    theta = np.empty(phase.shape[1:], dtype=np.result_type(phase, carrier))
    part = np.empty_like(theta)
    drop = tuple(a - 1 for a in squeeze)
    for t in range(ntag):
        np.subtract(phase[t], carrier[t], out=theta)
        mag = magnitude[t].squeeze(axis=drop) if squeeze else magnitude[t]
        for c, function in ((t, np.cos), (ntag + t, np.sin)):
            function(theta, out=part)
            np.multiply(mag, part.squeeze(axis=drop) if squeeze else part, out=channel(c))


def _reflect_border(out: NDArray[np.floating], shape: tuple[int, ...]) -> None:
    """Fill the one-voxel border of ``out`` (inner ``shape``) by reflection, axis by axis."""
    for axis, n in enumerate(shape):
        lead: list[slice | int] = [slice(None)] * out.ndim
        src: list[slice | int] = [slice(None)] * out.ndim
        lead[axis], src[axis] = 0, 2 if n > 1 else 1
        out[tuple(lead)] = out[tuple(src)]
        lead[axis], src[axis] = -1, -3 if n > 1 else -2
        out[tuple(lead)] = out[tuple(src)]


def _cubic_taps(
    phase: NDArray[np.floating],
    magnitude: NDArray[np.floating],
    carrier: NDArray[np.floating],
    squeeze: tuple[int, ...],
    before: NDArray[np.int64],
    after: NDArray[np.int64],
    buffer: NDArray[np.floating] | None = None,
) -> NDArray[np.floating]:
    """Cubic B-spline coefficients of ``|H| exp(i(φ − k·x))`` per tag, tap-ready.

    Each tag's demodulated image is written (real and imaginary parts as separate channels,
    channel-last as :func:`_demodulated_taps` lays them out) into an array extended by
    ``before``/``after`` voxels of odd reflection (``2 D[0] − D[k]``) per active axis,
    prefiltered in place along each axis (mirror boundary), and given a reflected one-voxel
    border. The same numbers as ``np.pad(..., mode="reflect", reflect_type="odd")`` followed
    by :func:`scipy.ndimage.spline_filter`, without complex temporaries or copies.
    """
    ntag = phase.shape[0]
    keep = [a for a in range(3) if a + 1 not in squeeze]
    shape = tuple(phase.shape[a + 1] for a in keep)
    d = len(shape)
    lead = [int(b) for b in before]
    trail = [int(e) for e in after]
    ext = tuple(n + b + e for n, b, e in zip(shape, lead, trail, strict=True))
    out = _tap_array((*(n + 2 for n in ext), 2 * ntag), buffer, _tap_dtype(phase, magnitude))
    work = out[(slice(1, -1),) * d]
    core = tuple(slice(b, b + n) for n, b in zip(shape, lead, strict=True))
    # with float32 phase and carrier, cos/sin run in float32 (SIMD, about 3x faster)
    _write_demodulated(phase, magnitude, carrier, squeeze, lambda c: work[core][..., c])
    # a NaN voxel would spread over the whole slice through the spline prefilter; as 0 it
    # falls below the magnitude floor and stays invalid where it is
    if not _finite(phase, magnitude):
        np.nan_to_num(work, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    for a in range(d):  # odd reflection, one axis after the other (as np.pad does)
        b, e, n = lead[a], trail[a], shape[a]

        def sl(start: int, stop: int | None, step: int = 1, axis: int = a) -> tuple:
            # the axes after this one are not extended yet: only their core is written
            # (the rest is uninitialised memory, which doubled could overflow)
            index: list[slice | int] = [slice(None)] * work.ndim
            index[axis + 1 : d] = core[axis + 1 :]
            index[axis] = slice(start, stop, step)
            return tuple(index)

        if b:  # D[b - k] = 2 D[b] - D[b + k]
            np.subtract(2.0 * work[sl(b, b + 1)], work[sl(2 * b, b, -1)], out=work[sl(0, b)])
        if e:  # D[b + n - 1 + k] = 2 D[b + n - 1] - D[b + n - 1 - k]
            stop = b + n - 2 - e
            np.subtract(
                2.0 * work[sl(b + n - 1, b + n)],
                work[sl(b + n - 2, stop if stop >= 0 else None, -1)],
                out=work[sl(b + n, b + n + e)],
            )
    for a in range(1, d):  # the leading-axis product also runs over the borders of the
        index: list[slice | int] = [slice(None)] * out.ndim  # others: keep them finite
        for end in (0, -1):
            index[a] = end
            out[tuple(index)] = 0.0
    _prefilter(out, work)
    _reflect_border(out, ext)
    return out


def _prefilter(out: NDArray[np.floating], work: NDArray[np.floating]) -> None:
    """Cubic B-spline prefilter (mirror boundary) of ``work`` in place along every grid axis.

    ``work`` is the interior (all but a one-voxel border per grid axis) of the C-contiguous
    ``out``, channels last. The numbers are those of :func:`scipy.ndimage.spline_filter1d`
    along each axis in turn, to rounding (~1e-16 relative), computed faster than its
    line-by-line recursion (latency-bound, ~7 ns a value): a short leading axis (at most
    :data:`_MATRIX_MAX` samples, e.g. the slices) by one matrix product with the filter's
    exact matrix, the other leading axes by the same recursion vectorised over whole
    slabs, and the last axis (whose lines are nearly contiguous) by scipy itself.
    """
    d = work.ndim - 1
    for a in range(d - 1):
        n = work.shape[a]
        if a == 0 and n <= _MATRIX_MAX:
            _prefilter_leading_matrix(out, n)
        else:
            _prefilter_recursive(work, a)
    ndimage.spline_filter1d(work, order=3, axis=d - 1, mode="mirror", output=work)


@functools.lru_cache(maxsize=16)
def _filter_matrix(n: int) -> NDArray[np.float64]:
    """The cubic prefilter (mirror) of ``n`` samples as an (n, n) matrix: scipy's, exactly."""
    matrix = ndimage.spline_filter1d(np.eye(n), order=3, axis=0, mode="mirror")
    matrix.flags.writeable = False
    return matrix


def _prefilter_leading_matrix(out: NDArray[np.floating], n: int) -> None:
    """Prefilter along axis 0 of ``out[1:-1]`` (``n`` samples) as a matrix product.

    ``out[1:-1]`` is contiguous, so it is an (n, rest) matrix; it is multiplied by the
    filter matrix in column blocks small enough for OpenBLAS to stay on one thread (see
    :mod:`harpx._blas`; its idle threads spin, which costs more than they save). Its border columns
    (the other axes' one-voxel borders, not yet written) are transformed too and
    overwritten afterwards by :func:`_reflect_border`; each column is independent.
    """
    matrix = _filter_matrix(n).astype(out.dtype, copy=False)
    flat = out[1:-1].reshape(n, -1)
    block = column_block(n, n)
    tmp = np.empty((n, block), dtype=out.dtype)
    for start in range(0, flat.shape[1], block):
        part = flat[:, start : start + block]
        product = tmp[:, : part.shape[1]]
        np.matmul(matrix, part, out=product)
        part[...] = product


def _prefilter_recursive(work: NDArray[np.floating], axis: int) -> None:
    """scipy's cubic mirror prefilter along ``axis``, vectorised over everything else.

    The operations and their order are those of scipy's ``ni_splines.c`` (gain, causal
    mirror initialisation, causal pass, anticausal initialisation, anticausal pass); the
    causal initialisation stops where the pole's powers fall below 1e-19.
    """
    c = np.moveaxis(work, axis, 0)
    n = c.shape[0]
    if n < 2:
        return
    z = _POLE
    c *= (1.0 - z) * (1.0 - 1.0 / z)
    tmp = np.empty(c.shape[1:], dtype=c.dtype)
    z_n_1 = z ** (n - 1)
    first = c[0] + z_n_1 * c[n - 1]
    z_i = z
    for i in range(1, n - 1):
        if abs(z_i) < 1e-19:
            break
        np.multiply(c[n - 1 - i], z_n_1, out=tmp)
        tmp += c[i]
        tmp *= z_i
        first += tmp
        z_i *= z
    first /= 1.0 - z_n_1 * z_n_1
    c[0] = first
    for i in range(1, n):
        np.multiply(c[i - 1], z, out=tmp)
        c[i] += tmp
    c[n - 1] = (z * c[n - 2] + c[n - 1]) * z / (z * z - 1.0)
    for i in range(n - 2, -1, -1):
        np.subtract(c[i + 1], c[i], out=c[i])
        c[i] *= z


def _weights(t: NDArray[np.floating], order: int) -> NDArray[np.floating]:
    """B-spline tap weights (``[..., 0, :]``) and their derivatives (``[..., 1, :]``).

    ``t`` holds fractions in [0, 1) of any shape; the result has shape
    ``(*t.shape, 2, order + 1)``, in the precision of ``t``.
    """
    out = np.empty((*t.shape, 2, order + 1), dtype=t.dtype)
    if order == 1:
        out[..., 0, 0] = 1 - t
        out[..., 0, 1] = t
        out[..., 1, 0] = -1.0
        out[..., 1, 1] = 1.0
        return out
    t2 = t * t
    t3 = t2 * t
    s = 1.0 - t
    out[..., 0, 0] = s**3 / 6
    out[..., 0, 1] = (3 * t3 - 6 * t2 + 4) / 6
    out[..., 0, 2] = (-3 * t3 + 3 * t2 + 3 * t + 1) / 6
    out[..., 0, 3] = t3 / 6
    out[..., 1, 0] = -(s * s) / 2
    out[..., 1, 1] = (3 * t2 - 4 * t) / 2
    out[..., 1, 2] = (-3 * t2 + 2 * t + 1) / 2
    out[..., 1, 3] = t2 / 2
    return out


def _tensor_weights(weights: NDArray[np.floating], nq: int) -> NDArray[np.floating]:
    """Tensor-product weights (m, nq, taps**d) of ``weights`` (m, d, 2, taps).

    Output q=0 is the value, q=j the derivative along axis j-1.
    """
    m, d = weights.shape[:2]
    tensor: NDArray[np.floating] | None = None
    for a in range(d):
        # per output q: derivative weights along axis a when q == a + 1, else value weights
        select = [1 if q == a + 1 else 0 for q in range(nq)]
        factor = weights[:, a, select]  # (m, nq, taps)
        if tensor is None:
            tensor = factor
        else:
            tensor = (tensor[..., :, None] * factor[..., None, :]).reshape(m, nq, -1)
    assert tensor is not None
    return tensor
