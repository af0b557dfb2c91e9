"""Can a body be tracked on an image grid at all? Cheap checks before tracking allocates.

:func:`check_fits_image` compares a body's nodes (mm) with the image's field of view and
voxel size and estimates the constraint quadrature the tracker would place, so a mesh in the
wrong units, with stray nodes, or too coarse for the voxels is refused with numbers before
anything large is allocated. :func:`check_coverage` then measures, from the constraint
points, how much of the body lies outside the images' field of view or masks, or inside
them on background (no tissue signal), and warns when either part is large enough to bias
the tracked motion of the rest; :func:`background_fraction` gives the second part for the
result's attributes.
"""

from __future__ import annotations

import warnings
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from harpx._typing import FloatArray
from harpx.errors import HarpxWarning, SchemaError, user_stacklevel
from harpx.imaging.phase_parameters import PhaseParameters
from harpx.mechanics.body import Body
from harpx.mechanics.cells import _VTK_TET_EDGES
from harpx.schema import AXES, GRID_DIMS, grid_step

__all__ = [
    "BACKGROUND_WARN",
    "OUTSIDE_WARN",
    "background_fraction",
    "check_coverage",
    "check_fits_image",
]

#: Fraction of the body's volume outside the images' field of view or every tag's mask
#: (in the reference frame) above which :func:`check_coverage` warns.
OUTSIDE_WARN = 0.05

#: Fraction of the body's volume inside the field of view and masks but without tissue
#: signal from any tag (in the reference frame) above which :func:`check_coverage` warns.
#: A mesh fitted to the tissue has some such volume at its edges, where the band-pass blur
#: or partial volume drops the magnitude below its floor; the user guide ("Choosing ε and
#: the penalty") gives how much the bundled scenes have, a few per cent.
BACKGROUND_WARN = 0.15

_EDGES_BY_DIRECTION = np.array(
    [[[0, 1], [3, 2], [4, 5], [7, 6]], [[0, 3], [1, 2], [4, 7], [5, 6]],
     [[0, 4], [1, 5], [2, 6], [3, 7]]]
)  # fmt: skip
# bytes held per constraint quadrature point and basis function (values, gradients, work
# arrays), plus per point (positions, weights, phase samples): a generous estimate
_BYTES_PER_POINT_BASIS = 64
_BYTES_PER_POINT = 400


