"""Conventional HARP tracking: the per-point fixed-point phase-matching baseline.

Every material point ``X`` keeps its reference harmonic phase vector
:math:`\\varphi_0(X) = \\varphi(X, t_0)` (paper eq. 1). In each frame, starting from the
point's position in the previous frame, the position is refined by Gauss–Newton steps on the
wrapped phase mismatch:

.. math::

    e = W(\\varphi(x, t) - \\varphi_0(X)), \\qquad
    x \\leftarrow x - B (G_B^T G_B)^{-1} G_B^T e, \\qquad G_B = \\nabla\\varphi(x, t)\\, B,

where ``B`` is an orthonormal basis of the span of the tag directions (3D with three tags;
the acquisition plane with two tags, so 2D tracking only moves points in-plane). Each
component of a step is clamped to one voxel. A point stops iterating when
:math:`\\|e\\| < 10^{-4}` rad or after ``iterations`` steps.

The method converges to the *nearest* position with the reference phase, so it inherits the
textbook failures of HARP on purpose, as the baseline the FE method must beat: a
frame-to-frame motion of more than half a tag period along a tag direction is tracked to the
wrong tag line (a "tag jump"), and points near tissue edges follow the blurred phase there.
"""

from __future__ import annotations

import math
import numbers
import time as _time
import warnings
from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from harpx._blas import matmul_one_thread
from harpx.errors import HarpxWarning, SchemaError, user_stacklevel
from harpx.imaging.phase_parameters import warn_spamm_dc
from harpx.imaging.sample import PhaseSampler, wrap
from harpx.imaging.tag_frequency import tag_frequency_flag, tags_unmeasured
from harpx.schema import AXES, GRID_DIMS, grid_step, newer_schema, standard_attrs, validate

__all__ = ["FADE_LEVEL", "FADE_QUANTILE", "track_harp"]

#: A point stops iterating once its residual norm is below this (rad).
TOLERANCE = 1e-4
#: A frame's tag has faded when the :data:`FADE_QUANTILE` of the harmonic magnitude over
#: the tracked points is below this many noise standard deviations of the harmonic image
#: (``harmonic_noise``); :func:`track_harp`, Notes.
FADE_LEVEL = 5.0
#: Quantile of the harmonic magnitude over the tracked points compared with
#: :data:`FADE_LEVEL` (the lower quartile: a quarter of the tissue)
FADE_QUANTILE = 0.25
#: Most points whose harmonic magnitude is sampled per frame for :data:`FADE_QUANTILE`
FADE_SAMPLE = 20_000


