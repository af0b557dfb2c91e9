r"""Contour points of the ventricle from myocardium masks, for its fit.

:func:`ventricle_contours` extracts the points from a myocardium mask (a tissue fraction
such as a ``tagged/1`` dataset's ``body``, or a binary mask): the 0.5 iso-contour is found
between neighbouring voxel centres by linear interpolation along the two in-plane axes of
the short-axis slices; a crossing whose low side lies in the cavity (the holes of the mask
within each slice) is endocardial, otherwise epicardial; crossings along the slice axis
near the top of the wall give the base. Long-axis contours are simply more points for
:func:`~harpx.anatomy.ventricle_template.fit_ventricle`.

The fit to a mask (:mod:`~harpx.anatomy.mask_fit`) also takes the crossings of long-axis
label volumes from here, classified by a first fitted template, and which of their ends is
the apex.

Units: mm.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
import scipy.ndimage as ndi
from numpy.typing import ArrayLike

from harpx._typing import FloatArray, IntArray
from harpx.anatomy.ventricle_template import VentricleTemplate
from harpx.io.labels import read_labels
from harpx.schema import grid_step

__all__ = ["ventricle_contours"]


def _crossings(
    f: FloatArray, coords: list[FloatArray], dim: int
) -> tuple[FloatArray, IntArray, Any]:
    """0.5 crossings of ``f`` along grid dimension ``dim`` (0 z, 1 y, 2 x).

    Returns the points (n, 3; x, y, z mm, linear interpolation between voxel centres), the
    (z, y, x) index of the voxel on the low-valued side, and whether that side comes first.
    """
    lo = [slice(None)] * 3
    hi = [slice(None)] * 3
    lo[dim], hi[dim] = slice(None, -1), slice(1, None)
    fa, fb = f[tuple(lo)], f[tuple(hi)]
    hit = (fa - 0.5) * (fb - 0.5) < 0
    idx = np.argwhere(hit)
    w = (0.5 - fa[hit]) / (fb[hit] - fa[hit])
    pos = np.stack([coords[k][idx[:, k]] for k in range(3)], axis=1)  # (z, y, x)
    step = np.diff(coords[dim])[idx[:, dim]]
    pos[:, dim] += w * step
    low_first = fa[hit] < fb[hit]
    low = idx.copy()
    low[:, dim] += np.where(low_first, 0, 1)
    return pos[:, ::-1], low, low_first


def _plane_structure(normal: int) -> Any:
    """4-connected in-plane structuring element of the slices normal to ``normal``."""
    structure = np.zeros((3, 3, 3), dtype=bool)
    plane = [slice(None)] * 3
    plane[normal] = slice(1, 2)
    structure[tuple(plane)] = np.expand_dims(ndi.generate_binary_structure(2, 1), normal)
    return structure


def ventricle_contours(
    mask: Any,
    *,
    slice_axis: Literal["x", "y", "z"] = "z",
    variable: str | None = None,
    axis: ArrayLike | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Endocardial, epicardial and base points of a myocardium mask.

    Parameters
    ----------
    mask : xarray.Dataset, xarray.DataArray, str or os.PathLike
        Myocardium fraction or binary mask on a ``(z, y, x)`` grid (see
        :func:`~harpx.io.labels.read_labels`; a ``tagged/1`` dataset gives
        its ``body``).
    slice_axis : {"x", "y", "z"}, default "z"
        Grid axis normal to the short-axis slices (the closest one for oblique hearts).
    variable : str, optional
        Mask variable of a dataset.
    axis : array_like, shape (3,), optional
        Long-axis direction (apex to base) that tells the base from the apex; default the
        direction from the epicardial to the endocardial points' centroid.

    Returns
    -------
    endo, epi, base : ndarray, shape (n, 3)
        Image points (mm) of the 0.5 iso-contour: in-plane crossings split by the side of
        the cavity, and slice-axis crossings with tissue on their apical side only
        (outside the cavity). Voxels fill their extent: beyond the first and last slice
        the mask is taken as background, so the end faces lie half a slice step beyond
        the outer slice centres.
    """
    da = read_labels(mask, variable=variable)
    f, coords = _padded_along(np.asarray(da.values, dtype=np.float64), da, slice_axis)
    normal = ("z", "y", "x").index(slice_axis)
    inside = f >= 0.5
    cavity = ndi.binary_fill_holes(inside, structure=_plane_structure(normal)) & ~inside
    return _contours(f, coords, normal, cavity, axis, np.ones(f.shape[normal], dtype=bool))


def _padded_along(f: FloatArray, da: Any, slice_axis: str) -> tuple[FloatArray, list[FloatArray]]:
    """The volume with one background slice added at both ends of the slice axis."""
    normal = ("z", "y", "x").index(slice_axis)
    coords = [np.asarray(da[d].values, dtype=np.float64) for d in ("z", "y", "x")]
    c = coords[normal]
    step = grid_step(da, slice_axis) or 1.0
    coords[normal] = np.concatenate([[c[0] - step], c, [c[-1] + step]])
    pad = [(0, 0)] * 3
    pad[normal] = (1, 1)
    return np.pad(f, pad, mode="constant", constant_values=0.0), coords


