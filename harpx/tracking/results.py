"""Build ``tracked/1`` datasets and compare them with ground truth."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from typing import Any, cast

import numpy as np
import xarray as xr

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.schema import fill_standard_attrs, standard_attrs
from harpx.tracking.resample import interpolate_displacement

__all__ = [
    "acquired_grid",
    "displacement_on_grid",
    "grid_points",
    "tracked_dataset",
    "tracking_error",
]


def grid_points(ds: xr.Dataset) -> FloatArray:
    """Voxel-centre positions of a grid, one row per voxel.

    Parameters
    ----------
    ds : xarray.Dataset
        Dataset with coordinates ``z``, ``y``, ``x`` (mm).

    Returns
    -------
    ndarray, shape (nz * ny * nx, 3)
        Positions in mm, columns (x, y, z), rows in C order over (z, y, x).
    """
    z, y, x = (np.asarray(ds[d], dtype=float) for d in ("z", "y", "x"))
    Z, Y, X = np.meshgrid(z, y, x, indexing="ij")
    return np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)


def acquired_grid(phase: xr.Dataset) -> xr.Dataset:
    """The acquired (native) voxel grid behind a possibly upsampled ``phase/1`` dataset.

    Upsampling subdivides every voxel into ``m`` along each axis (``upsample_factors``), so
    the acquired centre is the mean of its ``m`` sub-voxel centres.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset.

    Returns
    -------
    xarray.Dataset
        Empty dataset with the acquired ``z``, ``y``, ``x`` coordinates (mm) and ``time``.
    """
    factors = phase.attrs.get("upsample_factors", [1, 1, 1])
    coords: dict[str, Any] = {"time": phase["time"]}
    for dim, m in zip(("z", "y", "x"), np.atleast_1d(factors), strict=True):
        values = np.asarray(phase[dim], dtype=float)
        m = int(m)
        if m > 1 and values.size % m == 0:
            values = values.reshape(-1, m).mean(axis=1)
        coords[dim] = xr.DataArray(values, dims=dim, attrs=dict(phase[dim].attrs))
    return xr.Dataset(coords=coords)


def displacement_on_grid(body: Any, U: FloatArray, grid: xr.Dataset) -> xr.DataArray:
    """FE displacement of the material points at the voxel centres of ``grid``.

    Parameters
    ----------
    body : Body
        The tracked body.
    U : ndarray, shape (ntime, ndof)
        Displacements per frame, mm.
    grid : xarray.Dataset
        Dataset with coordinates ``z``, ``y``, ``x`` (mm) and ``time``.

    Returns
    -------
    xarray.DataArray
        (time, axis, z, y, x) displacement in mm, NaN where the voxel centre lies in no cell.
    """
    pts = grid_points(grid)
    lo = body.dof_points.min(axis=0) - 1e-9
    hi = body.dof_points.max(axis=0) + 1e-9
    in_box = np.all((pts >= lo) & (pts <= hi), axis=1)
    shape = tuple(grid.sizes[d] for d in ("z", "y", "x"))
    out = np.full((U.shape[0], pts.shape[0], 3), np.nan)
    if in_box.any():
        out[:, in_box], _ = interpolate_displacement(body, U, pts[in_box])
    data = out.reshape(U.shape[0], *shape, 3).transpose(0, 4, 1, 2, 3)
    return xr.DataArray(
        data,
        dims=("time", "axis", "z", "y", "x"),
        coords={d: grid[d] for d in ("time", "z", "y", "x")} | {"axis": ["x", "y", "z"]},
        attrs=standard_attrs("displacement_grid"),
    )


def tracked_dataset(
    body: Any,
    U: FloatArray,
    phase: xr.Dataset,
    diagnostics: Mapping[str, np.ndarray],
    settings: Mapping[str, Any],
) -> xr.Dataset:
    """Assemble a self-contained ``tracked/1`` dataset.

    Parameters
    ----------
    body : Body
        The tracked body, as for :func:`displacement_on_grid`.
    U : ndarray, shape (ntime, ndof)
        Displacements per frame, mm, as for :func:`displacement_on_grid`.
    phase : xarray.Dataset
        The ``phase/1`` dataset that was tracked (for time and grid coordinates).
    diagnostics : mapping of str to ndarray or (dims, ndarray)
        Per-frame arrays (time,) or (time, cell), or ``(dims, values)`` pairs.
    settings : mapping
        Settings recorded in ``attrs``; a ``phase/1`` dataset's ``sequence``,
        ``upsample`` and ``radius`` are recorded too (as ``sequence``, ``phase_upsample``
        and ``phase_radius``, as conventional HARP records them).

    Returns
    -------
    xarray.Dataset
        ``displacement_grid`` is on the acquired voxel grid (:func:`acquired_grid`), the
        grid of ``displacement_true`` in synthetic ``tagged/1`` data.
    """
    ntime = U.shape[0]
    nodal = np.stack([body.nodal_displacement(u) for u in U])  # (time, node, 3)
    strain = np.stack([body.green_strain(u) for u in U])  # (time, cell, 3, 3)
    ds = xr.Dataset(
        coords={
            "time": phase["time"],
            "axis": xr.DataArray(["x", "y", "z"], dims="axis", attrs=standard_attrs("axis")),
        }
    )
    ds["points"] = xr.DataArray(
        body.dof_points, dims=("node", "axis"), attrs=standard_attrs("points")
    )
    cells_attrs = standard_attrs("cells") | {"element": body.element}
    ds["cells"] = xr.DataArray(
        np.asarray(body.cells, dtype=np.int64), dims=("cell", "vertex"), attrs=cells_attrs
    )
    if body.regions:
        names = list(body.regions)
        label = np.full(body.ncell, -1, dtype=np.int64)
        for code, name in enumerate(names):  # loop over the few named regions
            label[np.asarray(body.regions[name], dtype=np.int64)] = code
        flags = {"flag_values": np.arange(len(names), dtype=np.int64)}  # CF flags: -1 = none
        ds["region"] = xr.DataArray(
            label,
            dims="cell",
            attrs=standard_attrs("region") | flags | {"flag_meanings": " ".join(names)},
        )
    ds["displacement"] = xr.DataArray(
        nodal, dims=("time", "node", "axis"), attrs=standard_attrs("displacement")
    )
    ds["green_strain"] = xr.DataArray(
        strain, dims=("time", "cell", "i", "j"), attrs=standard_attrs("green_strain")
    )
    if getattr(body, "fibers_qp", None) is not None:
        fib = body.cell_average(body.fibers_qp)
        fib /= np.linalg.norm(fib, axis=1, keepdims=True)
        ds["fiber"] = xr.DataArray(fib, dims=("cell", "axis"), attrs=standard_attrs("fiber"))
        ds["fiber_stretch"] = xr.DataArray(
            np.stack([body.fiber_stretch(u) for u in U]),
            dims=("time", "cell"),
            attrs=standard_attrs("fiber_stretch"),
        )
    for name, value in diagnostics.items():
        if isinstance(value, tuple):  # (dims, values) for anything not per frame
            dims, value = value
        else:
            dims = ("time",) if np.ndim(value) == 1 else ("time", "cell")
        ds[name] = xr.DataArray(np.asarray(value), dims=dims, attrs=standard_attrs(name))
    ds["displacement_grid"] = displacement_on_grid(body, U, acquired_grid(phase))
    ds["dof_displacement"] = xr.DataArray(
        U, dims=("time", "dof"), attrs={"units": "mm", "long_name": "displacement of each dof"}
    )
    ds.attrs.update({"harpx_schema": "tracked/1", **{k: v for k, v in settings.items()}})
    if phase.attrs.get("harpx_schema") == "phase/1":  # how the tracked phase was extracted
        for key in ("sequence", "upsample", "radius"):
            if key in phase.attrs:
                ds.attrs[key if key == "sequence" else f"phase_{key}"] = phase.attrs[key]
    assert ds.sizes["time"] == ntime
    return fill_standard_attrs(ds)


def tracking_error(
    tracked: xr.Dataset, truth: xr.Dataset, *, where: xr.DataArray | None = None
) -> xr.Dataset:
    """Displacement error of a tracked result against ground truth, inside the body.

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` dataset with ``displacement_grid``.
    truth : xarray.Dataset
        Dataset with ``displacement_true`` (time, axis, z, y, x), NaN outside the body
        (a ``tagged/1`` or ``phase/1`` dataset).
    where : xarray.DataArray of bool, optional
        Voxels to include, broadcastable to (time, z, y, x) on the grid of ``truth`` (e.g.
        an edge band, or where the true displacement exceeds half a tag period).

    Returns
    -------
    xarray.Dataset
        Per frame (``time``) and overall (``*_all``, over every frame after the reference
        frame, which is exact by construction) mean, standard deviation, 95th percentile
        and maximum of the error magnitude ``|u − u_true|`` in mm, plus
        ``coverage``: the fraction of body voxels that the tracked result covers.
        Frames are matched by their time (to 1e-6 relative); frames only one side has
        are left out of every statistic, and so are frames whose tracked displacement
        is NaN at every body voxel (a failed frame; its per-frame values are NaN).
        Attributes ``frames_without_estimate`` (ms: the truth's frames after the
        reference with no tracked frame or a failed one) and ``frames_without_truth``
        (ms: tracked frames the truth lacks) list them. The tracked displacement is
        relative to its first frame, so the truth must hold that frame with zero
        displacement there (its reference configuration; below 1e-6 mm plus 1e-4 of the
        largest true displacement).

    Raises
    ------
    ValueError
        If either variable is missing; no frame time is common to both datasets; the truth
        lacks the tracked first (reference) frame or is not zero there (referenced to
        another frame, e.g. a result tracked from a later frame); the reference frame is
        the only common one; or no body voxel after it (within ``where``) has a tracked
        displacement.

    Warns
    -----
    HarpxWarning
        When frames are left out (``frames_without_estimate``, ``frames_without_truth``):
        the ``*_all`` statistics then cover the other frames only, and do not compare with
        those of a result that has every frame.

    Examples
    --------
    The truth of a synthetic acquisition of a cylinder moving 0.5 mm along x, and a tracked
    result made by hand (the ``displacement_grid`` that :func:`harpx.tracking.track.track`
    returns): 0.2 mm too far along x in the second frame, with no value at x > 4 mm:

    >>> from harpx.imaging.synth import synthesize_tagged
    >>> from harpx.tracking.results import tracking_error
    >>> tagged = synthesize_tagged(
    ...     lambda X, t: np.broadcast_to([0.5 * t / 20.0, 0.0, 0.0], X.shape), shape=(4, 8, 8),
    ...     spacing=(2.0, 2.0, 2.0), times=[0.0, 20.0], tags=("x",), snr=None, oversample=1,
    ...     body=lambda X: (np.hypot(X[:, 0], X[:, 1]) < 6.0).astype(float))
    >>> u = tagged.displacement_true  # (time, axis, z, y, x) mm, NaN outside the body
    >>> wrong = u + xr.DataArray([[0.0, 0.0, 0.0], [0.2, 0.0, 0.0]], dims=("time", "axis"))
    >>> tracked = xr.Dataset({"displacement_grid": wrong.where(wrong.x < 4.0)})
    >>> err = tracking_error(tracked, tagged)
    >>> err["mean"].round(3).values.tolist(), float(err.coverage)  # 28 of 32 voxels per slice
    ([0.0, 0.2], 0.875)

    Only the voxels at x < 0 mm (``where``), all of which the result covers:

    >>> float(tracking_error(tracked, tagged, where=tagged.x < 0.0).coverage)
    1.0
    """
    if "displacement_true" not in truth:
        raise ValueError("truth has no 'displacement_true'; pass the synthetic tagged dataset")
    if "displacement_grid" not in tracked:
        raise ValueError("tracked has no 'displacement_grid'; track with harpx.tracking.track")
    true = truth["displacement_true"]
    est = tracked["displacement_grid"]
    est = _on_grid_of(est, true)
    t_est = np.asarray(est.time.values, dtype=np.float64)
    t_true = np.asarray(true.time.values, dtype=np.float64)
    nearest_true, match = _frame_match(t_est, t_true)
    _check_reference(true, t_est, t_true, nearest_true, match)
    est = est.isel(time=np.flatnonzero(match))
    true = true.isel(time=nearest_true[match])
    est = est.assign_coords(time=true.time.values)
    # numpy ufuncs on DataArrays return DataArrays (__array_ufunc__); numpy's stubs say ndarray
    err = cast(xr.DataArray, np.sqrt(((est - true) ** 2).sum("axis", skipna=False)))
    body = cast(xr.DataArray, np.isfinite(true)).all("axis")
    if where is not None:
        where = where.broadcast_like(body).astype(bool)
        body = body & where
        err = err.where(where)
    covered = cast(xr.DataArray, np.isfinite(err))
    values = err.values.reshape(err.sizes["time"], -1)
    ok = covered.values.reshape(err.sizes["time"], -1)

    def frame_stat(fn: Any) -> FloatArray:
        return np.array([fn(v[m]) if m.any() else np.nan for v, m in zip(values, ok, strict=True)])

    everything = values[1:][ok[1:]]  # the reference frame is exact by construction
    if everything.size == 0:
        raise ValueError(
            f"no body voxel after the reference frame has both a true and a tracked "
            f"displacement (frames {true.time.values.tolist()} ms; body voxels "
            f"{int(body.values[1:].sum())}, covered {int(ok[1:].sum())}): the tracked result "
            "does not overlap the truth's body"
            + (
                " within 'where'; pass a 'where' that selects body voxels"
                if where is not None
                else "; pass the truth of the same acquisition and grid"
            )
        )
    stats = {
        "mean": (frame_stat(np.mean), float(np.mean(everything))),
        "sd": (frame_stat(np.std), float(np.std(everything))),
        "p95": (frame_stat(lambda v: np.percentile(v, 95)), float(np.percentile(everything, 95))),
        "max": (frame_stat(np.max), float(np.max(everything))),
    }
    out = xr.Dataset(coords={"time": true.time})
    for name, (per_frame, overall) in stats.items():
        out[name] = xr.DataArray(
            per_frame, dims="time", attrs={"units": "mm", "long_name": f"{name} displacement error"}
        )
        out[f"{name}_all"] = xr.DataArray(
            overall,
            attrs={"units": "mm", "long_name": f"{name} displacement error over all frames"},
        )
    n_body = float(body.values.sum())
    out["coverage"] = xr.DataArray(
        float(covered.values.sum()) / n_body if n_body else np.nan,
        attrs={"units": "1", "long_name": "fraction of body voxels with a tracked displacement"},
    )
    # frames left out of the statistics: the truth's frames after the reference that have
    # no tracked frame, or one with no value in the body (failed); tracked frames the
    # truth lacks
    failed = body.values.reshape(err.sizes["time"], -1).any(axis=1) & ~ok.any(axis=1)
    untracked = np.setdiff1d(np.arange(t_true.size), nearest_true[match])
    untracked = t_true[untracked[t_true[untracked] > t_est[0]]]
    failed_t = np.asarray(true.time.values, dtype=np.float64)[failed]
    out.attrs["frames_without_estimate"] = np.sort(np.concatenate([untracked, failed_t]))
    out.attrs["frames_without_truth"] = t_est[~match]
    scored = int(ok[1:].any(axis=1).sum())
    _warn_left_out(failed_t, untracked, t_est[~match], scored)
    return out


def _on_grid_of(est: xr.DataArray, true: xr.DataArray) -> xr.DataArray:
    """The tracked grid displacement on the truth's voxel centres."""
    same = all(
        est.sizes[d] == true.sizes[d] and np.allclose(est[d].values, true[d].values)
        for d in ("z", "y", "x")
    )
    if same:
        # rebuilt sub-voxel means differ from the acquired coordinates by rounding only
        return est.assign_coords(z=true.z, y=true.y, x=true.x)
    # linear interpolation from the (finer) tracked grid; where a neighbour lies outside
    # the mesh (faces of the body), fall back to the nearest tracked voxel centre
    linear = est.interp(z=true.z, y=true.y, x=true.x)
    nearest = est.interp(z=true.z, y=true.y, x=true.x, method="nearest")
    return linear.fillna(nearest)


def _frame_match(t_est: FloatArray, t_true: FloatArray) -> tuple[IntArray, BoolArray]:
    """For each tracked frame time (ms), the nearest truth frame and whether it is the same
    time; frames are compared by time, never by position. Raises ValueError when no time
    is shared."""
    tol = 1e-6 * max(1.0, float(np.abs(np.concatenate([t_est, t_true])).max(initial=0.0)))
    nearest_true = np.abs(t_est[:, None] - t_true[None, :]).argmin(axis=1)
    match = np.abs(t_true[nearest_true] - t_est) <= tol
    if not match.any():
        raise ValueError(
            f"tracked and truth share no frame time: tracked has time {t_est.tolist()} ms, "
            f"truth {t_true.tolist()} ms; pass the truth of the same acquisition (or select "
            "matching frames with .sel(time=...))"
        )
    return nearest_true, match


def _warn_left_out(
    failed: FloatArray, untracked: FloatArray, no_truth: FloatArray, scored: int
) -> None:
    """Warn when :func:`tracking_error` left frames out of its statistics (times in ms)."""
    parts = []
    if failed.size:
        parts.append(
            f"the tracked displacement is NaN at every body voxel (a failed frame) at "
            f"t = {_times(failed)} ms"
        )
    if untracked.size:
        parts.append(f"the truth's frames at t = {_times(untracked)} ms were not tracked")
    if parts:
        parts[-1] += " (attrs['frames_without_estimate'])"
    if no_truth.size:
        parts.append(
            f"the truth has no frame at tracked t = {_times(no_truth)} ms "
            "(attrs['frames_without_truth'])"
        )
    if not parts:
        return
    warnings.warn(
        f"tracking_error left frames out: {'; '.join(parts)}. mean_all, p95_all and the "
        f"other *_all values cover only the {scored} frame(s) after the reference with a "
        "tracked and a true displacement, so they do not compare with a result scored on "
        "every frame; track every frame of the truth (or pass the truth of the same frames) "
        "to compare",
        HarpxWarning,
        stacklevel=user_stacklevel(),
    )


def _times(values: FloatArray) -> str:
    """``"60, 240"`` for frame times in ms."""
    return ", ".join(f"{float(t):g}" for t in values)


#: Largest |displacement_true| at the reference frame, relative to the largest over all
#: frames, that still counts as zero (the truth's reference configuration); plus 1e-6 mm.
_REFERENCE_ZERO = 1e-4


def _check_reference(
    true: xr.DataArray,
    t_est: FloatArray,
    t_true: FloatArray,
    nearest_true: np.ndarray,
    match: np.ndarray,
) -> None:
    """Refuse a truth whose displacement is not relative to the tracked reference frame.

    The tracked displacement is relative to its first frame; the truth's to the frame where
    it is zero. They compare only when the truth has the tracked first frame and is zero
    there (then the two reference configurations are the same), and a frame after it.
    """
    t_ref = float(t_est[0])
    times = f"tracked has time {t_est.tolist()} ms, truth {t_true.tolist()} ms"
    if not match[0]:
        raise ValueError(
            f"truth lacks the tracked result's reference frame, time {t_ref!r} ms ({times}): "
            f"the tracked displacement is relative to {t_ref!r} ms and the truth's reference "
            f"cannot be checked; pass a truth that keeps time {t_ref!r} ms (e.g. select "
            f"frames with .sel(time=[{t_ref!r}, ...]))"
        )
    values = np.asarray(true.transpose("time", ...).values, dtype=np.float64)
    size = np.where(np.isfinite(values), np.abs(values), 0.0).reshape(values.shape[0], -1)
    per_frame = size.max(axis=1, initial=0.0)  # largest |u_true| of each truth frame, mm
    tol = 1e-6 + _REFERENCE_ZERO * float(per_frame.max(initial=0.0))
    at_ref = float(per_frame[nearest_true[0]])
    if at_ref > tol:
        zero = np.flatnonzero(per_frame <= tol)
        where = (
            f"the truth is referenced to time {float(t_true[zero[0]])!r} ms"
            if zero.size
            else "no frame of the truth has zero displacement (its reference frame is not "
            "among its times)"
        )
        raise ValueError(
            f"tracked is referenced to its first frame, time {t_ref!r} ms, but the truth's "
            f"'displacement_true' there is not zero (up to {at_ref:.3g} mm): {where}, so the "
            f"two are displacements from different configurations ({times}); track from "
            "the truth's reference frame (keep it in the phase given to track) or pass a "
            f"truth referenced to {t_ref!r} ms"
        )
    if int(np.count_nonzero(match)) == 1:
        raise ValueError(
            f"tracked and truth share only the reference frame, time {t_ref!r} ms ({times}): "
            "the error there is zero by construction and there is no later frame to "
            "compare; pass a truth with the tracked frames after the reference"
        )