def track_harp(
    ds: xr.Dataset, *, points: ArrayLike | xr.Dataset | None = None, iterations: int = 10
) -> xr.Dataset:
    """Track material points through the frames by conventional HARP.

    Parameters
    ----------
    ds : xarray.Dataset
        A ``phase/1`` dataset, or a ``tagged/1`` dataset whose phase is then computed with
        :func:`harpx.imaging.harp.extract_phase` (default settings).
    points : array_like of shape (n, 3) or xarray.Dataset, optional
        Reference positions X in mm, columns (x, y, z); or a dataset with ``z``, ``y``, ``x``
        coordinates (e.g. the acquired ``tagged/1`` images) whose voxel centres inside the
        data are tracked. Default: the centres of the phase-grid voxels inside the data at
        frame 0 (inside every tag's ``mask`` and ``body >= 0.5`` where those exist, and
        above the sampler's magnitude floor). With a grid (default or dataset) the result
        also holds ``displacement_grid`` on that grid.
    iterations : int, default 10
        Maximum Gauss–Newton steps per point and frame (paper §4.1 uses ten).

    Returns
    -------
    xarray.Dataset
        A ``tracked/1`` dataset with ``method="harp"``: ``points`` (node, axis),
        ``cells`` (empty, ``element="points"``), ``displacement`` (time, node, axis) in mm
        (NaN only outside the acquired field of view: off the grid or outside a tag's
        ``mask``; a point whose harmonic magnitude falls below the sampler's floor, i.e. that
        has left the tissue signal, keeps its last position), attributes ``points_lost``
        (points valid at frame 0 that are NaN in some later frame) and ``points_unseen``
        (given points without valid phase at frame 0, NaN in every frame) and
        ``tags_off_frequency`` (:func:`~harpx.imaging.tag_frequency.tag_frequency_flag`) and
        ``tags_frequency_unmeasured`` (the tags whose stated frequency and direction nothing
        could check, :func:`~harpx.imaging.tag_frequency.tags_unmeasured`, or ``"none"``),
        per-frame ``epsilon`` (mean absolute wrapped residual over the points with a valid
        phase, rad), ``iterations`` (sweeps run), ``wall_time`` (s), ``valid_points`` (the
        points with a valid phase at the end of the frame; 0: the frame was not tracked),
        ``harmonic_snr`` (time, tag; the lower quartile of the harmonic magnitude at the
        tracked points over ``harmonic_noise``, dimensionless, NaN without a noise estimate)
        and ``faded`` (some tag's ``harmonic_snr`` below :data:`FADE_LEVEL`; Notes), and
        ``displacement_grid`` (time, axis, z, y, x) when ``points`` is None (NaN outside the
        tracked voxels).

    Raises
    ------
    SchemaError
        If ``ds`` is neither a valid ``phase/1`` nor a ``tagged/1`` dataset, or a
        ``points`` dataset has no ``z``, ``y``, ``x`` coordinates.
    ValueError
        If ``points`` is not a non-empty (n, 3) array of finite numbers (names the rows
        with NaN or inf), or ``iterations`` is not a whole number ≥ 1, or no point has a
        valid phase in frame 0 (names an all-False ``mask``; nothing would be tracked).

    Warns
    -----
    HarpxWarning
        If any point is lost (``points_lost > 0``) or unseen (``points_unseen > 0``), or
        if the phase's ``tag_frequency_measured`` misses a tag's ``tag_frequency``
        (:func:`~harpx.imaging.tag_frequency.tag_frequency_flag`; recorded as
        ``attrs["tags_off_frequency"]``). If a frame has no point with a valid phase (a blank
        frame: every point keeps its previous position; ``valid_points`` 0), or a tag has
        faded to the noise in a frame (``faded``).

    Notes
    -----
    Frames are tracked in order, each started from the previous frame's positions
    (frame-to-frame tracking, JHU ``TrackPointHarp``), but the target phase is always the
    reference phase :math:`\\varphi_0(X)`, so errors do not accumulate through the phase.
    A point that becomes invalid during a frame (no tissue signal, or outside the
    acquisition) keeps its last position for the next frame.

    Faded tags. The harmonic image is :math:`H = A e^{i\\varphi} + n` with complex Gaussian
    noise :math:`n` of standard deviation :math:`\\sigma_H` (``harmonic_noise``, both parts
    together), so :math:`|H|` is Rician: for :math:`A = 0` (no tags left) Rayleigh, with
    :math:`|H|^2/\\sigma_H^2` exponential, lower quartile :math:`0.54\\,\\sigma_H` and
    :math:`P(|H| > 5\\sigma_H) = e^{-25}`; for :math:`A \\gg \\sigma_H` about normal, lower
    quartile :math:`A - 0.48\\,\\sigma_H`, with phase standard deviation
    :math:`\\sigma_H/(\\sqrt 2 A)`. A lower quartile below :data:`FADE_LEVEL` = 5
    :math:`\\sigma_H` thus means that a quarter of the tissue has :math:`A \\lesssim
    5.5\\,\\sigma_H`, where the phase noise exceeds 0.13 rad (2 % of a tag period) and grows
    as :math:`1/A` as the tags fade further; pure noise never escapes the test. The lower
    quartile rather than the median because whatever else the band-pass keeps (the
    untagged signal of SPAMM images at tissue edges, which grows as the tags fade) holds up
    the magnitude of part of the tissue after its tags are gone. Without a noise estimate
    (``harmonic_noise`` NaN, e.g. tags oblique to every grid axis) ``harmonic_snr`` is NaN
    and nothing is flagged; with noise-free images (0) it is infinite.

    Examples
    --------
    >>> from harpx.imaging.sample import wrap
    >>> x = np.arange(24.0)
    >>> shift = np.array([0.0, 1.5])  # mm along x at frames 0 and 1
    >>> phase = wrap(2 * np.pi / 8 * (x[None, :] - shift[:, None]))  # (time, x)
    >>> ds = xr.Dataset(
    ...     {"phase": (("tag", "time", "z", "y", "x"),
    ...                np.broadcast_to(phase[None, :, None, None, :], (1, 2, 1, 4, 24))),
    ...      "magnitude": (("tag", "time", "z", "y", "x"), np.ones((1, 2, 1, 4, 24)))},
    ...     coords={"tag": ["x"], "axis": ["x", "y", "z"], "time": [0.0, 18.0],
    ...             "x": x, "y": np.arange(4.0), "z": [0.0],
    ...             "tag_direction": (("tag", "axis"), [[1.0, 0.0, 0.0]]),
    ...             "tag_frequency": ("tag", [1 / 8]), "slice_axis": ("tag", ["z"])},
    ...     attrs={"harpx_schema": "phase/1", "sequence": "CSPAMM", "upsample": 1,
    ...            "radius": 0.5})
    >>> ds = harpx.schema.fill_standard_attrs(ds)
    >>> out = track_harp(ds, points=[[10.0, 1.0, 0.0]])
    >>> np.round(out.displacement.sel(axis="x").values[:, 0], 4).tolist()
    [0.0, 1.5]
    """
    iterations = _iterations(iterations)
    ds = _as_phase(ds)
    off_frequency = tag_frequency_flag(ds, "conventional HARP")
    warn_spamm_dc(ds, "conventional HARP")
    grid = ds if points is None else points if isinstance(points, xr.Dataset) else None
    grid_points = grid is not None
    flat_index: NDArray[np.int64] | None = None
    if grid is not None:
        X, flat_index = _grid_candidates(grid)
    else:
        X = _explicit_points(points)
    # every sampler prepares only the box the points can reach (see _reach)
    reference = PhaseSampler(ds, 0, region=_bounds(X, np.isfinite(X).all(axis=1), 0.0))
    phi0, valid0 = reference.phase(X)
    if not valid0.any():
        raise ValueError(_no_data_message(ds, X.shape[0], grid is not None))
    if grid is not None:
        assert flat_index is not None
        X, flat_index, phi0, valid0 = X[valid0], flat_index[valid0], phi0[valid0], valid0[valid0]
    basis = _tag_basis(reference.wavevectors)
    step_limit = _voxel_size(ds)
    # a point moves at most `iterations` clamped steps in a frame
    reach = float(int(iterations) * np.max(np.where(np.isfinite(step_limit), step_limit, 0.0)))

    ntime = ds.sizes["time"]
    n = X.shape[0]
    displacement = np.full((ntime, n, 3), np.nan)
    displacement[0, valid0] = 0.0
    epsilon = np.zeros(ntime)
    sweeps = np.zeros(ntime, dtype=np.int64)
    wall = np.zeros(ntime)
    position = X.copy()
    sampler = reference
    noise = _harmonic_noise(ds)
    counted = np.zeros(ntime, dtype=np.int64)
    counted[0] = int(valid0.sum())
    snr = np.full((ntime, noise.size), np.nan)
    snr[0] = _harmonic_snr(reference, position, valid0, noise)
    for t in range(1, ntime):
        start = _time.perf_counter()
        region = _bounds(position, valid0, reach)
        sampler = PhaseSampler(ds, t, region=region, reuse=sampler)
        sweeps[t], phi, valid = _track_frame(
            sampler, position, phi0, valid0, basis, step_limit, int(iterations)
        )
        valid &= valid0
        counted[t] = int(valid.sum())
        snr[t] = _harmonic_snr(sampler, position, valid0, noise)
        residual = np.abs(wrap(phi[valid] - phi0[valid]))
        epsilon[t] = float(residual.mean()) if residual.size else np.nan
        # NaN only outside the acquisition; a point without tissue signal keeps its position
        acquired = valid0 & sampler.acquired(position).all(axis=1)
        displacement[t, acquired] = position[acquired] - X[acquired]
        wall[t] = _time.perf_counter() - start

    frames = {"displacement": displacement, "epsilon": epsilon, "iterations": sweeps,
              "wall_time": wall}  # fmt: skip
    out = _assemble(ds, X, frames, int(iterations))
    _flag_frames(out, ds, counted, snr)
    lost = int(np.count_nonzero(valid0 & np.isnan(displacement[1:, :, 0]).any(axis=0)))
    out.attrs["points_lost"] = lost
    out.attrs["tags_off_frequency"] = off_frequency
    out.attrs["tags_frequency_unmeasured"] = " ".join(tags_unmeasured(ds)) or "none"
    unseen = int(np.count_nonzero(~valid0))  # only given points: grid points are selected
    out.attrs["points_unseen"] = unseen
    if unseen:
        first = np.flatnonzero(~valid0)[:5].tolist()
        warnings.warn(
            f"{unseen} of {n} points have no valid phase in frame 0 (e.g. rows {first}): they "
            "lie outside the field of view, a tag's mask or the tissue signal, so they were "
            "not tracked and their displacement is NaN in every frame "
            "(out.attrs['points_unseen']); pass points inside the imaged tissue",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    if lost:
        warnings.warn(
            f"conventional HARP lost {lost} of {int(valid0.sum())} points "
            f"({100.0 * lost / max(int(valid0.sum()), 1):.1f} %): they left the acquired field "
            "of view (the grid or a tag's mask) in some frame, and their displacement is NaN "
            "there (out.attrs['points_lost']); acquire a larger field of view or track "
            "points farther from its edges",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    if grid_points:
        assert grid is not None and flat_index is not None
        out["displacement_grid"] = _on_grid(grid, displacement, flat_index)
    return out


def _iterations(value: Any) -> int:
    """``iterations`` as an int ≥ 1 (a whole number; numpy integers accepted)."""
    whole = isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
    if not (whole and math.isfinite(value) and value == int(value) and value >= 1):
        raise ValueError(
            f"iterations={value!r} must be a whole number of Gauss–Newton steps ≥ 1 "
            "(e.g. iterations=10)"
        )
    return int(value)


def _explicit_points(points: Any) -> NDArray[np.float64]:
    """Given points as a finite (n, 3) float array, n ≥ 1, else a ValueError naming why."""
    try:
        X = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"points must be numbers, an (n, 3) array of (x, y, z) in mm ({exc})"
        ) from exc
    if X.ndim != 2 or X.shape[1] != 3:
        raise ValueError(
            f"points must have shape (n, 3) with columns (x, y, z) in mm; got {X.shape}"
        )
    if X.shape[0] == 0:
        raise ValueError("points is empty: pass at least one (x, y, z) position in mm")
    bad = np.flatnonzero(~np.isfinite(X).all(axis=1))
    if bad.size:
        raise ValueError(
            f"points has {bad.size} rows with NaN or inf (rows {bad[:10].tolist()}"
            f"{' …' if bad.size > 10 else ''}); drop them, e.g. points[np.isfinite(points)"
            ".all(axis=1)]"
        )
    return X


def _as_phase(ds: xr.Dataset) -> xr.Dataset:
    schema = ds.attrs.get("harpx_schema")
    if schema == "tagged/1":
        from harpx.imaging.harp import extract_phase

        ds = extract_phase(ds)
    elif schema != "phase/1":
        newer = newer_schema(schema)
        raise SchemaError(
            f"track_harp needs a 'phase/1' or 'tagged/1' dataset; attrs['harpx_schema'] is "
            f"{schema!r}" + (f": {newer}" if newer else "")
        )
    validate(ds, kind="phase")
    return ds


def _grid_candidates(ds: xr.Dataset) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Voxel centres inside every mask and the body, and their flat (z, y, x) indices.

    The caller keeps those valid in the reference frame (above the magnitude floor).
    """
    missing = [d for d in GRID_DIMS if d not in ds.coords]
    if missing:
        raise SchemaError(
            f"points dataset has no coordinate(s) {missing!r}; pass a dataset on an image "
            "grid (coords z, y, x in mm, e.g. the tagged/1 images) or an (n, 3) array"
        )
    z, y, x = (np.asarray(ds[d].values, np.float64) for d in GRID_DIMS)
    inside = np.ones((z.size, y.size, x.size), bool)
    if "mask" in ds.variables:
        inside &= np.asarray(ds["mask"].transpose("tag", *GRID_DIMS).values, bool).all(axis=0)
    if "body" in ds.variables:
        inside &= np.asarray(ds["body"].transpose(*GRID_DIMS).values) >= 0.5
    flat = np.flatnonzero(inside)
    iz, iy, ix = np.unravel_index(flat, inside.shape)
    return np.stack([x[ix], y[iy], z[iz]], axis=-1), flat


def _bounds(
    points: NDArray[np.float64], keep: ArrayLike, reach: float
) -> NDArray[np.float64] | None:
    """Box (2, 3) in mm around the kept points, widened by ``reach`` (None: no point kept)."""
    mask = np.asarray(keep, dtype=bool)
    if not mask.any():
        return None
    kept = points[mask]
    return np.stack([kept.min(axis=0) - reach, kept.max(axis=0) + reach])


def _tag_basis(wavevectors: NDArray[np.float64]) -> NDArray[np.float64]:
    """Orthonormal basis (3, r) of the span of the tag directions."""
    _, s, vt = np.linalg.svd(wavevectors, full_matrices=False)
    rank = int(np.sum(s > 1e-9 * s.max()))
    return vt[:rank].T


def _voxel_size(ds: xr.Dataset) -> NDArray[np.float64]:
    """Grid spacing along (x, y, z) in mm (inf along an axis with a single sample)."""
    return np.array([grid_step(ds, name) or np.inf for name in AXES])


def _track_frame(
    sampler: PhaseSampler,
    position: NDArray[np.float64],
    phi0: NDArray[np.float64],
    valid0: NDArray[np.bool_],
    basis: NDArray[np.float64],
    step_limit: NDArray[np.float64],
    iterations: int,
) -> tuple[int, NDArray[np.float64], NDArray[np.bool_]]:
    """Gauss–Newton phase matching of every point in one frame (updates ``position``).

    Returns the sweeps run and the phase and validity at the final positions. A point that
    stops (converged, invalid or ill-conditioned) stops where it was last sampled, so only
    the points still moving after the last sweep are sampled again.
    """
    active = valid0.copy()
    rank = basis.shape[1]
    ntag = phi0.shape[1]
    sweeps = 0
    phi_end = np.zeros_like(phi0)
    valid_end = np.zeros(valid0.shape, dtype=bool)
    for sweep in range(iterations):
        index = np.flatnonzero(active)
        if index.size == 0:
            break
        sweeps = sweep + 1
        phi, grad, valid = sampler.sample(position[index])
        phi_end[index], valid_end[index] = phi, valid
        error = wrap(phi - phi0[index])  # (m, ntag), rad
        done = valid & (np.linalg.norm(error, axis=1) < TOLERANCE)
        # only the valid points that have not converged step: the algebra runs on those
        moving = np.flatnonzero(valid & ~done)
        healthy = np.ones(index.size, dtype=bool)
        if moving.size:
            # gradient within the tag span (k, ntag, r), normal equations (k, r, r) and
            # right-hand side (k, r), summed tag by tag (small-matrix products are slower)
            g = grad[moving]
            gb = g @ basis
            normal = gb[:, 0, :, None] * gb[:, 0, None, :]
            for t in range(1, ntag):
                normal += gb[:, t, :, None] * gb[:, t, None, :]
            rhs = np.einsum("mti,mt->mi", gb, error[moving])
            # ill-conditioned normal equations (|H| ~ 0, collinear gradients): no update
            scale = np.trace(normal, axis1=1, axis2=2) / rank
            det, solve = _symmetric_solver(normal)
            well = det > 1e-10 * np.maximum(scale, 1e-300) ** rank
            healthy[moving] = well
            if well.any():
                step = -matmul_one_thread(solve(well, rhs[well]), basis.T)
                target = index[moving[well]]
                position[target] += np.clip(step, -step_limit, step_limit)
        active[index[done | ~valid | ~healthy]] = False
    moved = np.flatnonzero(active)  # stepped after their last sample
    if moved.size:
        phi_end[moved], valid_end[moved] = sampler.phase(position[moved])
    return sweeps, phi_end, valid_end


def _symmetric_solver(
    normal: NDArray[np.float64],
) -> tuple[NDArray[np.float64], Callable[[NDArray[np.bool_], NDArray[np.float64]], Any]]:
    """Determinants of symmetric (k, r, r) matrices and a solver for a subset of them.

    For r = 3 (three tags) by the adjugate, in a few vectorised operations; otherwise by
    LAPACK. Both agree to rounding (the solver is only used on well-conditioned matrices).
    Returns ``det`` (k,) and ``solve(select, rhs)`` giving ``normal[select]⁻¹ rhs``.
    """
    if normal.shape[1] != 3:

        def lapack(select: NDArray[np.bool_], rhs: NDArray[np.float64]) -> Any:
            return np.linalg.solve(normal[select], rhs[..., None])[..., 0]

        return np.linalg.det(normal), lapack
    a, b, c = normal[:, 0, 0], normal[:, 0, 1], normal[:, 0, 2]
    d, e, f = normal[:, 1, 1], normal[:, 1, 2], normal[:, 2, 2]
    adjugate = np.empty_like(normal)  # symmetric: the cofactors
    adjugate[:, 0, 0] = d * f - e * e
    adjugate[:, 0, 1] = adjugate[:, 1, 0] = c * e - b * f
    adjugate[:, 0, 2] = adjugate[:, 2, 0] = b * e - c * d
    adjugate[:, 1, 1] = a * f - c * c
    adjugate[:, 1, 2] = adjugate[:, 2, 1] = b * c - a * e
    adjugate[:, 2, 2] = a * d - b * b
    det = a * adjugate[:, 0, 0] + b * adjugate[:, 0, 1] + c * adjugate[:, 0, 2]

    def cofactors(select: NDArray[np.bool_], rhs: NDArray[np.float64]) -> Any:
        return np.einsum("kij,kj->ki", adjugate[select], rhs) / det[select, None]

    return det, cofactors


def _assemble(
    ds: xr.Dataset, X: NDArray[np.float64], frames: dict[str, NDArray[Any]], iterations: int
) -> xr.Dataset:
    """``tracked/1`` of points ``X`` with per-frame variables ``frames`` (standard names).

    ``frames["displacement"]`` is ``(time, node, axis)``; every other entry is ``(time,)``.
    """
    cells = xr.Variable(("cell", "vertex"), np.zeros((0, 0), np.int64), standard_attrs("cells"))
    cells.attrs["element"] = "points"
    attrs: dict[str, Any] = {
        "harpx_schema": "tracked/1",
        "method": "harp",
        "max_iterations": iterations,
        "tolerance": TOLERANCE,
    }
    for key in ("sequence", "upsample", "radius"):
        if key in ds.attrs:
            attrs[key if key == "sequence" else f"phase_{key}"] = ds.attrs[key]
    return xr.Dataset(
        {
            "points": (("node", "axis"), X, standard_attrs("points")),
            "cells": cells,
            **{
                name: (
                    ("time", "node", "axis") if values.ndim == 3 else "time",
                    values,
                    standard_attrs(name),
                )
                for name, values in frames.items()
            },
        },
        coords={
            "axis": ("axis", list(AXES), standard_attrs("axis")),
            "time": ("time", np.asarray(ds["time"].values), dict(ds["time"].attrs)),
        },
        attrs=attrs,
    )


def _on_grid(
    ds: xr.Dataset, displacement: NDArray[np.float64], flat_index: NDArray[np.int64]
) -> xr.DataArray:
    shape = tuple(ds.sizes[d] for d in GRID_DIMS)
    ntime = displacement.shape[0]
    grid = np.full((ntime, 3, int(np.prod(shape))), np.nan)
    grid[:, :, flat_index] = displacement.transpose(0, 2, 1)
    coords = {d: (d, np.asarray(ds[d].values), dict(ds[d].attrs)) for d in GRID_DIMS}
    return xr.DataArray(
        grid.reshape(ntime, 3, *shape),
        dims=("time", "axis", *GRID_DIMS),
        coords=coords,
        attrs=standard_attrs("displacement_grid"),
    )


def _no_data_message(ds: xr.Dataset, count: int, grid: bool) -> str:
    """Why no point has a valid phase in the reference frame, and what to do."""
    what = "no voxel of the grid" if grid else f"none of the {count} given points"
    reasons = []
    if "mask" in ds.variables:
        mask = np.asarray(ds["mask"].transpose("tag", *GRID_DIMS).values, dtype=bool)
        labels = [str(v) for v in np.asarray(ds["tag"].values).ravel()]
        empty = [tag for tag, m in zip(labels, mask, strict=True) if not m.any()]
        if empty:
            reasons.append(f"the mask of tag(s) {empty!r} is all False (no data at all)")
        elif not mask.all(axis=0).any():
            reasons.append("the tags' masks do not overlap (no voxel has data from every tag)")
    if "body" in ds.variables and not (np.asarray(ds["body"].values) >= 0.5).any():
        reasons.append("'body' is below 0.5 everywhere (no tissue)")
    why = "; ".join(reasons) or (
        "they lie outside the field of view, a tag's mask or the tissue, or below the "
        "harmonic magnitude floor in frame 0 (no tag pattern where tag_direction and "
        "tag_frequency say)"
    )
    return (
        f"conventional HARP has nothing to track: {what} has a valid harmonic phase in frame "
        f"0 ({why}). Check the dataset's 'mask', 'body', tag_direction and tag_frequency, "
        "or pass points inside the imaged tissue"
    )


def _harmonic_noise(ds: xr.Dataset) -> NDArray[np.float64]:
    """Each tag's ``harmonic_noise`` (computed, if lazy); NaN where there is none."""
    if "harmonic_noise" not in ds.variables:
        return np.full(ds.sizes["tag"], np.nan)
    return np.asarray(ds["harmonic_noise"].values, dtype=np.float64).ravel()


def _harmonic_snr(
    sampler: PhaseSampler,
    position: NDArray[np.float64],
    keep: NDArray[np.bool_],
    noise: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Per tag, the :data:`FADE_QUANTILE` of the harmonic magnitude at the kept points with
    data (inside the field of view and every mask) over the tag's noise; NaN without points
    or noise. At most :data:`FADE_SAMPLE` evenly strided points are sampled: the quartile of
    that many is known to well under 1 % of its value."""
    inside = np.flatnonzero(keep)
    inside = inside[:: max(1, inside.size // FADE_SAMPLE)]
    if inside.size:
        inside = inside[sampler.acquired(position[inside]).all(axis=1)]
    if inside.size == 0:
        return np.full(noise.size, np.nan)
    magnitude, _ = sampler.magnitude(position[inside])
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.quantile(magnitude, FADE_QUANTILE, axis=0) / noise
    return np.asarray(np.where(np.isfinite(noise), ratio, np.nan), dtype=np.float64)


def _flag_frames(
    out: xr.Dataset, ds: xr.Dataset, counted: NDArray[np.int64], snr: NDArray[np.float64]
) -> None:
    """Record ``valid_points``, ``harmonic_snr`` and ``faded`` in ``out``; warn about frames
    without a valid point and frames whose tags have faded to the noise."""
    labels = [str(v) for v in np.asarray(ds["tag"].values).ravel()]
    empty = np.flatnonzero(counted == 0)
    faded_tags = np.asarray(snr < FADE_LEVEL)  # NaN (no noise estimate) compares False
    faded = np.asarray(faded_tags.any(axis=1))
    faded[empty] = False  # said below: no point had a phase there at all
    out["valid_points"] = xr.Variable("time", counted, standard_attrs("valid_points"))
    out["harmonic_snr"] = xr.Variable(("time", "tag"), snr, standard_attrs("harmonic_snr"))
    out["faded"] = xr.Variable("time", faded, standard_attrs("faded"))
    out.coords["tag"] = ("tag", np.array(labels, dtype=object), standard_attrs("tag"))
    if empty.size:
        warnings.warn(
            f"conventional HARP: frame(s) {empty[:10].tolist()} have no point with a valid "
            "harmonic phase (a blank or missing frame, or no tag pattern there): every point "
            "kept its previous position, so their displacement is the previous frame's, not "
            "a measurement (out['valid_points'] is 0 there); fix or drop those frames",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    if faded.any():
        frames = np.flatnonzero(faded)
        which = [
            f"frame {n} ("
            + ", ".join(f"{labels[k]!r} {snr[n, k]:.2g}" for k in np.flatnonzero(faded_tags[n]))
            + ")"
            for n in frames[:5]
        ]
        warnings.warn(
            f"conventional HARP: the tags have faded to the noise in {frames.size} frame(s): "
            f"{'; '.join(which)}{' …' if frames.size > 5 else ''} (a quarter of the tracked "
            f"points have a harmonic magnitude below {FADE_LEVEL:g} × harmonic_noise). The phase "
            "there is mostly noise, so the tracked positions are not measured motion "
            "(out['faded'], out['harmonic_snr']); track fewer frames (ds.isel(time=...)) or "
            "use CSPAMM or a longer T1",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
