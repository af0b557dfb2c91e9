r"""Harmonic phase of tagged images: ``tagged/1`` → ``phase/1`` (paper §3.2).

For every tag the acquisition slices (normal to that tag's ``slice_axis``) are cubic-spline
upsampled in-plane, band-passed with a disk around the tag frequency and inverse
transformed; the complex harmonic image is interpolated between slices onto the common
refined grid, and its angle and modulus are the ``phase`` and ``magnitude``. The numpy work
lives in :mod:`harpx.imaging._kernels`; this module maps dims, keeps dask inputs lazy and
labels the result.
"""

from __future__ import annotations

import warnings
from collections.abc import Hashable
from typing import Literal

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from harpx.errors import HarpxWarning, SchemaError, user_stacklevel
from harpx.imaging._kernels import refine_linear, refine_positions
from harpx.imaging.bandpass import harmonic_phase
from harpx.imaging.fft import default_threads
from harpx.imaging.noise import harmonic_noise
from harpx.imaging.phase_parameters import (
    DEFAULT_RADIUS,
    DEFAULT_UPSAMPLE,
    spamm_dc_message,
)
from harpx.imaging.tag_frequency import measure_tag_peak, tag_frequency_mismatch
from harpx.schema import AXES, GRID_DIMS, grid_step, standard_attrs, validate

__all__ = ["extract_phase", "refinement_factors", "slice_geometry"]


def _check_upsample(upsample: int) -> None:
    if isinstance(upsample, bool) or not isinstance(upsample, int | np.integer) or upsample < 1:
        raise ValueError(
            f"'upsample' must be an integer >= 1 (1 = native resolution), got {upsample!r}"
        )


def _warn_spamm_dc(ds: xr.Dataset, radius: float) -> None:
    """HarpxWarning when SPAMM images are band-passed so wide that the zero-frequency peak
    leaks into the harmonic image."""
    message = spamm_dc_message(str(ds.attrs.get("sequence")), float(radius))
    if message:
        warnings.warn(f"phase(): {message}", HarpxWarning, stacklevel=user_stacklevel())


def _check_options(upsample: int, radius: float) -> None:
    _check_upsample(upsample)
    if (
        isinstance(radius, bool)
        or not isinstance(radius, float | int | np.floating)
        or not (0.0 < float(radius) <= 1.0)
    ):
        raise ValueError(
            f"'radius' must be in (0, 1] (filter radius as a fraction of the tag frequency), "
            f"got {radius!r}"
        )


def _warn_constant_frames(ds: xr.Dataset) -> None:
    """HarpxWarning naming the frames whose image is one value within the tag's mask.

    Such a frame has no tag pattern: its harmonic magnitude is zero and its phase
    meaningless. Only images held in memory are checked (a dask image is not computed).
    """
    values = (
        ds["image"].transpose("tag", "time", *GRID_DIMS).values
        if isinstance(ds["image"].variable.data, np.ndarray)
        else None
    )
    if values is None:
        return
    mask = None
    if "mask" in ds.variables:
        mask = np.asarray(ds["mask"].transpose("tag", *GRID_DIMS).values, dtype=bool)
    found: list[str] = []
    dropped: set[int] = set()
    for t, tag in enumerate(str(v) for v in np.asarray(ds["tag"].values).ravel()):
        frames = values[t].reshape(values.shape[1], -1)
        if mask is not None:
            if not mask[t].any():
                continue  # no data at all: validate and the tracker name that
            frames = frames[:, mask[t].ravel()]
        low, high = frames.min(axis=1), frames.max(axis=1)
        flat = np.flatnonzero(low == high)
        if flat.size:
            value = float(low[flat[0]])
            where = "in its mask " if mask is not None else ""
            found.append(
                f"tag {tag!r} frame(s) {flat[:10].tolist()}{' …' if flat.size > 10 else ''} "
                f"(every voxel {where}is {value:g}{': a blank frame' if value == 0 else ''})"
            )
            dropped.update(int(n) for n in flat)
    if found:
        warnings.warn(
            f"constant images: {'; '.join(found)}. A constant image has no tag pattern, so "
            "its phase carries no motion (harmonic magnitude 0) and tracking cannot use it; "
            f"fix those frames or drop them (ds.drop_isel(time={sorted(dropped)[:10]}))",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )


def _checked_tag_frequency(ds: xr.Dataset, lazy: bool, check: bool) -> dict[str, xr.Variable]:
    """``tag_frequency_measured`` (tag) and ``tag_peak_measured`` (tag, axis) from the first
    frame of the images ``ds``; warns if they miss the stated frequency or direction.

    NaN throughout without ``check``. For dask-backed images they stay lazy and nothing is
    checked here (the trackers check them when they read the phase).
    """
    others = [n for n in ds.data_vars if n not in ("image", "mask")]  # e.g. the truth
    first = ds.drop_vars(others).isel(time=[0])
    attrs = standard_attrs("tag_frequency_measured")
    shape = (ds.sizes["tag"], len(AXES))
    if not check:
        peak = np.full(shape, np.nan)
    elif lazy:
        import dask
        import dask.array

        peak = dask.array.from_delayed(dask.delayed(measure_tag_peak)(first), shape, float)
    else:
        peak = measure_tag_peak(first)
    measured = (peak**2).sum(axis=1) ** 0.5
    if check and not lazy:
        message = tag_frequency_mismatch(ds, measured, peak)
        if message:
            warnings.warn(message, HarpxWarning, stacklevel=user_stacklevel())
    return {
        "tag_frequency_measured": xr.Variable(("tag",), measured, attrs),
        "tag_peak_measured": xr.Variable(
            ("tag", "axis"), peak, standard_attrs("tag_peak_measured")
        ),
    }


def refinement_factors(ds: xr.Dataset, upsample: int) -> tuple[int, int, int]:
    """Integer refinement factor per grid axis ``(z, y, x)`` of the common output grid.

    Axes that lie in the acquisition plane of at least one tag are refined towards the
    isotropic in-plane spacing ``d_min / upsample``, where ``d_min`` is the smallest spacing
    among those axes: factor ``upsample * max(1, round(d / d_min))`` (integer so that the
    refined grid stays aligned with the native voxels). Axes that are only ever slice axes
    keep their native spacing (factor 1).

    Parameters
    ----------
    ds : xarray.Dataset
        A ``tagged/1`` dataset.
    upsample : int
        Requested in-plane upsampling factor (>= 1).

    Returns
    -------
    tuple of int
        Factors for ``(z, y, x)``.

    Raises
    ------
    SchemaError
        If an in-plane axis has fewer than 2 voxels.
    ValueError
        If ``upsample`` is not an integer >= 1.
    """
    _check_upsample(upsample)
    slice_axes = [str(s) for s in np.asarray(ds["slice_axis"].values).ravel()]
    inplane = sorted({d for s in slice_axes for d in GRID_DIMS if d != s}, key=GRID_DIMS.index)
    spacing = {}
    for dim in inplane:
        step = grid_step(ds, dim)
        if step is None:
            raise SchemaError(
                f"grid dim {dim!r} has {ds.sizes[dim]} voxel(s) but lies in the acquisition "
                "plane of a tag; in-plane axes need at least 2 voxels to be band-passed"
            )
        spacing[dim] = step
    dmin = min(spacing.values())
    fz, fy, fx = (
        int(upsample) * max(1, round(spacing[d] / dmin)) if d in spacing else 1 for d in GRID_DIMS
    )
    return fz, fy, fx