def check_fits_image(body: Body, grid: Any, *, max_points: int = 10_000_000) -> None:
    """Raise before tracking if a body's size or position cannot match an image grid.

    Cheap checks (a pass over nodes and cells) that catch a mesh in the wrong units or
    with stray nodes before the tracker allocates its constraint quadrature, whose point
    count grows with (cell size / voxel size)³:

    * every node lies within one field of view (the largest extent of the grid) of the
      image's field of view;
    * the mesh is larger than one voxel;
    * the constraint quadrature, points at most one acquired voxel apart as the tracker
      places them, has at most ``max_points`` points.

    Parameters
    ----------
    body : Body
        The tracking body (mm).
    grid : xarray.Dataset
        A ``tagged/1`` or ``phase/1`` dataset: coordinates ``z``, ``y``, ``x`` (mm) and,
        for phase images, the ``upsample`` attribute (the acquired voxel is ``upsample``
        grid steps).
    max_points : int, default 10_000_000
        Largest constraint quadrature allowed (about 1 kB of memory per point).

    Raises
    ------
    TypeError
        If ``body`` is not a Body or ``grid`` has no coordinates.
    NotImplementedError
        For a body on curved hexahedra (``skfem.MeshHex2``): tracking samples the body
        through the straight-cell point locator.
    ValueError
        Naming the nodes far outside the field of view, the mesh and field-of-view sizes,
        the estimated point count and memory, and a likely unit mix-up (µm or m instead
        of mm) when the size ratio suggests one.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from harpx.mechanics.mesh import box
    >>> from harpx.mechanics.materials import NeoHookean
    >>> grid = xr.Dataset(coords={d: np.arange(16.0) for d in "zyx"})
    >>> body = Body(box((8.0, 8.0, 8.0), (2, 2, 2), origin=(4.0, 4.0, 4.0)), NeoHookean(1, 120))
    >>> check_fits_image(body, grid)  # inside, in mm: nothing to say
    >>> far = Body(box((8e3, 8e3, 8e3), (2, 2, 2)), NeoHookean(1, 120))  # micrometres
    >>> try:
    ...     check_fits_image(far, grid)
    ... except ValueError as err:
    ...     print(str(err).split(": ")[-1])
    are its coordinates in micrometres (divide by 1000)?
    """
    import skfem

    if not isinstance(body, Body):
        raise TypeError(f"body must be a harpx Body, got {type(body).__name__!r}")
    if not hasattr(grid, "coords"):
        raise TypeError(
            f"grid must be a tagged/1 or phase/1 xarray.Dataset, got {type(grid).__name__!r}"
        )
    if isinstance(body.mesh, skfem.MeshHex2):
        raise NotImplementedError(
            "tracking a body on curved hexahedra (skfem.MeshHex2) is not implemented: the "
            "tracker locates points with the straight (trilinear) cell map; track with the "
            "straight mesh (curved=False)"
        )
    low, high, step = [], [], []
    for axis in ("x", "y", "z"):
        if axis not in grid.coords:
            raise SchemaError(f"grid has no coordinate {axis!r} (voxel centres in mm)")
        values = np.asarray(grid[axis].values, dtype=np.float64)
        if values.size == 0 or not np.all(np.isfinite(values)):
            raise SchemaError(f"grid coordinate {axis!r} is empty or not finite")
        d = grid_step(grid, axis) or 0.0
        low.append(values[0] - d / 2)
        high.append(values[-1] + d / 2)
        if values.size > 1:
            step.append(abs(d))
    lo, hi = np.array(low), np.array(high)
    fov = float((hi - lo).max())
    voxel = PhaseParameters.from_dataset(grid).upsample * min(step) if step else fov
    nodes = np.asarray(body.nodes)
    size = float(np.ptp(nodes, axis=0).max())
    if not fov > 0:
        raise SchemaError(
            f"the image grid has a single voxel along every axis (x, y, z at "
            f"{lo.round(3).tolist()} mm): there is no field of view to track in"
        )
    ratio = size / fov
    hint = ""
    if ratio > 20:
        hint = (
            f"; the mesh is {ratio:.3g} times larger than the image: are its coordinates in "
            "micrometres (divide by 1000)?"
        )
    elif size < voxel:
        hint = (
            "; the mesh is smaller than one voxel: are its coordinates in metres (multiply "
            "by 1000)?"
        )
    outside = np.maximum(lo - nodes, nodes - hi).max(axis=1)  # mm beyond the field of view
    far = np.flatnonzero(outside > fov)
    if far.size:
        shown = ", ".join(str(int(i)) for i in far[:10]) + (", ..." if far.size > 10 else "")
        raise SchemaError(
            f"mesh nodes [{shown}] lie up to {outside.max():.4g} mm outside the image field "
            f"of view ({lo.round(3).tolist()} to {hi.round(3).tolist()} mm, x/y/z); the mesh "
            f"spans {size:.4g} mm, the field of view {fov:.4g} mm"
            f"{hint if 2 * far.size > len(nodes) else '; move or fix those nodes'}"
        )
    if size < voxel:
        raise SchemaError(
            f"the mesh spans {size:.4g} mm but one acquired voxel is {voxel:.4g} mm{hint}"
        )
    count = 1
    if body.element.startswith("tet"):  # the tracker's rule: m³ points, m from the longest edge
        corners = nodes[body.cells[:, :4]]  # (ncell, 4, 3)
        pairs = _VTK_TET_EDGES
        length = np.linalg.norm(corners[:, pairs[:, 0]] - corners[:, pairs[:, 1]], axis=-1)
        m = max(1, int(np.ceil(float(length.max()) / (1.5 * voxel))))
        count = m**3
        longest = (
            f"its longest tetrahedron edge is {float(length.max()):.4g} mm, {m} points per "
            f"edge at most 1.5 voxels ({1.5 * voxel:.4g} mm) apart, {count} points per cell"
        )
    else:
        corners = nodes[body.cells[:, :8]]  # (ncell, 8, 3)
        for edges in _EDGES_BY_DIRECTION:  # n points along the longest edge per direction
            length = np.linalg.norm(corners[:, edges[:, 0]] - corners[:, edges[:, 1]], axis=-1)
            count *= max(1, int(np.ceil(float(length.max()) / voxel)))
        longest = f"its longest cells are {count ** (1 / 3):.3g} voxels ({voxel:.4g} mm) across"
    points = count * body.ncell
    if points > max_points:
        gib = points * (_BYTES_PER_POINT + _BYTES_PER_POINT_BASIS * body.nbasis) / 2**30
        raise SchemaError(
            f"tracking this mesh would place {points:.3g} constraint points (~{gib:.3g} GiB; "
            f"limit max_points={max_points:.3g}): {longest}{hint or ''}; refine the "
            "mesh (smaller cells) or check its units (mm)"
        )


