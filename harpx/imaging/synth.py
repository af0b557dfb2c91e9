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

The inverse motion :math:`\chi_t^{-1}` comes from ``inverse`` when given, otherwise from
:func:`harpx.imaging.motion.invert_motion`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Literal, Required, TypedDict

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike, NDArray

from harpx.imaging.fft import fft2, ifft2
from harpx.imaging.motion import Motion, gridded_displacement, invert_motion
from harpx.imaging.stacks import tagged_dataset
from harpx.schema import AXES, GRID_DIMS

# invert_motion and gridded_displacement stay importable from here (their home is motion)
__all__ = ["AcquisitionOptions", "synthesize_tagged", "voxel_density"]

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
def _checked_acquisition(
    shape: Sequence[int],
    spacing: Sequence[float],
    times: ArrayLike,
    sequence: str,
    snr: float | None,
    t1: float,
    oversample: int,
    kspace_fraction: float,
    slice_thickness: float | None,
) -> tuple[tuple[int, int, int], NDArray[np.float64], NDArray[np.float64]]:
    """The grid size, spacing (mm) and frame times (ms) of :func:`synthesize_tagged`, each
    option checked (a ``ValueError`` names the one that is wrong)."""
    grid = tuple(int(n) for n in shape)
    spacing_arr = np.asarray(spacing, dtype=np.float64)
    if len(grid) != 3 or min(grid) < 1:
        raise ValueError(f"'shape' must be 3 positive sizes (nz, ny, nx), got {grid!r}")
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
    return (grid[0], grid[1], grid[2]), spacing_arr, times_arr


def _voxel_centres(
    shape: tuple[int, int, int], spacing: NDArray[np.float64], origin: Sequence[float] | None
) -> list[NDArray[np.float64]]:
    """Voxel centres along z, y, x (mm); ``origin`` is voxel (0, 0, 0), default the grid
    centred on 0."""
    if origin is None:
        origin_arr = -0.5 * (np.asarray(shape) - 1) * spacing
    else:
        origin_arr = np.asarray(origin, dtype=np.float64)
        if origin_arr.shape != (3,):
            raise ValueError(f"'origin' must be (z0, y0, x0) in mm, got {origin!r}")
    return [origin_arr[k] + spacing[k] * np.arange(shape[k]) for k in range(3)]


def _slice_lattices(
    slice_axes: Sequence[str],
    slice_thickness: float | None,
    spacing: NDArray[np.float64],
    oversample: int,
) -> dict[tuple[Any, ...], tuple[list[NDArray[np.float64]], list[int]]]:
    """One sampling lattice per distinct slice profile: its sub-sample offsets along z, y, x
    (``oversample`` per voxel; across a slice of ``slice_thickness`` as many as cover it at
    that density) and the tags that share it, and so share the motion's inversion."""
    iso = [_offsets(oversample, spacing[k]) for k in range(3)]
    lattices: dict[tuple[Any, ...], tuple[list[NDArray[np.float64]], list[int]]] = {}
    for j, s in enumerate(slice_axes):
        offs = []
        for k, dim in enumerate(GRID_DIMS):
            if dim == s and slice_thickness is not None:
                nsub = max(oversample, int(np.ceil(oversample * slice_thickness / spacing[k])))
                offs.append(_offsets(nsub, slice_thickness))
            else:
                offs.append(iso[k])
        key = tuple(tuple(np.round(o, 12)) for o in offs)
        lattices.setdefault(key, (offs, []))[1].append(j)
    return lattices


def _tag_signal(
    rho: NDArray[np.float64], theta: NDArray[np.float64], sequence: str, beta: float, fade: float
) -> NDArray[np.float64]:
    """Tagged signal of tissue density ``rho`` at tag phase ``theta`` (rad) with tag fading
    ``fade`` = exp(-t/T1): ``rho * m`` of the module notes."""
    if sequence == "CSPAMM":
        signal: NDArray[np.float64] = rho * (2.0 * np.sin(beta) ** 2 * fade) * np.cos(theta)
        return signal
    tagged = np.cos(beta) ** 2 + np.sin(beta) ** 2 * np.cos(theta)
    spamm: NDArray[np.float64] = rho * (tagged * fade + (1.0 - fade))
    return spamm


def _with_noise(
    image: NDArray[np.float64], sequence: str, sigma: float, rng: np.random.Generator
) -> NDArray[np.float64]:
    """Images with the noise of the module notes (step 3), standard deviation ``sigma``; a
    noise-free SPAMM image is its modulus."""
    if sigma > 0:
        if sequence == "CSPAMM":
            noisy: NDArray[np.float64] = image + sigma * rng.standard_normal(image.shape)
            return noisy
        noise = rng.standard_normal((2, *image.shape))
        return np.hypot(image + sigma * noise[0], sigma * noise[1])
    return np.abs(image) if sequence == "SPAMM" else image


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
    shape, spacing_arr, times_arr = _checked_acquisition(
        shape, spacing, times, sequence, snr, t1, oversample, kspace_fraction, slice_thickness
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
    centres = _voxel_centres(shape, spacing_arr, origin)

    def density(X: NDArray[np.float64]) -> NDArray[np.float64]:
        if body is None:
            return np.ones(X.shape[0])
        return np.clip(np.asarray(body(X), dtype=np.float64), 0.0, 1.0)

    # reference frame: body density (voxel averaged) and truth at the voxel centres
    body_img = voxel_density(density, centres, spacing_arr, oversample=oversample)
    voxel_pts = _lattice_blocks(centres, [np.zeros(1)] * 3)
    u0 = np.concatenate([np.asarray(u(p, float(times_arr[0]))) for _, p in voxel_pts])
    if np.max(np.abs(u0)) > 1e-6:
        raise ValueError(
            f"the displacement at the reference frame times[0]={times_arr[0]!r} ms is not zero "
            f"(max |u| = {np.max(np.abs(u0)):.3g} mm); express u relative to the configuration "
            "at times[0]"
        )

    # 1. partial volume and slice profile: the signal at each lattice's sub-samples, taken
    # back to the reference configuration, averaged per voxel
    fade = np.exp(-times_arr / t1)
    image = np.empty((len(labels), times_arr.size, *shape))
    wave = 2.0 * np.pi * frequency[:, None] * direction  # rad/mm, (tag, xyz)
    for offs, members in _slice_lattices(
        slice_axes, slice_thickness, spacing_arr, oversample
    ).values():
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
                    signal = _tag_signal(rho, X @ wave[j], sequence, beta, float(fade[n]))
                    image[j, n, zs] = _voxel_mean(signal, zs.stop - zs.start, centres, offs)

    truth = np.empty((times_arr.size, 3, *shape))
    for n, t in enumerate(times_arr):
        u_vox = np.concatenate([np.asarray(u(p, float(t))) for _, p in voxel_pts])
        truth[n] = u_vox.T.reshape(3, *shape)
    truth[:, :, body_img < 0.5] = np.nan

    # 2. finite resolution, 3. noise
    if kspace_fraction < 1.0:
        for j, s in enumerate(slice_axes):
            first, second = (1 + k for k, d in enumerate(GRID_DIMS) if d != s)
            image[j] = _crop_kspace(image[j], (first, second), kspace_fraction)
    peak = 2.0 * np.sin(beta) ** 2 if sequence == "CSPAMM" else 1.0
    sigma = 0.0 if snr is None else peak / float(snr)
    image = _with_noise(image, sequence, sigma, rng)

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
