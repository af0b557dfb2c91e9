"""The slice profile of thick-slice stacks, for the blur model (:mod:`harpx.tracking.blur`).

A stack's slices each measure the tissue's signal integrated over a slab; the blur model
carries that average along each tag's slice axis (the operator :math:`T` of
:mod:`harpx.tracking.blur`'s notes). This module holds what that needs: the slab geometry
a ``phase/1`` dataset carries (:func:`slab_geometry`), the operator itself
(:func:`slice_operator`), and where a tag's slice axis is seen by some tag
(:func:`axis_seen`), without which the slab model gives way to the in-plane one
(:func:`blend_corrections`).
"""

from __future__ import annotations

import numpy as np
import xarray as xr

from harpx._typing import FloatArray
from harpx.schema import GRID_DIMS, grid_step

__all__ = [
    "SEEN_TOLERANCE",
    "axis_seen",
    "blend_corrections",
    "grid_spacing",
    "slab_geometry",
    "slice_operator",
]

#: A slice axis seen by at least 1 - this fraction everywhere keeps the slice-profile model
#: alone (:mod:`harpx.tracking.blur` notes).
SEEN_TOLERANCE = 1e-6


def grid_spacing(phase: xr.Dataset) -> FloatArray:
    """Voxel spacing (z, y, x) of the phase grid.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images (or any dataset with ``z``, ``y``, ``x`` coordinates, mm).

    Returns
    -------
    ndarray, shape (3,)
        Mean coordinate step along z, y, x (:func:`harpx.schema.grid_step`), mm; 1 along an
        axis with fewer than two voxels.
    """
    return np.array([grid_step(phase, d) or 1.0 for d in GRID_DIMS])


def slab_geometry(
    phase: xr.Dataset, t: int, spacing: FloatArray
) -> tuple[float, FloatArray] | None:
    """Slice thickness and slice centres of one tag, if the phase carries them and resolves.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images with ``slice_thickness`` (tag) and ``slice_position`` (tag,
        slice) where known (NaN pads a tag with fewer slices).
    t : int
        Tag index.
    spacing : ndarray, shape (3,)
        Grid spacing (z, y, x), mm (:func:`grid_spacing`).

    Returns
    -------
    (float, ndarray) or None
        Thickness (mm) and increasing slice centres (mm); None when the phase does not
        carry them, or its grid does not resolve the slab (spacing along the slice axis
        above half the thickness, :mod:`harpx.tracking.blur` notes).
    """
    if "slice_thickness" not in phase.variables or "slice_position" not in phase.variables:
        return None
    thickness = float(np.asarray(phase["slice_thickness"].values, dtype=np.float64)[t])
    centres = np.asarray(phase["slice_position"].transpose("tag", ...).values, np.float64)[t]
    centres = centres[np.isfinite(centres)]
    normal = GRID_DIMS.index(str(np.asarray(phase["slice_axis"].values)[t]))
    if not (np.isfinite(thickness) and thickness > 0 and centres.size):
        return None
    if spacing[normal] > 0.5 * thickness or np.any(np.diff(centres) <= 0):
        return None
    return thickness, centres


def slice_operator(
    planes: FloatArray, thickness: float, centres: FloatArray, wavenumber: float = 0.0
) -> np.ndarray:
    r"""The slice profile and interpolation between slices along a slice axis, :math:`T`.

    Parameters
    ----------
    planes : ndarray, shape (n,)
        Evenly spaced positions of the grid planes along the slice axis, mm.
    thickness : float
        Slice thickness (boxcar profile), mm.
    centres : ndarray, shape (s,)
        Increasing slice centres, mm.
    wavenumber : float, default 0
        The tag's wave-vector component along the slice axis, :math:`k_\zeta`, rad/mm.

    Returns
    -------
    ndarray of complex, shape (n, n)
        :math:`T = E^* L W E` (:mod:`harpx.tracking.blur` notes): ``T @ S`` along the
        slice axis is the demodulated signal the slices measure, interpolated back to the
        planes; rows of planes outside every slab are 0.

    Examples
    --------
    >>> T = slice_operator(np.arange(6.0), 3.0, np.array([1.0, 4.0]))
    >>> T.real.round(3)[1].tolist()  # plane 1 is slice 0's centre: its slab's mean
    [0.333, 0.333, 0.333, 0.0, 0.0, 0.0]
    """
    z = np.asarray(planes, dtype=np.float64)
    c = np.asarray(centres, dtype=np.float64)
    step = float(z[1] - z[0]) if z.size > 1 else float(thickness)
    half = 0.5 * float(thickness)
    # W (slice, plane): overlap of plane i's cell with slab s, over the thickness
    overlap = np.minimum(z[None, :] + 0.5 * step, c[:, None] + half) - np.maximum(
        z[None, :] - 0.5 * step, c[:, None] - half
    )
    W = np.clip(overlap, 0.0, None) / float(thickness)
    # L (plane, slice): linear in the slice position, nearest beyond the outer centres
    eye = np.eye(c.size)
    L = np.stack([np.interp(z, c, eye[s]) for s in range(c.size)], axis=1)
    eps = 1e-6 * step
    L[(z < c[0] - half - eps) | (z > c[-1] + half + eps)] = 0.0
    carrier = np.exp(1j * wavenumber * z)
    return np.asarray(np.conj(carrier)[:, None] * (L @ W) * carrier[None, :])