def _check_chunks(ds: xr.Dataset, names: list[str]) -> bool:
    """True if ``image`` is dask-backed; SchemaError if any variable is chunked in space."""
    for name in names:
        var = ds[name]
        if var.chunks is None:
            continue
        for dim in GRID_DIMS:
            n = len(var.chunksizes[dim])
            if n > 1:
                raise SchemaError(
                    f"{name!r} is chunked along core dim {dim!r} ({n} chunks); every slice must "
                    f"be one chunk: rechunk with ds.chunk({{{dim!r}: -1}}) (chunk over 'tag' or "
                    "'time' instead)"
                )
    return ds["image"].chunks is not None


def _phase_block(
    image: NDArray,
    freq: NDArray[np.float64],
    slice_index: NDArray[np.int64],
    *,
    spacing: tuple[float, float, float],
    factors: tuple[int, int, int],
    radius: float,
    threads: int,
    dtype: np.dtype,
) -> tuple[NDArray[np.floating], NDArray[np.floating]]:
    """Phase and magnitude of a block (tag, time, z, y, x); loops over its (<= 3) tags."""
    shape = (*image.shape[:-3], *(n * m for n, m in zip(image.shape[-3:], factors, strict=True)))
    phase, magnitude = np.empty(shape, dtype), np.empty(shape, dtype)
    for t in range(image.shape[0]):
        harmonic_phase(
            image[t],
            spacing=spacing,
            freq=freq[t].reshape(-1, 3)[0],
            slice_axis=int(slice_index[t].ravel()[0]),
            radius=radius,
            upsample=factors,
            threads=threads,
            out=(phase[t], magnitude[t]),
            dtype=dtype,
        )
    return phase, magnitude


def _refined_coord(ds: xr.Dataset, dim: str, factor: int) -> xr.Variable:
    values = np.asarray(ds[dim].values, dtype=np.float64)
    attrs = {**standard_attrs(dim), **ds[dim].attrs}
    if factor == 1:
        return xr.Variable(dim, values, attrs)
    step = grid_step(ds, dim)
    assert step is not None  # factor > 1 only on in-plane axes, which have >= 2 voxels
    return xr.Variable(dim, values[0] + step * refine_positions(values.size, factor), attrs)


