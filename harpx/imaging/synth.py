r"""Synthetic SPAMM / CSPAMM tagged cine images from a known motion (``tagged/1``).

Image formation. With :math:`X` the reference position (the
configuration at ``times[0]``) and :math:`x = X + u(X, t)`, the signal of tag :math:`j` at a
spatial sample :math:`x` is :math:`\rho(X)\, m_j(X, t)` evaluated at
:math:`X = \chi_t^{-1}(x)` (Eulerian resampling of the material pattern), with
:math:`E = e^{-t/T_1}`, :math:`\theta_j = 2\pi f_j\, d_j \cdot X` and tagging pulses of angle
:math:`\beta` (``M0 = 1``):

.. math::

    m^{\mathrm{CSPAMM}} = 2\sin^2\!\beta\, E \cos\theta_j, \qquad
    m^{\mathrm{SPAMM}} = (\cos^2\!\beta + \sin^2\!\beta\cos\theta_j)\, E + (1 - E).

Acquisition effects, in this order:

1. **partial volume and slice profile**: the signal is averaged over ``oversample`` sub-samples
   per in-plane axis of each voxel and over a boxcar of ``slice_thickness`` along the tag's
   ``slice_axis`` (sub-sampled at the same density);
2. **finite resolution**: each slice's centred k-space is cropped to ``kspace_fraction`` of
   its extent along both in-plane axes;
3. **noise** with :math:`\sigma = S_{peak}/\mathrm{SNR}`, :math:`S_{peak}` the noise-free
   signal of a voxel full of tissue on a tag crest at :math:`t = 0` (``2 sin²β`` for CSPAMM,
   1 for SPAMM): real Gaussian on the CSPAMM difference, complex Gaussian then modulus
   (Rician) for SPAMM.

The inverse motion :math:`\chi_t^{-1}` comes from ``inverse`` when given, otherwise from the
vectorised fixed point :math:`X \leftarrow x - u(X, t)` (warm-started from the previous
frame) with a Newton polish for points where it stalls; a :class:`~harpx.errors.ConvergenceError`
says when the motion cannot be inverted (e.g. it folds).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Literal, Required, TypedDict

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from harpx.errors import ConvergenceError
from harpx.imaging.fft import fft2, ifft2
from harpx.imaging.stacks import tagged_dataset
from harpx.schema import AXES, GRID_DIMS

__all__ = [
    "AcquisitionOptions",
    "gridded_displacement",
    "invert_motion",
    "synthesize_tagged",
    "voxel_density",
]

Motion = Callable[[NDArray[np.float64], float], NDArray[np.float64]]
Density = Callable[[NDArray[np.float64]], NDArray[np.float64]]


class AcquisitionOptions(TypedDict, total=False):
    """Keyword arguments of :func:`synthesize_tagged` that the stacks of one protocol share.

    A protocol of several stacks (e.g. short-axis slices with x, y tags and long-axis slices
    with a z tag) images each stack with its own geometry but the same timing, contrast
    and noise: collect those in one ``AcquisitionOptions`` and pass it to every call as
    ``**options``. The keys, their units and defaults are those of
    :func:`synthesize_tagged`; only ``times`` is required.
    """

    times: Required[ArrayLike]
    tag_period: float | Sequence[float]
    sequence: Literal["SPAMM", "CSPAMM"]
    snr: float | None
    t1: float
    flip_angle: float | None
    body: Density | None
    inverse: Motion | None
    oversample: int
    kspace_fraction: float
    rng: np.random.Generator | int | None


#: Points processed per block (bounds memory: ~ 30 doubles per point are alive at once).
BLOCK_POINTS = 1 << 20


# --------------------------------------------------------------------------------------------
# motion helpers
# --------------------------------------------------------------------------------------------
def _jacobian_inverse(
    displacement: Motion, X: NDArray[np.float64], t: float, h: float
) -> NDArray[np.float64]:
    """Inverse of ``I + grad u`` at ``X`` by forward differences; identity where singular."""
    base = displacement(X, t)
    jac = np.empty((X.shape[0], 3, 3))
    for k in range(3):
        shifted = X.copy()
        shifted[:, k] += h
        jac[:, :, k] = (displacement(shifted, t) - base) / h
        jac[:, k, k] += 1.0
    det = np.linalg.det(jac)
    singular = ~(np.abs(det) > 1e-8)
    jac[singular] = np.eye(3)
    return np.linalg.inv(jac)  # type: ignore[return-value]  # numpy stub: float64 in, out


def invert_motion(
    displacement: Motion,
    x: ArrayLike,
    t: float,
    *,
    start: ArrayLike | None = None,
    tol: float = 1e-9,
    max_iter: int = 100,
) -> NDArray[np.float64]:
    r"""Reference positions :math:`X` with :math:`X + u(X, t) = x` (vectorised over points).

    Parameters
    ----------
    displacement : callable
        ``u(X, t)``: Lagrangian displacement in mm of points ``X`` (n, 3) mm at time ``t`` ms.
    x : array_like, shape (n, 3)
        Spatial positions in mm, columns (x, y, z).
    t : float
        Time in ms.
    start : array_like, shape (n, 3), optional
        Initial guess (default ``x``), e.g. the solution of the previous frame.
    tol : float, default 1e-9
        Convergence tolerance on :math:`|X + u(X) - x|_\infty` per point, mm.
    max_iter : int, default 100
        Maximum number of iterations.

    Returns
    -------
    ndarray, shape (n, 3)
        :math:`X = \chi_t^{-1}(x)` in mm.

    Raises
    ------
    ConvergenceError
        If some points do not converge (the motion folds, or is too large for the
        iteration); ``history`` holds the largest residual of every iteration.

    Notes
    -----
    Fixed-point iteration :math:`X \leftarrow x - u(X, t) = X - r` started at ``start``
    (or :math:`X = x`). It contracts with rate :math:`|\nabla u|`; when the residual falls by
    less than 4× per step the update is preconditioned with :math:`(I + \nabla u)^{-1}`
    (forward differences, refreshed whenever progress slows again), which turns it into a
    chord/Newton iteration. Only points not yet converged are iterated.

    Examples
    --------
    >>> from harpx.imaging.synth import invert_motion
    >>> shift = lambda X, t: np.full_like(X, 0.5 * np.sin(X[:, :1]))
    >>> x = np.array([[1.0, 2.0, 3.0]])
    >>> X = invert_motion(shift, x, 0.0)
    >>> bool(np.allclose(X + shift(X, 0.0), x, atol=1e-9))
    True
    """
    x = np.asarray(x, dtype=np.float64)
    X = x.copy() if start is None else np.array(start, dtype=np.float64)
    h = 1e-7 * max(1.0, float(np.max(np.abs(x)))) if x.size else 1e-7
    history: list[float] = []
    # compact working set: points still iterating, written back to X as they converge
    index = np.arange(x.shape[0])
    Xa, xa = X.copy(), x
    precond: NDArray[np.float64] | None = None
    previous = np.inf
    for _ in range(max_iter):
        if index.size == 0:
            return X
        r = Xa + displacement(Xa, t) - xa
        err2 = np.einsum("ij,ij->i", r, r)
        worst = float(np.sqrt(err2.max()))
        history.append(worst)
        done = err2 < tol * tol
        if done.any():
            X[index[done]] = Xa[done]
            keep = ~done
            index, Xa, xa, r = index[keep], Xa[keep], xa[keep], r[keep]
            if precond is not None:
                precond = precond[keep]
            if index.size == 0:
                return X
        if worst > 0.25 * previous:  # slow contraction: (re)build the preconditioner here
            precond = _jacobian_inverse(displacement, Xa, t, h)
        previous = worst
        Xa -= r if precond is None else np.einsum("nij,nj->ni", precond, r)
    X[index] = Xa
    raise ConvergenceError(
        f"inverting the motion at t={t!r} ms failed for {index.size} of {x.shape[0]} points "
        f"after {max_iter} iterations (max |X + u(X) - x| = {history[-1]:.3g} mm > "
        f"tol={tol:g} mm); the motion may fold (det(I + grad u) <= 0) or be too large for "
        "the iteration; pass inverse=callable(x, t) with the exact inverse",
        history,
    )


def gridded_displacement(field: xr.DataArray) -> Motion:
    """Turn a gridded displacement (time, axis, z, y, x) into a callable ``u(X, t)``.

    Trilinear in space (constant beyond the grid) and linear in time (constant beyond the
    first and last frame). NaNs (outside the body) are filled from the nearest finite voxel.

    Parameters
    ----------
    field : xarray.DataArray
        Dims (time, axis, z, y, x) with coords ``time`` (ms), ``axis`` (x, y, z) and evenly
        spaced ``z``, ``y``, ``x`` (mm); values in mm.

    Returns
    -------
    callable
        ``u(X, t)`` for points ``X`` (n, 3) in mm, returning (n, 3) mm.
    """
    dims = ("time", "axis", *GRID_DIMS)
    if set(field.dims) != set(dims):
        raise ValueError(f"gridded displacement needs dims {dims!r}, got {field.dims!r}")
    field = field.transpose(*dims).sel(axis=list(AXES))
    data = np.asarray(field.values, dtype=np.float64)
    bad = ~np.isfinite(data)
    if bad.any():
        for n in range(data.shape[0]):
            for a in range(3):
                values = data[n, a]
                missing = ~np.isfinite(values)
                if missing.all():
                    values[...] = 0.0
                elif missing.any():
                    idx = ndimage.distance_transform_edt(
                        missing, return_distances=False, return_indices=True
                    )
                    values[...] = values[tuple(idx)]
    times = np.asarray(field["time"].values, dtype=np.float64)
    origin = np.array([float(field[d].values[0]) for d in GRID_DIMS])
    step = np.array(
        [float(np.diff(field[d].values).mean()) if field.sizes[d] > 1 else 1.0 for d in GRID_DIMS]
    )

    def u(X: NDArray[np.float64], t: float) -> NDArray[np.float64]:
        X = np.asarray(X, dtype=np.float64)
        index = ((X[:, [2, 1, 0]] - origin) / step).T
        if times.size == 1:
            frames, weights = [0], [1.0]
        else:
            k = int(np.clip(np.searchsorted(times, t) - 1, 0, times.size - 2))
            w = float(np.clip((t - times[k]) / (times[k + 1] - times[k]), 0.0, 1.0))
            frames, weights = [k, k + 1], [1.0 - w, w]
        out = np.zeros((X.shape[0], 3))
        for n, w in zip(frames, weights, strict=True):
            if w == 0.0:
                continue
            for a in range(3):
                out[:, a] += w * ndimage.map_coordinates(data[n, a], index, order=1, mode="nearest")
        return out

    return u


# --------------------------------------------------------------------------------------------
# parsing of the tag set
# --------------------------------------------------------------------------------------------
def _parse_tags(
    tags: Sequence[str | Sequence[float]],
    tag_period: float | Sequence[float],
    slice_axis: str | Sequence[str] | None,
) -> tuple[list[str], NDArray[np.float64], NDArray[np.float64], list[str]]:
    if isinstance(tags, str):
        tags = [tags]
    labels: list[str] = []
    directions = []
    for i, tag in enumerate(tags):
        if isinstance(tag, str):
            if tag not in AXES:
                raise ValueError(f"tag {tag!r} is not one of {list(AXES)!r} or a 3-vector")
            labels.append(tag)
            directions.append(np.eye(3)[AXES.index(tag)])
        else:
            d = np.asarray(tag, dtype=np.float64)
            norm = float(np.linalg.norm(d)) if d.shape == (3,) else 0.0
            if not norm > 0:
                raise ValueError(f"tag direction {tag!r} must be a non-zero 3-vector (x, y, z)")
            labels.append(f"tag{i}")
            directions.append(d / norm)
    if not 1 <= len(labels) <= 3 or len(set(labels)) != len(labels):
        raise ValueError(f"'tags' must hold 1 to 3 distinct tags, got {tags!r}")
    direction = np.array(directions)
    period = np.broadcast_to(np.asarray(tag_period, dtype=np.float64), (len(labels),)).copy()
    if not np.all(period > 0):
        raise ValueError(f"'tag_period' must be positive (mm), got {tag_period!r}")
    if slice_axis is None:
        axes = []
        for d in direction:
            # the axis most orthogonal to the tag; ties prefer z, then y (x, y tags -> z; z -> y)
            order = sorted(range(3), key=lambda a: (round(abs(d[a]), 12), -a))
            axes.append(AXES[order[0]])
    elif isinstance(slice_axis, str):
        axes = [slice_axis] * len(labels)
    else:
        axes = [str(s) for s in slice_axis]
    if len(axes) != len(labels) or any(s not in AXES for s in axes):
        raise ValueError(
            f"'slice_axis' must be None, one of {list(AXES)!r} or one per tag, got {slice_axis!r}"
        )
    for label, d, s in zip(labels, direction, axes, strict=True):
        if abs(d[AXES.index(s)]) > 0.5:
            raise ValueError(
                f"tag {label!r} (direction {np.round(d, 3).tolist()}) lies mostly along its "
                f"slice_axis {s!r}; choose a slice_axis normal to the tag direction"
            )
    return labels, direction, 1.0 / period, axes


# --------------------------------------------------------------------------------------------
# sampling lattices
# --------------------------------------------------------------------------------------------
def _offsets(n: int, width: float) -> NDArray[np.float64]:
    """Centres of ``n`` equal sub-intervals of a boxcar of ``width`` centred on 0."""
    return width * ((np.arange(n) + 0.5) / n - 0.5)


def _lattice_blocks(
    centres: Sequence[NDArray[np.float64]], offsets: Sequence[NDArray[np.float64]]
) -> list[tuple[slice, NDArray[np.float64]]]:
    """Split the sample lattice into z slabs: (voxel slice along z, points (n, 3) x-y-z).

    Points are ordered (sub-z, sub-y, sub-x, z, y, x) so that a voxel average is a mean over
    the leading axis of contiguous rows (:func:`_voxel_mean`).
    """
    cz, cy, cx = centres
    oz, oy, ox = offsets
    per_z = len(oz) * cy.size * len(oy) * cx.size * len(ox)
    bz = max(1, BLOCK_POINTS // max(per_z, 1))
    py = (oy[:, None] + cy[None, :])[None, :, None, None, :, None]
    px = (ox[:, None] + cx[None, :])[None, None, :, None, None, :]
    blocks = []
    for z0 in range(0, cz.size, bz):
        zs = slice(z0, min(cz.size, z0 + bz))
        pz = (oz[:, None] + cz[None, zs])[:, None, None, :, None, None]
        shape = np.broadcast_shapes(pz.shape, py.shape, px.shape)
        pts = np.empty((*shape, 3))
        pts[..., 0] = px
        pts[..., 1] = py
        pts[..., 2] = pz
        blocks.append((zs, pts.reshape(-1, 3)))
    return blocks


def _voxel_mean(values: NDArray[np.float64], nvox_z: int, centres, offsets) -> NDArray:
    _, cy, cx = centres
    nsub = int(np.prod([len(o) for o in offsets]))
    return values.reshape(nsub, -1).mean(axis=0).reshape(nvox_z, cy.size, cx.size)


def voxel_density(
    body: Density,
    centres: Sequence[ArrayLike],
    spacing: ArrayLike,
    *,
    oversample: int = 3,
) -> NDArray[np.float64]:
    """Voxel-averaged density of a body on a grid (partial volume).

    Parameters
    ----------
    body : callable
        Density ``ρ(X)`` in [0, 1] of points (n, 3) mm, columns (x, y, z).
    centres : sequence of 3 array_like
        Voxel-centre coordinates ``(z, y, x)``, mm.
    spacing : array_like, shape (3,)
        Voxel size ``(dz, dy, dx)``, mm.
    oversample : int, default 3
        Sub-samples per voxel and axis (``oversample**3`` per voxel), at the centres of equal
        sub-intervals.

    Returns
    -------
    ndarray, shape (nz, ny, nx)
        Mean density over each voxel (dimensionless).

    Examples
    --------
    >>> from harpx.imaging.synth import voxel_density
    >>> half = lambda X: (X[:, 0] < 0.0).astype(float)  # the half space x < 0
    >>> voxel_density(half, ([0.0], [0.0], [-1.0, 0.0, 1.0]), (1, 1, 1), oversample=2)[0, 0]
    array([1. , 0.5, 0. ])
    """
    axes = [np.asarray(c, dtype=np.float64).ravel() for c in centres]
    step = np.asarray(spacing, dtype=np.float64)
    offsets = [_offsets(int(oversample), step[k]) for k in range(3)]
    out = np.empty(tuple(a.size for a in axes))
    for zs, pts in _lattice_blocks(axes, offsets):
        rho = np.clip(np.asarray(body(pts), dtype=np.float64), 0.0, 1.0)
        out[zs] = _voxel_mean(rho, zs.stop - zs.start, axes, offsets)
    return out


def _crop_kspace(volume: NDArray[np.float64], plane: tuple[int, int], fraction: float) -> NDArray:
    """Keep the centred ``fraction`` of each slice's k-space along both in-plane axes."""
    moved = np.moveaxis(volume, plane, (-2, -1))
    spec = fft2(moved)
    for axis in (-2, -1):
        n = moved.shape[axis]
        keep = np.abs(np.fft.fftfreq(n)) <= 0.5 * fraction + 1e-12
        shape = [1] * spec.ndim
        shape[axis] = n
        spec *= keep.reshape(shape)
    return np.moveaxis(ifft2(spec).real, (-2, -1), plane)


