"""FFTs through pyfftw with a cache of plans that own aligned buffers.

Every transform goes through :func:`get_plan` (for grid-sized transforms whose buffers
should not outlive their use, with ``cached=False``, or :func:`inplace_plans`),
which returns a :class:`pyfftw.FFTW` object for one exact ``(shape, dtype, axes, threads,
direction)``. Plans are created once, with
``FFTW_MEASURE`` for arrays of at least ``MEASURE_MIN_SIZE`` elements and ``FFTW_ESTIMATE``
below (measuring a small plan costs more than it saves; FFTW's wisdom is kept for the life
of the process), and cached per calling thread, so that threads of a pool never share a
plan's buffers. A cached plan *owns* its SIMD-aligned ``input_array`` and ``output_array``:
callers copy data into ``plan.input_array``, call ``plan.execute()`` and read
``plan.output_array``. Nothing in harpx calls ``update_arrays`` on a cached plan, so the
buffers stay valid for kernels that keep sparse data in them between calls (see
:mod:`harpx.imaging._kernels`).

Why this design (``benchmarks/bench_phase.py``, ``benchmarks/results/phase.md``): direct
execution on owned aligned buffers is as fast as ``pyfftw.builders`` and faster than the
``pyfftw.interfaces`` cache, which re-checks and may copy its arrays on every call; numpy.fft
is 2-3 times slower.

The public helpers (:func:`fft2`, :func:`ifft2`, :func:`rfft2`, :func:`irfft2`) follow the
numpy conventions (unnormalised forward, ``1/n`` inverse) over the last two axes and return
new arrays.
"""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from collections.abc import Sequence
from typing import Literal

import numpy as np
import pyfftw
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "default_threads",
    "fft2",
    "get_plan",
    "ifft2",
    "inplace_plans",
    "irfft2",
    "rfft2",
]

#: FFTW planner effort of cached plans with at least MEASURE_MIN_SIZE elements.
PLANNER_EFFORT = "FFTW_MEASURE"
#: Smaller transforms are planned with FFTW_ESTIMATE: measuring costs more than it saves.
MEASURE_MIN_SIZE = 1 << 20
#: In-place plans executed fewer times than this are planned with FFTW_ESTIMATE: measuring
#: costs about as much as it saves over this many runs of a stack of image planes
#: (benchmarks/results/tracking_speed.md).
MEASURE_PAYS_AFTER = 160
#: Plans kept per thread (least recently used are dropped; each holds two buffers).
MAX_PLANS_PER_THREAD = 24

Direction = Literal["forward", "backward"]

_PLAN_LOCK = threading.Lock()
_LOCAL = threading.local()


def default_threads(threads: int | None = None) -> int:
    """Number of FFT threads: ``threads`` if given, else ``os.cpu_count()``.

    Parameters
    ----------
    threads : int or None
        Requested number of threads (>= 1), or None for all available cores.

    Returns
    -------
    int
        The number of threads to use.

    Raises
    ------
    ValueError
        If ``threads`` is not a positive integer.
    """
    if threads is None:
        return max(1, os.cpu_count() or 1)
    if isinstance(threads, bool) or not isinstance(threads, int | np.integer) or threads < 1:
        raise ValueError(f"'threads' must be a positive integer or None, got {threads!r}")
    return int(threads)


def _cache() -> OrderedDict[tuple, pyfftw.FFTW]:
    cache = getattr(_LOCAL, "plans", None)
    if cache is None:
        cache = OrderedDict()
        _LOCAL.plans = cache
    return cache


def get_plan(
    shape: Sequence[int],
    dtype: np.dtype | type,
    axes: Sequence[int],
    *,
    direction: Direction,
    threads: int | None = None,
    cached: bool = True,
) -> pyfftw.FFTW:
    """Cached FFTW plan that owns aligned input and output buffers.

    The transform kind follows the input dtype and direction: a real input with
    ``direction="forward"`` is a real-to-complex transform (last axis of ``axes`` halved to
    ``n // 2 + 1``), a complex input with ``direction="backward"`` and ``dtype`` real means the
    *output* is real (complex-to-real, ``shape`` is then the real output shape), otherwise
    complex-to-complex.

    Parameters
    ----------
    shape : sequence of int
        Shape of the real-space array (input for forward, output for backward transforms).
    dtype : numpy dtype
        ``float64`` for real-to-complex / complex-to-real plans, ``complex128`` otherwise.
    axes : sequence of int
        Axes transformed (negative values allowed).
    direction : {"forward", "backward"}
        Sign of the exponent; backward plans are *not* normalised by ``execute()``.
    threads : int or None
        FFTW threads of this plan; None means ``os.cpu_count()``.
    cached : bool, default True
        False: a new plan, not kept in the cache, whose buffers live as long as it does (for
        a transform too large to keep between calls; a second planning of the same problem
        takes FFTW's wisdom and costs little).

    Returns
    -------
    pyfftw.FFTW
        The plan; use ``plan.input_array``, ``plan.execute()`` and ``plan.output_array``.
    """
    shape = tuple(int(s) for s in shape)
    dtype = np.dtype(dtype)
    axes = tuple(int(a) % len(shape) for a in axes)
    nthreads = default_threads(threads)
    if not cached:
        return _new_plan(shape, dtype, axes, direction, nthreads)
    key = (shape, dtype.str, axes, nthreads, direction)
    cache = _cache()
    plan = cache.get(key)
    if plan is not None:
        cache.move_to_end(key)
        return plan
    plan = _new_plan(shape, dtype, axes, direction, nthreads)
    cache[key] = plan
    while len(cache) > MAX_PLANS_PER_THREAD:
        cache.popitem(last=False)
    return plan


