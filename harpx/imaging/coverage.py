"""Why sample points see no image data: a diagnosis that names the cause.

When no constraint point of a body has valid phase, the causes look alike from the inside
(every sample is invalid) but need different fixes. :func:`explain_missing_data` checks
them in order and returns one sentence for the first that applies:

1. a tag's ``mask`` is all False (no acquisition has data anywhere);
2. the frame's images have no tag pattern (a blank, constant or missing frame);
3. the points lie outside the field of view (wrong units or origin);
4. the points lie outside every tag's mask (the slab of slices misses the body);
5. the points lie where the frame has no tissue signal (the tissue moved away from them);
6. a tag's phase varies along another axis than its ``tag_direction`` (directions
   swapped between tags, or row/column confused when reading DICOM).

Only the frame in question is read (per tag its magnitude and a 1-voxel phase difference),
so it is cheap enough to run before raising an error.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx.imaging._kernels import wrap
from harpx.schema import AXES, GRID_DIMS, grid_step

__all__ = ["CHECK_STRIDE", "explain_missing_data", "phase_direction_mismatch"]


def explain_missing_data(phase: xr.Dataset, points: ArrayLike, time_index: int = 0) -> str:
    """The likeliest reason why ``points`` have no valid phase in one frame.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset (``phase``, ``magnitude``, optional ``mask``).
    points : array_like, shape (n, 3)
        Sample positions (x, y, z) in mm.
    time_index : int, default 0
        Frame to diagnose.

    Returns
    -------
    str
        One sentence naming the cause and the fix (a generic overlap hint if none of the
        checks applies).

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> ds = xr.Dataset(
    ...     {"magnitude": (("tag", "time", "z", "y", "x"), np.zeros((1, 1, 2, 2, 2)))},
    ...     coords={"tag": ["x"], "z": [0.0, 1.0], "y": [0.0, 1.0], "x": [0.0, 1.0]},
    ... )
    >>> explain_missing_data(ds, [[0.5, 0.5, 0.5]])[:47]
    "frame 0 of tag 'x' has no tag pattern (harmonic"
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tags = [str(t) for t in np.asarray(phase["tag"].values).ravel()]
    mask = phase["mask"] if "mask" in phase.variables else None
    if mask is not None:
        for t, tag in enumerate(tags):
            if not bool(mask.isel(tag=t).any()):
                return (
                    f"'mask' of tag {tag!r} is all False, so that acquisition has no data "
                    "anywhere; set it True where the tag's slices were acquired"
                )
    if "magnitude" in phase.variables:
        for t, tag in enumerate(tags):
            peak = float(np.nanmax(np.abs(phase["magnitude"].isel(tag=t, time=time_index))))
            if not peak > 0:
                return (
                    f"frame {time_index} of tag {tag!r} has no tag pattern (harmonic "
                    f"magnitude max {peak:g}): its image is blank or constant (one value "
                    f"everywhere); drop it (ds.drop_isel(time={time_index})) or fix its images"
                )
    low, high = [], []
    for axis in AXES:
        values = np.asarray(phase[axis].values, dtype=np.float64)
        half = 0.5 * (grid_step(phase, axis) or 1.0)
        low.append(values[0] - half)
        high.append(values[-1] + half)
    inside = np.all((pts >= np.array(low)) & (pts <= np.array(high)), axis=1)
    if not inside.any():
        return (
            f"no point lies inside the field of view (x, y, z from {np.round(low, 3).tolist()} "
            f"to {np.round(high, 3).tolist()} mm; the points span "
            f"{np.round(pts.min(axis=0), 3).tolist()} to {np.round(pts.max(axis=0), 3).tolist()}"
            " mm): check the mesh's units (mm) and origin"
        )
    sel = {d: xr.DataArray(pts[inside, AXES.index(d)], dims="point") for d in GRID_DIMS}
    if mask is not None:
        hit = mask.transpose("tag", *GRID_DIMS).sel(sel, method="nearest")
        if not bool(hit.any()):
            return (
                "the points lie inside the field of view but outside every tag's 'mask' (the "
                "acquired slices miss the body); check the slice positions or the mask"
            )
    if "magnitude" in phase.variables:
        signal = _with_signal(phase, sel, time_index)
        if signal < FAINT_FRACTION:
            later = (
                "the tissue has moved away from the tracked body: most likely it moved a tag "
                "period or more between two frames, which the phase cannot tell from no "
                "motion (check target_reached of the frames before; track with more frames)"
                if time_index > 0
                else "the mesh lies off the tissue: check its position against the images"
            )
            return (
                f"the points lie inside the field of view and the masks but where frame "
                f"{time_index} has no tissue signal (only {100 * signal:.1f} % of them have a "
                f"harmonic magnitude above {MAGNITUDE_FLOOR:g} of its 99th percentile in "
                f"every tag): {later}"
            )
    mismatch = phase_direction_mismatch(phase, time_index)
    if mismatch:
        return mismatch
    return "check that the mesh (mm) and the image grid (coords x, y, z) overlap"


