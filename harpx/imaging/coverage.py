"""Why sample points see no image data: a diagnosis that names the cause.

When no constraint point of a body has valid phase, the causes look alike from the inside
(every sample is invalid) but need different fixes. :func:`explain_missing_data` checks
them in order and returns one sentence for the first that applies:

1. a tag's ``mask`` is all False (no acquisition has data anywhere);
2. the frame's images are all zero (a blank or missing frame);
3. the points lie outside the field of view (wrong units or origin);
4. the points lie outside every tag's mask (the slab of slices misses the body);
5. a tag's phase varies along another axis than its ``tag_direction`` (directions
   swapped between tags, or row/column confused when reading DICOM).

Only a few voxels per tag and frame are read (the frame's magnitude and a 1-voxel phase
difference), so it is cheap enough to run before raising an error.
"""

from __future__ import annotations

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx.schema import AXES, GRID_DIMS

__all__ = ["explain_missing_data", "phase_direction_mismatch"]


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
    >>> explain_missing_data(ds, [[0.5, 0.5, 0.5]])[:48]
    "frame 0 of tag 'x' is all zero (magnitude max 0)"
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
                    f"frame {time_index} of tag {tag!r} is all zero (magnitude max {peak:g}): "
                    f"a blank frame; drop it (ds.drop_isel(time={time_index})) or fix its images"
                )
    low, high = [], []
    for axis in AXES:
        values = np.asarray(phase[axis].values, dtype=np.float64)
        half = 0.5 * float(values[1] - values[0]) if values.size > 1 else 0.5
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
    if mask is not None:
        sel = {d: xr.DataArray(pts[inside, AXES.index(d)], dims="point") for d in GRID_DIMS}
        hit = mask.transpose("tag", *GRID_DIMS).sel(sel, method="nearest")
        if not bool(hit.any()):
            return (
                "the points lie inside the field of view but outside every tag's 'mask' (the "
                "acquired slices miss the body); check the slice positions or the mask"
            )
    mismatch = phase_direction_mismatch(phase, time_index)
    if mismatch:
        return mismatch
    return "check that the mesh (mm) and the image grid (coords x, y, z) overlap"


def phase_direction_mismatch(phase: xr.Dataset, time_index: int = 0) -> str:
    """A sentence if some tag's phase varies mostly along another axis than its direction.

    The mean absolute wrapped phase step per mm along each grid axis (over voxels with the
    upper quarter of the magnitude, inside the tag's mask) points along the tag's wave
    vector. For a tag clearly along one axis (component > 0.8), the rate along that axis
    must be at least half the largest rate.

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
        values = np.asarray(phase["phase"].isel(tag=t, time=time_index).values, dtype=np.float64)
        strong = None
        if "magnitude" in phase.variables:
            mag = np.asarray(phase["magnitude"].isel(tag=t, time=time_index).values)
            strong = mag >= np.nanpercentile(mag, 75)
            if "mask" in phase.variables:
                strong &= np.asarray(phase["mask"].isel(tag=t).values, bool)
        rate = np.zeros(3)
        for g, dim in enumerate(GRID_DIMS):
            if values.shape[g] < 2:
                continue
            step = float(phase[dim].values[1] - phase[dim].values[0])
            wrapped = np.angle(np.exp(1j * np.diff(values, axis=g)))
            keep = (
                np.ones(wrapped.shape, bool)
                if strong is None
                else np.take(strong, range(values.shape[g] - 1), axis=g)
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