class _Coverage(NamedTuple):
    """Per constraint point: its share of the body's volume (summing to 1, or all 0), and
    whether no tag has data there in frame 0 (``unseen``), it lies in the field of view
    (``low`` to ``high``, mm, x/y/z), in some tag's mask (checked only where a point is
    unseen and in view; True elsewhere), and on background (unseen, in a mask and between
    the outermost voxel centres, where the images' interpolation reaches: unseen for want
    of signal, not for the edge of the field of view)."""

    weight: FloatArray
    unseen: np.ndarray
    in_view: np.ndarray
    in_mask: np.ndarray
    background: np.ndarray
    low: FloatArray
    high: FloatArray


def _coverage_parts(
    phase: xr.Dataset, points: ArrayLike, volume: ArrayLike, valid: ArrayLike
) -> _Coverage:
    """What :func:`check_coverage` and :func:`background_fraction` measure (:class:`_Coverage`)."""
    pts = np.asarray(points, dtype=np.float64)
    weight = np.asarray(volume, dtype=np.float64).ravel()
    seen = np.asarray(valid, dtype=bool)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(weight) != len(pts) or len(seen) != len(pts):
        raise ValueError(
            f"points {pts.shape}, volume {weight.shape} and valid {seen.shape} must describe "
            "the same n constraint points: (n, 3), (n,) and (n, ntag)"
        )
    total = float(weight.sum())
    weight = weight / total if len(pts) and total > 0 else np.zeros_like(weight)
    unseen = np.asarray(~seen.reshape(len(pts), -1).any(axis=1), dtype=bool)
    low, high = np.empty(3), np.empty(3)
    first, last = np.empty(3), np.empty(3)  # the outermost voxel centres (a flat axis: all)
    for column, axis in enumerate(AXES):
        values = np.asarray(phase[axis].values, dtype=np.float64)
        half = 0.5 * float(np.ptp(values)) / max(values.size - 1, 1) if values.size > 1 else 0.5
        low[column], high[column] = values.min() - half, values.max() + half
        first[column], last[column] = (
            (values.min(), values.max()) if values.size > 1 else (low[column], high[column])
        )
    in_view = np.all((pts >= low) & (pts <= high), axis=1)
    in_mask = np.ones(len(pts), dtype=bool)
    check = unseen & in_view
    if "mask" in phase.variables and check.any():
        inside = pts[check]
        sel = {d: xr.DataArray(inside[:, AXES.index(d)], dims="point") for d in GRID_DIMS}
        mask = phase["mask"].transpose("tag", *GRID_DIMS).sel(sel, method="nearest")
        in_mask[check] = np.asarray(mask.values, dtype=bool).any(axis=0)
    interior = np.all((pts >= first) & (pts <= last), axis=1)
    background = unseen & in_mask & interior
    return _Coverage(weight, unseen, in_view, in_mask, background, low, high)


def background_fraction(
    phase: xr.Dataset, points: ArrayLike, volume: ArrayLike, valid: ArrayLike
) -> float:
    """Volume fraction of a body on image background: in view and mask, but no signal.

    The constraint points between the images' outermost voxel centres and inside some tag's
    ``mask`` where no tag has data in the reference frame (``valid``: the tracker's own
    validity, the harmonic magnitude below its floor or, with a ``body`` variable, outside
    the tissue): there nothing pulls the body, and its motion comes from the mechanics
    alone. Points in the outer half voxel of the field of view, where the images cannot be
    interpolated, are left out.

    Parameters
    ----------
    phase : xarray.Dataset
        As for :func:`check_coverage`.
    points : array_like, shape (n, 3)
        As for :func:`check_coverage`.
    volume : array_like, shape (n,)
        As for :func:`check_coverage`.
    valid : array_like of bool, shape (n, ntag)
        As for :func:`check_coverage`.

    Returns
    -------
    float
        That volume fraction, in [0, 1] (0 for a body without volume); the tracker records
        it as ``attrs["background_fraction"]``.

    Raises
    ------
    ValueError
        If the arrays do not match in length or ``points`` is not (n, 3).
    """
    parts = _coverage_parts(phase, points, volume, valid)
    return float(parts.weight[parts.background].sum())