def axis_seen(phase: xr.Dataset, voxels: np.ndarray) -> FloatArray:
    """Fraction of each image axis (x, y, z) that the tags acquired at some voxels see.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` images: ``tag_direction`` and, if present, the per-tag ``mask`` of the
        acquisition (without one every tag covers the whole grid).
    voxels : ndarray of int, shape (n,)
        Row-major (z, y, x) indices of grid voxels.

    Returns
    -------
    ndarray, shape (n, 3)
        ``|P e_a|²`` for the image axes ``e_a``, ``P`` the projector onto the span of the
        directions of the tags whose mask holds the voxel, in [0, 1].

    Examples
    --------
    >>> import xarray as xr
    >>> ds = xr.Dataset(coords={"tag_direction": (("tag", "axis"), [[1.0, 0, 0], [0, 1.0, 0]])})
    >>> axis_seen(ds, np.array([0])).tolist()  # x and y tags: z unseen
    [[1.0, 1.0, 0.0]]
    """
    index = np.asarray(voxels, dtype=np.int64)
    directions = np.asarray(
        phase["tag_direction"].transpose("tag", "axis").values, dtype=np.float64
    )  # (tag, x y z)
    if "mask" in phase.variables:
        mask = np.asarray(phase["mask"].transpose("tag", *GRID_DIMS).values, dtype=bool)
        cover = mask.reshape(mask.shape[0], -1)[:, index]
    else:
        cover = np.ones((directions.shape[0], index.size), dtype=bool)
    # the tags covering a voxel, as bits of one code: a projector per code met
    codes = (cover.astype(np.int64) << np.arange(cover.shape[0])[:, None]).sum(axis=0)
    out = np.zeros((index.size, 3))
    for code in np.unique(codes):  # at most 2^tag codes, not voxels
        rows = directions[[(int(code) >> t) & 1 == 1 for t in range(directions.shape[0])]]
        projector = np.linalg.pinv(rows) @ rows if rows.size else np.zeros((3, 3))
        out[codes == code] = np.clip(np.diag(projector), 0.0, 1.0)
    return out


def blend_corrections(
    profiled: np.ndarray, plain: np.ndarray, weighted: np.ndarray, density: np.ndarray
) -> None:
    """Blend a slice-profile correction and an in-plane one (rad), in place into ``profiled``.

    Parameters
    ----------
    profiled, plain : ndarray of float32, same shape
        The two models' corrections of one tag and frame (0 outside the tissue).
    weighted, density : ndarray, shape (profiled.size,)
        The splatted density times the seen fraction of the tag's slice axis, and the
        splatted density: the slice-profile model's weight is their ratio (1 where no
        tissue lands), the in-plane model's its complement, blended as unit phasors.
    """
    w = np.divide(weighted, density, out=np.ones_like(weighted), where=density > 0)
    w = np.clip(w, 0.0, 1.0).reshape(profiled.shape)
    sine = w * np.sin(profiled) + (1.0 - w) * np.sin(plain)
    cosine = w * np.cos(profiled) + (1.0 - w) * np.cos(plain)
    profiled[...] = np.where((profiled != 0) | (plain != 0), np.arctan2(sine, cosine), 0.0)