def _contours(
    f: FloatArray,
    coords: list[FloatArray],
    normal: int,
    cavity: Any,
    axis: ArrayLike | None,
    use: Any,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Endo, epi and base points of ``f`` from the slices flagged in ``use``."""
    endo_pts, epi_pts = [], []
    for dim in range(3):  # the two in-plane axes
        if dim == normal:
            continue
        pts, low, _ = _crossings(f, coords, dim)
        keep = use[low[:, normal]]
        in_cavity = cavity[tuple(low.T)]
        endo_pts.append(pts[keep & in_cavity])
        epi_pts.append(pts[keep & ~in_cavity])
    endo_all, epi_all = np.concatenate(endo_pts), np.concatenate(epi_pts)
    pts, low, low_first = _crossings(f, coords, normal)
    # the base faces the base direction: tissue on the apical side, nothing on the basal
    # side (the cavity centroid lies basal of the epicardial one, which holds the apex)
    if axis is None:
        axis = endo_all.mean(axis=0) - epi_all.mean(axis=0)
    towards = float(np.asarray(axis, dtype=np.float64)[2 - normal])
    outward_up = ~low_first  # the tissue is at the lower index, nothing above
    top = outward_up if towards >= 0 else ~outward_up
    base_pts = pts[top & ~cavity[tuple(low.T)]]
    return endo_all, epi_all, base_pts


def _covers_axis(inside: Any, cavity: Any, normal: int, ring: int, towards: int) -> bool:
    """Whether the slice next to ring slice ``ring`` (in direction ``towards``) has tissue
    within two voxels of the centroid of that ring's cavity."""
    hole = np.argwhere(np.take(cavity, ring, axis=normal))
    tissue = np.argwhere(np.take(inside, ring + towards, axis=normal))
    if hole.size == 0 or tissue.size == 0:
        return False
    return bool(np.min(np.linalg.norm(tissue - hole.mean(axis=0), axis=1)) <= 2.0)


def _lax_sense(
    volumes: list[tuple[FloatArray, list[FloatArray], FloatArray]],
    centre: FloatArray,
    e_n: FloatArray,
    band: float,
) -> float | None:
    """+1 when long-axis slices put the apex at the low end of ``e_n``, -1 at the high end.

    At the apex the wall crosses the long axis (the line through ``centre`` along ``e_n``);
    at the base its two sides stay a cavity radius away. The end of the tissue (within
    ``band`` mm of its extreme) that comes closer to the axis is the apex; None when
    neither end does (closer than half the other's distance).
    """
    xyz = np.concatenate([v[2] for v in volumes])
    s = (xyz - centre) @ e_n
    r = np.linalg.norm((xyz - centre) - np.outer(s, e_n), axis=1)
    near_low = float(r[s < s.min() + band].min())
    near_high = float(r[s > s.max() - band].min())
    if near_low < 0.5 * near_high:
        return 1.0
    if near_high < 0.5 * near_low:
        return -1.0
    return None


def _lax_points(
    volumes: list[tuple[FloatArray, list[FloatArray], FloatArray]], template: VentricleTemplate
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Endo, epi and base points of long-axis label volumes, classified by ``template``.

    Each volume holds the myocardium of one long-axis slice on an axis-aligned grid (the
    slice's slab, background elsewhere). Iso-surface crossings whose mask gradient points
    out of the slice plane (the slab faces) are dropped; the others are endocardial where
    the tissue lies outward of the crossing along the template's layer normal, epicardial
    otherwise, and basal where the tissue lies apical of a crossing in the upper half of
    the slice's tissue.
    """
    endo, epi, base = [], [], []
    u = template.axis
    for f, coords, xyz in volumes:  # a few long-axis slices
        _, sv, vt = np.linalg.svd(xyz - xyz.mean(axis=0), full_matrices=False)
        plane_normal = vt[2] if sv[2] < 0.3 * sv[0] else None
        grad = np.gradient(f, *coords)  # d/dz, d/dy, d/dx
        s_tissue = xyz @ u
        s_mid = 0.5 * (s_tissue.min() + s_tissue.max())
        for dim in range(3):
            pts, low, low_first = _crossings(f, coords, dim)
            high = low.copy()
            high[:, dim] += np.where(low_first, 1, -1)
            g = np.stack(
                [0.5 * (grad[2 - a][tuple(low.T)] + grad[2 - a][tuple(high.T)]) for a in range(3)],
                axis=1,
            )
            g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-12)
            if plane_normal is not None:
                in_plane = np.abs(g @ plane_normal) < 0.5
                pts, g = pts[in_plane], g[in_plane]
            e_r = template.local_basis(pts)[0]
            basal = (g @ u < -0.7) & (pts @ u > s_mid)
            outward = np.einsum("ni,ni->n", g, e_r) > 0
            endo.append(pts[~basal & outward])
            epi.append(pts[~basal & ~outward])
            base.append(pts[basal])
    return np.concatenate(endo), np.concatenate(epi), np.concatenate(base)