def _new_plan(
    shape: tuple[int, ...], dtype: np.dtype, axes: tuple[int, ...], direction: Direction,
    nthreads: int,
) -> pyfftw.FFTW:  # fmt: skip
    """A new plan of :func:`get_plan`'s kind from its normalised arguments."""
    real = dtype.kind == "f"
    half = list(shape)
    half[axes[-1]] = shape[axes[-1]] // 2 + 1
    if direction == "forward":
        in_shape, in_dtype = shape, dtype
        out_shape = tuple(half) if real else shape
        out_dtype = np.result_type(dtype, np.complex64)
    elif direction == "backward":
        out_shape, out_dtype = shape, dtype
        in_shape = tuple(half) if real else shape
        in_dtype = np.result_type(dtype, np.complex64)
    else:
        raise ValueError(f"'direction' must be 'forward' or 'backward', got {direction!r}")
    effort = PLANNER_EFFORT if int(np.prod(shape)) >= MEASURE_MIN_SIZE else "FFTW_ESTIMATE"
    with _PLAN_LOCK:  # the FFTW planner is not thread safe
        inp = pyfftw.empty_aligned(in_shape, dtype=in_dtype)
        out = pyfftw.empty_aligned(out_shape, dtype=out_dtype)
        return pyfftw.FFTW(
            inp,
            out,
            axes=axes,
            direction="FFTW_FORWARD" if direction == "forward" else "FFTW_BACKWARD",
            flags=(effort,),
            threads=nthreads,
        )


def inplace_plans(
    shape: Sequence[int],
    dtype: np.dtype | type,
    axes: Sequence[int],
    *,
    threads: int | None = None,
    memory: NDArray[np.complexfloating] | None = None,
    executions: int | None = None,
) -> tuple[NDArray[np.complexfloating], pyfftw.FFTW, pyfftw.FFTW]:
    """One aligned complex buffer with a forward and a backward plan that transform it in place.

    Not cached: the caller holds the buffer (and its two plans) for as long as it needs them,
    a third of the memory of :func:`get_plan`'s forward and backward plans, which own an
    input and an output buffer each and stay in the cache. Planned like :func:`get_plan`
    (``FFTW_MEASURE`` from ``MEASURE_MIN_SIZE`` elements; FFTW's wisdom makes a second
    planning of the same problem cheap), unless ``executions`` says the plans will not run
    often enough for measuring to pay (fewer than ``MEASURE_PAYS_AFTER`` times each).

    Parameters
    ----------
    shape : sequence of int
        Shape of the buffer.
    dtype : numpy dtype
        ``complex64`` or ``complex128``.
    axes : sequence of int
        Axes transformed (negative values allowed).
    threads : int or None
        FFTW threads of both plans; None means ``os.cpu_count()``.
    memory : ndarray, optional
        A C-contiguous, SIMD-aligned array of ``dtype`` (from an earlier call) whose memory
        the buffer takes, reshaped, so that transforms of several shapes of one size share
        it; planning overwrites its content.
    executions : int, optional
        How many times the caller will execute each plan (None: often).

    Returns
    -------
    buffer : ndarray of ``dtype``, shape ``shape``
        Fill it, call ``forward.execute()`` or ``backward.execute()`` (unnormalised) and read
        it.
    forward, backward : pyfftw.FFTW
        The plans.

    Raises
    ------
    ValueError
        If ``dtype`` is not complex, or ``memory`` does not fit.
    """
    shape = tuple(int(s) for s in shape)
    dtype = np.dtype(dtype)
    if dtype.kind != "c":
        raise ValueError(f"in-place plans need a complex dtype, got {dtype!r}")
    axes = tuple(int(a) % len(shape) for a in axes)
    nthreads = default_threads(threads)
    often = executions is None or executions >= MEASURE_PAYS_AFTER
    effort = (
        PLANNER_EFFORT if often and int(np.prod(shape)) >= MEASURE_MIN_SIZE else "FFTW_ESTIMATE"
    )
    if memory is not None and (
        memory.dtype != dtype or memory.size != int(np.prod(shape)) or not memory.flags.c_contiguous
    ):
        raise ValueError(
            f"'memory' must be a C-contiguous {dtype} array of {int(np.prod(shape))} elements, "
            f"got {memory.dtype} of shape {memory.shape!r}"
        )
    with _PLAN_LOCK:  # the FFTW planner is not thread safe
        buffer = (
            pyfftw.empty_aligned(shape, dtype=dtype) if memory is None else memory.reshape(shape)
        )
        forward, backward = (
            pyfftw.FFTW(
                buffer, buffer, axes=axes, direction=direction, flags=(effort,), threads=nthreads
            )  # fmt: skip
            for direction in ("FFTW_FORWARD", "FFTW_BACKWARD")
        )
    return buffer, forward, backward