def check_coverage(
    phase: xr.Dataset,
    points: ArrayLike,
    volume: ArrayLike,
    valid: ArrayLike,
    *,
    threshold: float = OUTSIDE_WARN,
    background: float = BACKGROUND_WARN,
) -> float:
    """Warn when much of a body lies outside the images, or inside them on background.

    Constraint points without data from any tag in the reference frame carry no force:
    there the tracked motion comes from the mechanics alone, and it drags the cells that
    are imaged. This measures the part of the body (by volume) whose points have no data
    *because* they lie outside the field of view or outside every tag's ``mask``, and
    separately the part inside both that lacks tissue signal
    (:func:`background_fraction`): a blurred tissue edge has a little of it, a mesh larger
    than the tissue or moved off it much more.

    Parameters
    ----------
    phase : xarray.Dataset
        ``phase/1`` dataset: coordinates ``z``, ``y``, ``x`` (mm), optional ``mask``.
    points : array_like, shape (n, 3)
        Reference positions (x, y, z) of the constraint points, mm.
    volume : array_like, shape (n,)
        Reference volume of each point, mm³.
    valid : array_like of bool, shape (n, ntag)
        Which tags have data at each point in the reference frame
        (``PhaseConstraint.reference_valid``).
    threshold : float, default :data:`OUTSIDE_WARN`
        Volume fraction outside the field of view or masks above which to warn, in [0, 1].
    background : float, default :data:`BACKGROUND_WARN`
        Volume fraction on background above which to warn, in [0, 1].

    Returns
    -------
    float
        Volume fraction of the body outside the field of view or every tag's mask, in
        [0, 1] (for the result's attributes).

    Raises
    ------
    ValueError
        If the arrays do not match in length or ``points`` is not (n, 3).

    Warns
    -----
    HarpxWarning
        If the fraction outside is above ``threshold`` (the message gives the fractions
        outside the field of view and outside the masks, and the fix), and if the fraction
        on background is above ``background`` (the message gives it and the fix).
    """
    parts = _coverage_parts(phase, points, volume, valid)
    weight, unseen, in_view, in_mask = parts.weight, parts.unseen, parts.in_view, parts.in_mask
    off_view = float(weight[unseen & ~in_view].sum())
    off_mask = float(weight[unseen & in_view & ~in_mask].sum())
    outside = off_view + off_mask
    if outside > threshold:
        count = int(np.count_nonzero(unseen & ~(in_view & in_mask)))
        low, high = np.round(parts.low, 3).tolist(), np.round(parts.high, 3).tolist()
        warnings.warn(
            f"{100 * outside:.0f} % of the body ({count} of {len(weight)} constraint points) "
            f"lies outside the images in frame 0: {100 * off_view:.0f} % outside the field of "
            f"view (x, y, z from {low} to {high} mm) and {100 * off_mask:.0f} % outside every "
            "tag's mask. No tag pulls that part, so its motion comes from the mechanics alone "
            "and biases the tracked motion of the imaged part next to it (cells there have "
            "observed_directions 0). Crop the mesh to the imaged region, or image (or "
            "resample onto) a larger field of view",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    on_background = float(weight[parts.background].sum())
    if on_background > background:
        warnings.warn(
            f"{100 * on_background:.0f} % of the body ({int(np.count_nonzero(parts.background))}"
            f" of {len(weight)} constraint points) lies on image background in frame 0: inside "
            "the field of view and masks, but no tag has tissue signal there (harmonic "
            "magnitude below its floor). No tag pulls that part, so its motion and strain "
            "come from the mechanics alone and bias the tissue's next to it (cells there have "
            "observed_directions 0; attrs['background_fraction']). Fit the mesh to the "
            "tissue (check its position and units against the magnitude images)",
            HarpxWarning,
            stacklevel=user_stacklevel(),
        )
    return outside