def _refine_nearest(var: xr.Variable, factors: dict[str, int]) -> xr.Variable:
    """Each refined voxel takes the value of the native voxel that contains it."""
    index = {d: np.arange(var.sizes[d] * m) // m for d, m in factors.items() if m > 1}
    return var.isel(index) if index else var


def _refine_linear(var: xr.Variable, factors: tuple[int, int, int], threads: int) -> xr.Variable:
    """Linear interpolation onto the refined centres (constant beyond the ends), lazily."""
    sizes = {d: var.sizes[d] * m for d, m in zip(GRID_DIMS, factors, strict=True)}
    lead = [d for d in var.dims if d not in GRID_DIMS]
    return xr.apply_ufunc(
        refine_linear,
        var.transpose(*lead, *GRID_DIMS),
        input_core_dims=[list(GRID_DIMS)],
        output_core_dims=[list(GRID_DIMS)],
        exclude_dims=set(GRID_DIMS),
        dask="parallelized",
        output_dtypes=[np.float64],
        dask_gufunc_kwargs={"output_sizes": sizes},
        kwargs={"factors": factors, "threads": threads},
    )


#: Suffixes of the ad-hoc per-stack attributes the synthetic scenes write (``sa_``, ``la_``
#: prefixes): slice centres along the stack's normal and slice thickness, mm.
_STACK_ATTRS = ("_slice_positions_mm", "_slice_thickness_mm")


def slice_geometry(ds: xr.Dataset) -> dict[str, xr.Variable]:
    """Each tag's slice thickness and slice centres, as far as ``ds`` tells them.

    Sources, first that applies per tag:

    1. the standard coordinates ``slice_thickness`` (tag) and ``slice_position`` (tag,
       slice) (:mod:`harpx.schema`), taken as they are;
    2. a pair of stack attributes ``<p>_slice_positions_mm`` and ``<p>_slice_thickness_mm``
       (what the synthetic scenes write) whose slab, from half a thickness below the first
       centre to half above the last, is the tag's ``mask`` along its ``slice_axis`` (within
       a voxel at each end); a stack that matches no tag, or a tag matched by two stacks, is
       not used;
    3. ``attrs["slice_thickness"]`` when the grid along every tag's ``slice_axis`` is the
       slice lattice (:meth:`harpx.imaging.stacks.SliceStack.axis_aligned`'s convention):
       the centres are the grid coordinates along it.

    A tag none of them describes gets NaN: nothing is guessed, and the blur correction keeps
    its in-plane model for it (:func:`harpx.tracking.blur.blur_models`).

    Parameters
    ----------
    ds : xarray.Dataset
        ``tagged/1`` or ``phase/1`` dataset.

    Returns
    -------
    dict of str to xarray.Variable
        ``slice_thickness`` (tag) and ``slice_position`` (tag, slice), mm, NaN-padded; empty
        when no tag is described.

    Examples
    --------
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: 0 * X, shape=(2, 16, 16), spacing=(6.0, 1.5, 1.5), times=[0.0],
    ...     tags=("x",), snr=None, oversample=1, slice_thickness=6.0)
    >>> geometry = slice_geometry(tagged)
    >>> geometry["slice_thickness"].values.tolist(), geometry["slice_position"].values.tolist()
    ([6.0], [[-3.0, 3.0]])
    """
    if "slice_thickness" in ds.variables and "slice_position" in ds.variables:
        return {name: ds[name].variable for name in ("slice_thickness", "slice_position")}
    axes = [str(s) for s in np.asarray(ds["slice_axis"].values).ravel()]
    ntag = len(axes)
    found: list[list[tuple[float, NDArray[np.float64]]]] = [[] for _ in range(ntag)]
    prefixes = [k[: -len(_STACK_ATTRS[0])] for k in ds.attrs if str(k).endswith(_STACK_ATTRS[0])]
    mask = (  # read (computed, if lazy) only when a stack's attributes are to be matched
        np.asarray(ds["mask"].transpose("tag", *GRID_DIMS).values, dtype=bool)
        if "mask" in ds.variables and prefixes
        else None
    )
    for prefix in prefixes:
        if mask is None or prefix + _STACK_ATTRS[1] not in ds.attrs:
            continue
        centres = np.atleast_1d(np.asarray(ds.attrs[prefix + _STACK_ATTRS[0]], np.float64))
        thickness = float(ds.attrs[prefix + _STACK_ATTRS[1]])
        if not (centres.size and np.all(np.diff(centres) > 0) and thickness > 0):
            continue
        for t, axis in enumerate(axes):
            a = GRID_DIMS.index(axis)
            grid = np.asarray(ds[axis].values, dtype=np.float64)
            step = grid_step(ds, axis) or thickness
            held = mask[t].any(axis=tuple(b for b in range(3) if b != a))
            if not held.any():
                continue
            low, high = grid[held].min(), grid[held].max()
            slab = (centres[0] - 0.5 * thickness, centres[-1] + 0.5 * thickness)
            if abs(low - slab[0]) <= step + 1e-6 and abs(high - slab[1]) <= step + 1e-6:
                found[t].append((thickness, centres))
    thick = np.full(ntag, np.nan)
    positions: list[NDArray[np.float64]] = [np.empty(0)] * ntag
    for t in range(ntag):
        if len(found[t]) == 1:
            thick[t], positions[t] = found[t][0]
    lattice = float(ds.attrs.get("slice_thickness", np.nan))
    lattice_ok = lattice > 0 and all(
        (grid_step(ds, axis) or np.inf) >= lattice * (1 - 1e-6) for axis in axes
    )  # a grid finer than the slices is a resampled one, not the lattice
    if lattice_ok and not np.isfinite(thick).any():
        for t, axis in enumerate(axes):
            thick[t] = lattice
            positions[t] = np.asarray(ds[axis].values, dtype=np.float64)
    if not np.isfinite(thick).any():
        return {}
    count = max(p.size for p in positions)
    table = np.full((ntag, count), np.nan)
    for t, p in enumerate(positions):  # per tag (≤ 3)
        table[t, : p.size] = p
    return {
        "slice_thickness": xr.Variable(("tag",), thick, standard_attrs("slice_thickness")),
        "slice_position": xr.Variable(("tag", "slice"), table, standard_attrs("slice_position")),
    }


def extract_phase(
    ds: xr.Dataset,
    *,
    upsample: int = DEFAULT_UPSAMPLE,
    radius: float = DEFAULT_RADIUS,
    threads: int | None = None,
    dtype: Literal["float32", "float64"] = "float32",
) -> xr.Dataset:
    r"""Harmonic phase and magnitude of a ``tagged/1`` dataset (``phase/1``).

    Per tag, every 2D slice of its acquisition plane (the two axes other than its
    ``slice_axis``) is upsampled with cubic splines, band-passed with a disk centred on the
    tag frequency vector projected on that plane (radius ``radius`` × its length) and
    inverse Fourier transformed. The complex harmonic image :math:`H` is then linearly
    interpolated between slices onto the common refined grid, and

    .. math:: \varphi = \angle H \in [-\pi, \pi), \qquad |H|

    are returned. For an undeformed tag pattern :math:`\cos(2\pi f\,d\cdot X)` the phase is
    :math:`W(2\pi f\,d\cdot X)` (paper eq. 1).

    Parameters
    ----------
    ds : xarray.Dataset
        ``tagged/1`` dataset (``image`` (tag, time, z, y, x)); may be dask-backed, chunked over
        ``tag``/``time`` only.
    upsample : int, default 2
        In-plane upsampling factor (dimensionless, >= 1; 1 filters at native resolution).
        Refined spacing per axis is ``d_min / upsample`` for axes in some tag's plane (see
        :func:`refinement_factors`); the grid is refined by subdividing voxels, so the field
        of view is unchanged and the first refined centre is ``z[0] - (m-1) dz / (2m)``.
    radius : float, default 0.5
        Band-pass radius as a fraction of the tag frequency (dimensionless, in (0, 1]); 0.5
        keeps the DC peak of SPAMM images well out of the pass band (SPAMM above
        :data:`~harpx.imaging.phase_parameters.SPAMM_MAX_RADIUS` warns).
    threads : int or None, default None
        Threads for the FFTs and the per-frame work. None means ``os.cpu_count()`` for
        in-memory data and 1 for dask-backed data (dask already parallelises over chunks).
    dtype : {"float32", "float64"}, default "float32"
        Precision of the transforms and of ``phase`` and ``magnitude``. float32 halves the
        memory of the refined grid (8x the input voxels at ``upsample=2``) and runs about
        twice as fast; its phase differs from float64 by about 1e-6 rad, which leaves
        tracking errors unchanged (``benchmarks/bench_phase.py`` measures both).

    Returns
    -------
    xarray.Dataset
        ``phase/1``: ``phase`` (rad, in [-π, π)) and ``magnitude`` (image units), of ``dtype``, with
        dims (tag, time, z, y, x) on the refined grid; the tag coords and ``time``; ``mask``
        (nearest native voxel), ``body`` and ``displacement_true`` (linear interpolation, NaN where
        a neighbour is NaN) when present, ``displacement_true`` always dask-backed (one chunk
        per frame for in-memory data, refined when read: it is the synthetic truth, read to
        evaluate a tracking, and refined it holds three float64 components per voxel and
        frame, more than ``phase`` and ``magnitude`` together); ``harmonic_noise`` (tag), the
        noise standard deviation of each harmonic image (:mod:`harpx.imaging.noise`);
        ``tag_frequency_measured`` (tag), cycles/mm, the tag frequency the first frame's
        images show in each tag's plane (their spectral peak,
        :mod:`harpx.imaging.tag_frequency`; NaN where it cannot be measured; lazy for
        dask-backed data); ``tag_peak_measured`` (tag, axis), cycles/mm, that peak's
        frequency vector (:func:`~harpx.imaging.tag_frequency.measure_tag_peak`);
        ``slice_thickness`` (tag) and ``slice_position`` (tag, slice) when
        :func:`slice_geometry` finds them. Attributes: ``harpx_schema="phase/1"``,
        ``sequence``, ``upsample``, ``radius``, ``bandpass="disk"``
        (the filter the tracker's blur correction models) and ``upsample_factors`` (z, y, x).

    Raises
    ------
    SchemaError
        If ``ds`` is not a valid ``tagged/1`` dataset, or ``image`` is chunked along
        ``z``, ``y`` or ``x`` (the message says how to rechunk).
    ValueError
        If ``upsample``, ``radius``, ``threads`` or ``dtype`` is out of range.

    Warns
    -----
    HarpxWarning
        If a frame of a tag's image is one value within the tag's mask (blank or constant:
        no tag pattern, so no phase); names the frames and the value. Only images held in
        memory are checked. Also if a tag's measured frequency (``tag_frequency_measured``)
        differs from its stated ``tag_frequency`` by more than
        :data:`~harpx.imaging.tag_frequency.FREQUENCY_TOLERANCE`: the band-pass is centred
        off the images' tag peak (a wrong tag period); likewise if the peak lies more than
        :data:`~harpx.imaging.tag_frequency.DIRECTION_TOLERANCE` degrees off the stated
        ``tag_direction`` in the tag's plane. Dask-backed data are checked by the
        trackers instead, which compute them. Also for SPAMM images filtered with ``radius``
        above :data:`~harpx.imaging.phase_parameters.SPAMM_MAX_RADIUS`, whose pass band
        takes in the leakage of the zero-frequency peak (the trackers warn again).

    Notes
    -----
    The cubic-spline upsampling is applied in the Fourier domain through its exact transfer
    function with periodic boundaries, the same periodic extension the FFT band-pass
    assumes; it equals spatial upsampling (``scipy.ndimage.zoom(order=3, grid_mode=True,
    mode="grid-wrap")``) followed by the filter to rounding, at a fraction of the cost
    (:mod:`harpx.imaging._kernels`). Interpolation between slices acts on the complex
    harmonic image, never on the wrapped phase.

    Examples
    --------
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: 0 * X, shape=(2, 16, 16), spacing=(2.0, 1.5, 1.5), times=[0.0],
    ...     tags=("x",), snr=None, oversample=1)
    >>> ph = extract_phase(tagged, upsample=2)
    >>> ph.phase.sizes["x"], ph.attrs["harpx_schema"]
    (32, 'phase/1')
    """
    return _extract_phase(ds, upsample, radius, threads, dtype, check_tag_frequency=True)


def _extract_phase(
    ds: xr.Dataset,
    upsample: int,
    radius: float,
    threads: int | None,
    dtype: str,
    check_tag_frequency: bool,
) -> xr.Dataset:
    """:func:`extract_phase`; without ``check_tag_frequency``, ``tag_frequency_measured`` is
    left NaN and neither it nor the SPAMM radius is warned about (for images that are not
    tag patterns, such as the noise samples of
    :func:`harpx.tracking.uncertainty.tracking_uncertainty`)."""
    validate(ds, "tagged")
    _check_options(upsample, radius)
    _warn_constant_frames(ds)
    if check_tag_frequency:
        _warn_spamm_dc(ds, radius)
    if str(dtype) not in ("float32", "float64"):
        raise ValueError(f"'dtype' must be 'float32' or 'float64', got {dtype!r}")
    real = np.dtype(str(dtype))
    image = ds["image"]
    carried = [n for n in ("mask", "body", "displacement_true") if n in ds.variables]
    lazy = _check_chunks(ds, ["image", *carried])
    nthreads = default_threads(threads) if threads is not None or not lazy else 1
    factors = refinement_factors(ds, int(upsample))
    spacing = tuple(grid_step(ds, d) or 1.0 for d in GRID_DIMS)

    direction = ds["tag_direction"].transpose("tag", "axis").values.astype(np.float64)
    frequency = ds["tag_frequency"].values.astype(np.float64)
    # tag frequency vector f d in cycles/mm, reordered from (x, y, z) to the grid's (z, y, x)
    freq_zyx = (frequency[:, None] * direction)[:, [AXES.index(d) for d in GRID_DIMS]]
    slice_index = np.array(
        [GRID_DIMS.index(str(s)) for s in np.asarray(ds["slice_axis"].values).ravel()]
    )
    freq_var = xr.Variable(("tag", "component"), freq_zyx)
    slice_var = xr.Variable(("tag",), slice_index)

    sizes = {d: ds.sizes[d] * m for d, m in zip(GRID_DIMS, factors, strict=True)}
    phase, magnitude = xr.apply_ufunc(
        _phase_block,
        image.variable.transpose("tag", "time", *GRID_DIMS),
        freq_var,
        slice_var,
        input_core_dims=[list(GRID_DIMS), ["component"], []],
        output_core_dims=[list(GRID_DIMS), list(GRID_DIMS)],
        exclude_dims=set(GRID_DIMS),
        dask="parallelized",
        output_dtypes=[real, real],
        dask_gufunc_kwargs={"output_sizes": sizes},
        kwargs={
            "spacing": spacing,
            "factors": factors,
            "radius": float(radius),
            "threads": nthreads,
            "dtype": real,
        },
    )
    dims = ("tag", "time", *GRID_DIMS)
    factor_of = dict(zip(GRID_DIMS, factors, strict=True))
    coords: dict[Hashable, xr.Variable] = {
        name: ds[name].variable for name in ds.coords if not set(ds[name].dims) & set(GRID_DIMS)
    }
    for dim in GRID_DIMS:
        coords[dim] = _refined_coord(ds, dim, factor_of[dim])
    coords.update(slice_geometry(ds))  # for the blur correction's slice profile
    data_vars: dict[Hashable, xr.Variable] = {
        "phase": xr.Variable(dims, phase.transpose(*dims).data, standard_attrs("phase")),
        "magnitude": xr.Variable(
            dims, magnitude.transpose(*dims).data, standard_attrs("magnitude")
        ),
    }
    data_vars["harmonic_noise"] = harmonic_noise(
        image.isel(time=0), freq_var, slice_var, spacing=spacing, radius=float(radius)
    )
    if "mask" in ds.data_vars or "mask" in ds.coords:
        mask = _refine_nearest(ds["mask"].variable, factor_of)
        mask.attrs = {**standard_attrs("mask"), **ds["mask"].attrs}
        data_vars["mask"] = mask
    for name in ("body", "displacement_true"):
        if name in ds.variables:
            source = ds[name].variable
            if name == "displacement_true" and source.chunks is None:
                # the synthetic truth, read for evaluation only: refined frame by frame when
                # read, not held (three float64 components per refined voxel and frame)
                source = source.chunk({d: 1 for d in source.dims if d == "time"})
            var = _refine_linear(source.astype(np.float64), factors, nthreads)
            var.attrs = {**standard_attrs(name), **ds[name].attrs}
            data_vars[name] = var
    data_vars.update(_checked_tag_frequency(ds, lazy, check_tag_frequency))
    attrs = {k: v for k, v in ds.attrs.items() if k != "harpx_schema"}
    attrs.update(
        harpx_schema="phase/1",
        sequence=ds.attrs["sequence"],
        upsample=int(upsample),
        radius=float(radius),
        bandpass="disk",
        upsample_factors=[int(m) for m in factors],
    )
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)