# --------------------------------------------------------------------------------------------
# the synthesiser
# --------------------------------------------------------------------------------------------
def synthesize_tagged(
    displacement: Motion | xr.DataArray,
    *,
    shape: Sequence[int],
    spacing: Sequence[float],
    times: ArrayLike,
    origin: Sequence[float] | None = None,
    tag_period: float | Sequence[float] = 8.0,
    tags: Sequence[str | Sequence[float]] = ("x", "y", "z"),
    slice_axis: str | Sequence[str] | None = None,
    sequence: Literal["SPAMM", "CSPAMM"] = "CSPAMM",
    snr: float | None = 20.0,
    t1: float = 850.0,
    flip_angle: float | None = None,
    body: Density | None = None,
    inverse: Motion | None = None,
    oversample: int = 3,
    slice_thickness: float | None = None,
    kspace_fraction: float = 1.0,
    rng: np.random.Generator | int | None = None,
) -> xr.Dataset:
    r"""Synthetic tagged cine volumes of a known motion (``tagged/1``).

    Parameters
    ----------
    displacement : callable or xarray.DataArray
        Lagrangian displacement ``u(X, t)`` in mm for reference points ``X`` (n, 3) mm,
        columns (x, y, z), at time ``t`` ms; or a gridded field (time, axis, z, y, x)
        interpolated linearly (:func:`gridded_displacement`). ``u(X, times[0])`` must be 0.
    shape : (int, int, int)
        Grid size ``(nz, ny, nx)``.
    spacing : (float, float, float)
        Voxel spacing ``(dz, dy, dx)`` in mm.
    times : array_like of float
        Frame times in ms after tagging (>= 0, increasing); ``times[0]`` is the reference.
    origin : (float, float, float), optional
        Centre of voxel (0, 0, 0) as ``(z0, y0, x0)`` in mm; default centres the grid on 0.
    tag_period : float or sequence of float, default 8.0
        Tag spacing in mm (one value, or one per tag).
    tags : sequence, default ("x", "y", "z")
        Tag directions: axis names or explicit 3-vectors (x, y, z), normalised (labels
        ``"tag0"``, ...).
    slice_axis : str or sequence of str, optional
        Axis normal to each tag's acquisition slices; default ``"z"`` for x and y tags,
        ``"y"`` for z tags (generally the axis most orthogonal to the tag).
    sequence : {"SPAMM", "CSPAMM"}, default "CSPAMM"
        Tagging sequence (signal model in the module notes).
    snr : float or None, default 20
        Signal-to-noise ratio ``S_peak / σ`` (dimensionless); None for noise-free images.
    t1 : float, default 850
        Longitudinal relaxation time T1 in ms (tag fading).
    flip_angle : float, optional
        Angle β of each of the two tagging pulses, degrees. Default 45° for SPAMM (a 1-1
        SPAMM of 90° in total: full modulation with a non-negative magnitude pattern) and
        90° for CSPAMM.
    body : callable, optional
        Density ``ρ(X)`` in [0, 1] of reference points (n, 3) mm; default 1 everywhere.
    inverse : callable, optional
        Exact inverse motion ``X = inverse(x, t)`` (n, 3) mm; default: numerical inversion
        (:func:`invert_motion`).
    oversample : int, default 3
        Sub-samples per voxel and axis for partial volume (dimensionless, >= 1).
    slice_thickness : float, optional
        Boxcar slice profile thickness in mm along each tag's ``slice_axis``; default its
        spacing (contiguous slices).
    kspace_fraction : float, default 1.0
        Fraction of each slice's centred k-space kept per in-plane axis (in (0, 1]).
    rng : numpy.random.Generator or int, optional
        Noise generator or seed.

    Returns
    -------
    xarray.Dataset
        ``tagged/1`` with ``image`` (tag, time, z, y, x), ``mask`` (tag, z, y, x) True
        everywhere (each voxel of the grid is a sample of the acquisition: the grid is its
        field of view and slab; the mask is not the tissue), ``body`` (z, y, x)
        voxel-averaged density at the reference frame (the tissue's support),
        ``displacement_true`` (time, axis, z, y, x) = ``u`` at the voxel centres (NaN where
        ``body < 0.5``), tag coords, and attrs ``sequence``,
        ``noise_sigma``, ``t1``, ``flip_angle``, ``oversample``, ``kspace_fraction``.

    Raises
    ------
    ValueError
        On inconsistent arguments (each message names the argument).
    ConvergenceError
        If the motion cannot be inverted numerically.

    Examples
    --------
    >>> from harpx.imaging.synth import synthesize_tagged
    >>> ds = synthesize_tagged(lambda X, t: 0 * X, shape=(2, 8, 8), spacing=(2, 2, 2),
    ...                        times=[0.0], tags=("x",), snr=None, oversample=1)
    >>> ds.image.dims, ds.attrs["harpx_schema"]
    (('tag', 'time', 'z', 'y', 'x'), 'tagged/1')
    """
    shape = tuple(int(n) for n in shape)
    spacing_arr = np.asarray(spacing, dtype=np.float64)
    if len(shape) != 3 or min(shape) < 1:
        raise ValueError(f"'shape' must be 3 positive sizes (nz, ny, nx), got {shape!r}")
    if spacing_arr.shape != (3,) or not np.all(spacing_arr > 0):
        raise ValueError(f"'spacing' must be 3 positive spacings (dz, dy, dx) mm, got {spacing!r}")
    times_arr = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if times_arr.ndim != 1 or times_arr.size == 0 or not np.all(np.isfinite(times_arr)):
        raise ValueError(f"'times' must be a non-empty 1D array of ms, got {times!r}")
    if times_arr[0] < 0 or np.any(np.diff(times_arr) <= 0):
        raise ValueError(f"'times' must be >= 0 ms after tagging and increasing, got {times!r}")
    if sequence not in ("SPAMM", "CSPAMM"):
        raise ValueError(f"'sequence' must be 'SPAMM' or 'CSPAMM', got {sequence!r}")
    if snr is not None and not snr > 0:
        raise ValueError(f"'snr' must be positive or None, got {snr!r}")
    if not t1 > 0:
        raise ValueError(f"'t1' must be positive (ms), got {t1!r}")
    if (
        isinstance(oversample, bool)
        or not isinstance(oversample, int | np.integer)
        or oversample < 1
    ):
        raise ValueError(f"'oversample' must be an integer >= 1, got {oversample!r}")
    if not 0.0 < kspace_fraction <= 1.0:
        raise ValueError(f"'kspace_fraction' must be in (0, 1], got {kspace_fraction!r}")
    if slice_thickness is not None and not slice_thickness > 0:
        raise ValueError(
            f"'slice_thickness' must be positive (mm) or None, got {slice_thickness!r}"
        )
    beta_deg = (45.0 if sequence == "SPAMM" else 90.0) if flip_angle is None else float(flip_angle)
    beta = np.deg2rad(beta_deg)
    labels, direction, frequency, slice_axes = _parse_tags(tags, tag_period, slice_axis)
    if isinstance(displacement, xr.DataArray):
        u = gridded_displacement(displacement)
    elif callable(displacement):
        u = displacement
    else:
        raise ValueError(
            f"'displacement' must be a callable u(X, t) or a DataArray, got {type(displacement)!r}"
        )
    rng = np.random.default_rng(rng)

    nz, ny, nx = shape
    if origin is None:
        origin_arr = -0.5 * (np.asarray(shape) - 1) * spacing_arr
    else:
        origin_arr = np.asarray(origin, dtype=np.float64)
        if origin_arr.shape != (3,):
            raise ValueError(f"'origin' must be (z0, y0, x0) in mm, got {origin!r}")
    centres = [origin_arr[k] + spacing_arr[k] * np.arange(shape[k]) for k in range(3)]

    def density(X: NDArray[np.float64]) -> NDArray[np.float64]:
        if body is None:
            return np.ones(X.shape[0])
        return np.clip(np.asarray(body(X), dtype=np.float64), 0.0, 1.0)

    # reference frame: body density (voxel averaged) and truth at the voxel centres
    iso = [_offsets(oversample, spacing_arr[k]) for k in range(3)]
    body_img = voxel_density(density, centres, spacing_arr, oversample=oversample)
    inside = body_img >= 0.5
    voxel_pts = _lattice_blocks(centres, [np.zeros(1)] * 3)
    u0 = np.concatenate([np.asarray(u(p, float(times_arr[0]))) for _, p in voxel_pts])
    if np.max(np.abs(u0)) > 1e-6:
        raise ValueError(
            f"the displacement at the reference frame times[0]={times_arr[0]!r} ms is not zero "
            f"(max |u| = {np.max(np.abs(u0)):.3g} mm); express u relative to the configuration "
            "at times[0]"
        )

    # one sampling lattice per distinct slice profile; tags sharing it share the inversion
    lattices: dict[tuple, list[int]] = {}
    offsets_of: dict[tuple, list[NDArray[np.float64]]] = {}
    for j, s in enumerate(slice_axes):
        offs = []
        for k, dim in enumerate(GRID_DIMS):
            if dim == s and slice_thickness is not None:
                nsub = max(oversample, int(np.ceil(oversample * slice_thickness / spacing_arr[k])))
                offs.append(_offsets(nsub, slice_thickness))
            else:
                offs.append(iso[k])
        key = tuple(tuple(np.round(o, 12)) for o in offs)
        lattices.setdefault(key, []).append(j)
        offsets_of[key] = offs

    fade = np.exp(-times_arr / t1)
    image = np.empty((len(labels), times_arr.size, *shape))
    truth = np.empty((times_arr.size, 3, *shape))
    wave = 2.0 * np.pi * frequency[:, None] * direction  # rad/mm, (tag, xyz)
    for key, members in lattices.items():
        offs = offsets_of[key]
        blocks = _lattice_blocks(centres, offs)
        previous: list[NDArray[np.float64] | None] = [None] * len(blocks)
        for n, t in enumerate(times_arr):
            for b, (zs, x) in enumerate(blocks):
                if n == 0:
                    X = x
                elif inverse is not None:
                    X = np.asarray(inverse(x, float(t)), dtype=np.float64)
                else:
                    X = invert_motion(u, x, float(t), start=previous[b])
                previous[b] = X
                rho = density(X)
                for j in members:
                    theta = X @ wave[j]
                    if sequence == "CSPAMM":
                        signal = rho * (2.0 * np.sin(beta) ** 2 * fade[n]) * np.cos(theta)
                    else:
                        tagged = np.cos(beta) ** 2 + np.sin(beta) ** 2 * np.cos(theta)
                        signal = rho * (tagged * fade[n] + (1.0 - fade[n]))
                    image[j, n, zs] = _voxel_mean(signal, zs.stop - zs.start, centres, offs)

    for n, t in enumerate(times_arr):
        u_vox = np.concatenate([np.asarray(u(p, float(t))) for _, p in voxel_pts])
        truth[n] = u_vox.T.reshape(3, *shape)
    truth[:, :, ~inside] = np.nan

    if kspace_fraction < 1.0:
        for j, s in enumerate(slice_axes):
            first, second = (1 + k for k, d in enumerate(GRID_DIMS) if d != s)
            image[j] = _crop_kspace(image[j], (first, second), kspace_fraction)

    peak = 2.0 * np.sin(beta) ** 2 if sequence == "CSPAMM" else 1.0
    sigma = 0.0 if snr is None else peak / float(snr)
    if sigma > 0:
        if sequence == "CSPAMM":
            image += sigma * rng.standard_normal(image.shape)
        else:
            noise = rng.standard_normal((2, *image.shape))
            image = np.hypot(image + sigma * noise[0], sigma * noise[1])
    elif sequence == "SPAMM":
        image = np.abs(image)

    attrs: dict[str, Any] = {
        "noise_sigma": float(sigma),
        "t1": float(t1),
        "flip_angle": beta_deg,
        "oversample": int(oversample),
        "kspace_fraction": float(kspace_fraction),
    }
    if snr is not None:
        attrs["snr"] = float(snr)
    if slice_thickness is not None:
        attrs["slice_thickness"] = float(slice_thickness)
    # every voxel of the grid is a sample of the acquisition: the mask (field of view and
    # slab) is the whole grid; the tissue is `body`
    return tagged_dataset(
        image,
        tag=labels,
        tag_direction=direction,
        tag_frequency=frequency,
        slice_axis=slice_axes,
        time=times_arr,
        z=centres[0],
        y=centres[1],
        x=centres[2],
        sequence=sequence,
        mask=np.ones(shape, dtype=bool),
        body=body_img,
        displacement_true=truth,
        attrs=attrs,
    )