def _run(
    a: NDArray,
    dtype: np.dtype,
    direction: Direction,
    threads: int | None,
    shape: tuple[int, ...],
    scale: float,
) -> NDArray:
    plan = get_plan(shape, dtype, (-2, -1), direction=direction, threads=threads)
    np.copyto(plan.input_array, a, casting="same_kind")
    plan.execute()
    out = np.empty(plan.output_array.shape, dtype=plan.output_array.dtype)
    if scale == 1.0:
        np.copyto(out, plan.output_array)
    else:
        np.multiply(plan.output_array, scale, out=out)
    return out


def _check2d(a: NDArray, name: str) -> None:
    if a.ndim < 2:
        raise ValueError(f"{name!r} needs at least 2 dimensions, got shape {a.shape!r}")


def fft2(a: ArrayLike, *, threads: int | None = None) -> NDArray[np.complex128]:
    """Forward 2D FFT over the last two axes (unnormalised, like :func:`numpy.fft.fft2`).

    Parameters
    ----------
    a : array_like, shape (..., n1, n2)
        Real or complex data (any units).
    threads : int or None
        FFTW threads; None means ``os.cpu_count()``.

    Returns
    -------
    ndarray of complex128, shape (..., n1, n2)
        The spectrum (same units as ``a``).

    Examples
    --------
    >>> from harpx.imaging.fft import fft2
    >>> bool(np.allclose(fft2(np.eye(4)), np.fft.fft2(np.eye(4))))
    True
    """
    a = np.asarray(a)
    _check2d(a, "a")
    return _run(a, np.dtype(np.complex128), "forward", threads, a.shape, 1.0)


def ifft2(a: ArrayLike, *, threads: int | None = None) -> NDArray[np.complex128]:
    """Inverse 2D FFT over the last two axes, normalised by ``1/(n1 n2)`` like numpy.

    Parameters
    ----------
    a : array_like, shape (..., n1, n2)
        Complex spectrum.
    threads : int or None
        FFTW threads; None means ``os.cpu_count()``.

    Returns
    -------
    ndarray of complex128, shape (..., n1, n2)
        The inverse transform.
    """
    a = np.asarray(a)
    _check2d(a, "a")
    n = a.shape[-1] * a.shape[-2]
    return _run(a, np.dtype(np.complex128), "backward", threads, a.shape, 1.0 / n)


def rfft2(a: ArrayLike, *, threads: int | None = None) -> NDArray[np.complex128]:
    """Real-to-complex 2D FFT over the last two axes (like :func:`numpy.fft.rfft2`).

    Parameters
    ----------
    a : array_like of float, shape (..., n1, n2)
        Real data.
    threads : int or None
        FFTW threads; None means ``os.cpu_count()``.

    Returns
    -------
    ndarray of complex128, shape (..., n1, n2 // 2 + 1)
        The non-negative half of the spectrum along the last axis.

    Raises
    ------
    ValueError
        If ``a`` has fewer than 2 dimensions or is complex.
    """
    a = np.asarray(a)
    _check2d(a, "a")
    if np.iscomplexobj(a):
        raise ValueError(f"rfft2 needs real input, got dtype {a.dtype!r}; use fft2")
    return _run(a, np.dtype(np.float64), "forward", threads, a.shape, 1.0)


def irfft2(
    a: ArrayLike, shape: Sequence[int], *, threads: int | None = None
) -> NDArray[np.float64]:
    """Complex-to-real inverse 2D FFT over the last two axes (like :func:`numpy.fft.irfft2`).

    Parameters
    ----------
    a : array_like of complex, shape (..., n1, n2 // 2 + 1)
        Half spectrum.
    shape : sequence of int
        ``(n1, n2)``, the real output size of the last two axes.
    threads : int or None
        FFTW threads; None means ``os.cpu_count()``.

    Returns
    -------
    ndarray of float64, shape (..., n1, n2)
        The real inverse transform, normalised by ``1/(n1 n2)``.

    Raises
    ------
    ValueError
        If ``a`` has fewer than 2 dimensions or its last two do not match ``shape``.
    """
    a = np.asarray(a)
    _check2d(a, "a")
    n1, n2 = (int(s) for s in shape)
    if a.shape[-2] != n1 or a.shape[-1] != n2 // 2 + 1:
        raise ValueError(
            f"half spectrum of shape {a.shape!r} does not match output shape {(n1, n2)!r}; "
            f"expected last two dims ({n1}, {n2 // 2 + 1})"
        )
    out_shape = (*a.shape[:-2], n1, n2)
    # the c2r transform destroys its input: it is the plan's own buffer, refilled every call
    return _run(a, np.dtype(np.float64), "backward", threads, out_shape, 1.0 / (n1 * n2))