#: Fraction of a frame's 99th-percentile harmonic magnitude below which a point has no
#: tissue signal (the default floor of :class:`harpx.imaging.sample.PhaseSampler`).
MAGNITUDE_FLOOR = 0.05
#: Below this fraction of points with tissue signal, missing signal is the diagnosis.
FAINT_FRACTION = 0.05


def _with_signal(phase: xr.Dataset, sel: dict[str, xr.DataArray], time_index: int) -> float:
    """Fraction of the selected voxels above every tag's magnitude floor in one frame."""
    signal = np.ones(sel[GRID_DIMS[0]].size, dtype=bool)
    for t in range(phase.sizes["tag"]):
        frame = phase["magnitude"].isel(tag=t, time=time_index)
        values = np.abs(np.asarray(frame.values, dtype=np.float64))
        if "mask" in phase.variables:
            inside = np.asarray(phase["mask"].isel(tag=t).transpose(*frame.dims).values, bool)
            values = values[inside] if inside.any() else values
        finite = values[np.isfinite(values)]
        if not finite.size:
            continue
        floor = MAGNITUDE_FLOOR * float(np.percentile(finite, 99))
        signal &= np.abs(np.asarray(frame.sel(sel, method="nearest").values)) >= floor
    return float(signal.mean()) if signal.size else 1.0


#: :func:`phase_direction_mismatch` reads every this many lines of voxels along each axis.
CHECK_STRIDE = 4


def phase_direction_mismatch(phase: xr.Dataset, time_index: int = 0) -> str:
    """A sentence if some tag's phase varies mostly along another axis than its direction.

    The mean absolute wrapped phase step per mm along each grid axis (over voxels with the
    upper quarter of the magnitude, inside the tag's mask) points along the tag's wave
    vector. For a tag clearly along one axis (component > 0.8), the rate along that axis
    must be at least half the largest rate. The means are taken over every
    :data:`CHECK_STRIDE`-th line of voxels along each axis (steps between neighbouring
    voxels of a line, so no step is wider than the grid's): a sample of the volume.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset.
    time_index : int, default 0
        Frame to check.

    Returns
    -------
    str
        Empty if every tag is consistent.
    """
    if "tag_direction" not in phase.coords:
        return ""
    for t, tag in enumerate(str(v) for v in np.asarray(phase["tag"].values).ravel()):
        values = np.asarray(phase["phase"].isel(tag=t, time=time_index).values)
        strong = None
        if "magnitude" in phase.variables:
            mag = np.asarray(phase["magnitude"].isel(tag=t, time=time_index).values)
            every = (slice(None, None, CHECK_STRIDE),) * 3
            strong = mag >= np.nanpercentile(mag[every], 75)
            if "mask" in phase.variables:
                strong &= np.asarray(phase["mask"].isel(tag=t).values, bool)
        rate = np.zeros(3)
        for g, dim in enumerate(GRID_DIMS):
            if values.shape[g] < 2:
                continue
            step = grid_step(phase, dim) or 1.0  # at least two planes here
            lines = tuple(
                slice(None) if a == g else slice(None, None, CHECK_STRIDE) for a in range(3)
            )
            wrapped = wrap(np.diff(values[lines].astype(np.float64), axis=g))
            keep = (
                np.ones(wrapped.shape, bool)
                if strong is None
                else np.take(strong[lines], range(values.shape[g] - 1), axis=g)
            )
            if keep.any():
                rate[AXES.index(dim)] = float(np.nanmean(np.abs(wrapped[keep]))) / abs(step)
        direction = np.asarray(phase["tag_direction"].isel(tag=t).values, dtype=np.float64)
        main = int(np.argmax(np.abs(direction)))
        clear = abs(direction[main]) > 0.8  # a tag clearly along one axis
        if clear and rate.max() > 0 and rate[main] < 0.5 * rate.max():
            return (
                f"tag {tag!r} has tag_direction {np.round(direction, 3).tolist()} but its "
                f"phase varies along {AXES[int(np.argmax(rate))]!r} "
                f"({np.round(rate, 3).tolist()} rad/mm along x, y, z): are the tag directions "
                "swapped between tags (or row and column confused)?"
            )
    return ""
