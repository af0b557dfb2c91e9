r"""The image noise behind a phase dataset, for :mod:`harpx.tracking.uncertainty`.

The image noise is taken as white within each acquired slice and independent between
frames and tags; across the planes of the grid normal to a tag's slices it is correlated
when the grid was resampled from thicker slices (:mod:`harpx.imaging.stacks`). Given the
tagged images, :func:`image_noise` measures each tag's covariance between planes, level
included, from the second differences along the tag lines that :mod:`harpx.imaging.noise`
uses: with :math:`D_j` the second differences of plane :math:`j`,
:math:`\operatorname{var}(D_j \pm D_k) = 6(\sigma_j^2 + \sigma_k^2 \pm 2 C_{jk})`, each
variance from a median absolute deviation, over the pixels without tag signal (tissue edges
inflate it) when every plane has enough of them, and lags are added while their mean
correlation exceeds ``SIGNIFICANCE`` standard errors. Without the tagged images the planes
are taken as independent, at the level of the phase's ``harmonic_noise``
(:math:`\sigma = \sigma_H \sqrt{N / n_d}`, inverting :mod:`harpx.imaging.noise`), and
:func:`~harpx.tracking.uncertainty.tracking_uncertainty` warns so. Its result's
``noise_model`` attribute gives, per tag, how the noise was modelled
(:meth:`ImageNoise.describe`) and its level relative to ``harmonic_noise``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from numpy.typing import NDArray

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.imaging.noise import MAD_GAUSS, MAX_TAG_LEAK, band_share, harmonic_noise_block
from harpx.imaging.phase_parameters import PhaseParameters
from harpx.schema import AXES, GRID_DIMS, grid_step, validate
from harpx.tracking.results import acquired_grid

__all__ = ["BACKGROUND", "SIGNIFICANCE", "ImageNoise", "image_noise"]

#: Harmonic magnitude, in units of ``harmonic_noise``, below which a pixel has no tag signal.
BACKGROUND = 3.0
#: Standard errors a lag's mean correlation must exceed to count as correlated.
SIGNIFICANCE = 4.0
#: Standard error of a MAD-based correlation from n Gaussian pairs is about this / sqrt(n).
_MAD_CORRELATION_SE = 1.65
#: Fewest second differences in a plane for its own variance estimate.
_MIN_PLANE_SAMPLES = 50


@dataclass(frozen=True)
class ImageNoise:
    r"""Noise of each tag's images on their acquired grid (module notes).

    Attributes
    ----------
    z, y, x : ndarray
        Acquired voxel-centre coordinates, mm.
    slice_axis : ndarray of int, shape (ntag,)
        Grid axis (0 = z, 1 = y, 2 = x) normal to each tag's slices.
    factors : tuple of ndarray
        Per tag a matrix ``L`` (nplane, nplane) along the slice axis with ``L L^T`` the
        covariance of the image noise between planes, image units (white within a plane).
    mask : ndarray of bool, shape (ntag, nz, ny, nx)
        Where each tag's images hold data (and noise).
    estimated : ndarray of bool, shape (ntag,)
        Whether the covariance between planes was measured from tagged images (False: the
        planes were assumed independent).
    correlated_planes : ndarray of int, shape (ntag,)
        Number of neighbouring planes over which the noise is correlated (1: white).
    background : ndarray of bool, shape (ntag,)
        Whether the covariance was measured on pixels without tag signal only (else on
        every pixel of the mask, where tissue edges inflate it).
    white_level : ndarray, shape (ntag,)
        The image noise level the phase's ``harmonic_noise`` implies,
        :math:`\sigma_H \sqrt{N / n_d}`, image units (what the tracker's noise floor uses).
    """

    z: FloatArray
    y: FloatArray
    x: FloatArray
    slice_axis: IntArray
    factors: tuple[FloatArray, ...]
    mask: BoolArray
    estimated: BoolArray
    correlated_planes: IntArray
    background: BoolArray
    white_level: FloatArray

    def sample(self, rng: np.random.Generator, count: int) -> NDArray[np.float32]:
        """``count`` independent image-noise fields per tag.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the standard normal samples.
        count : int
            Fields to draw per tag.

        Returns
        -------
        ndarray of float32, shape (ntag, count, nz, ny, nx)
            Zero-mean Gaussian noise on the acquired grid, image units: white within each
            plane, covariance ``L L^T`` (:attr:`factors`) across the planes along the tag's
            slice axis, 0 outside the tag's :attr:`mask`.
        """
        shape = (self.z.size, self.y.size, self.x.size)
        out = np.empty((len(self.factors), count, *shape), dtype=np.float32)
        for t, L in enumerate(self.factors):  # ≤ 3 tags
            axis = int(self.slice_axis[t])
            plane = tuple(shape[a] for a in range(3) if a != axis)
            white = rng.standard_normal((count, shape[axis], *plane), dtype=np.float32)
            mixed = np.einsum("jk,ckab->cjab", L.astype(np.float32), white)  # across planes
            out[t] = np.moveaxis(mixed, 1, 1 + axis) * self.mask[t]
        return out

    def describe(self, tags: Sequence[str]) -> str:
        """How each tag's noise was modelled, as text for the result's attributes.

        Parameters
        ----------
        tags : sequence of str
            Tag names, one per tag in the order of :attr:`factors`.

        Returns
        -------
        str
            One entry per tag, separated by ``"; "``: the tag name, whether the covariance
            across the planes was measured (and on which pixels) or assumed independent, and
            the median plane level relative to :attr:`white_level`.
        """
        parts = []
        for t, (tag, std) in enumerate(zip(tags, self.plane_std(), strict=True)):
            axis = GRID_DIMS[int(self.slice_axis[t])]
            level = float(np.median(std[std > 0])) / self.white_level[t] if (std > 0).any() else 0
            if self.estimated[t]:
                where = "pixels without tag signal" if self.background[t] else "all pixels"
                how = (
                    f"covariance across the planes along {axis} measured on {where} "
                    f"({int(self.correlated_planes[t])} correlated plane(s))"
                )
            else:
                how = f"planes along {axis} assumed independent"
            parts.append(f"{tag}: white in-plane, {how}, median level {level:.3g} × harmonic_noise")
        return "; ".join(parts)

    def plane_std(self) -> tuple[FloatArray, ...]:
        """Noise standard deviation of every plane along each tag's slice axis.

        Returns
        -------
        tuple of ndarray
            Per tag, shape (nplane,): the square root of the diagonal of ``L L^T``, image
            units.
        """
        return tuple(np.sqrt(np.einsum("jk,jk->j", L, L)) for L in self.factors)


def _mad(values: FloatArray) -> FloatArray:
    """Median absolute deviation of each row about its median, ignoring NaN (0 if empty)."""
    out = np.zeros(values.shape[0])
    has = np.isfinite(values).any(axis=1)
    if has.any():
        rows = values[has]
        centre = np.nanmedian(rows, axis=1, keepdims=True)
        out[has] = np.nanmedian(np.abs(rows - centre), axis=1)
    return out


def _plane_covariance(planes: FloatArray, valid: BoolArray) -> tuple[FloatArray, int]:
    """Covariance (image units²) between the planes of white-in-plane noise (module notes).

    ``planes`` (nplane, n1, n2) with the tag lines along axis 1; ``valid`` (same shape)
    marks the pixels to use. Returns the covariance (nplane, nplane), zero beyond the
    correlated lags, and the number of correlated planes (1: white).
    """
    nplane = planes.shape[0]
    second = np.diff(planes, n=2, axis=1)
    ok = valid[:, :-2] & valid[:, 1:-1] & valid[:, 2:]
    D = np.where(ok, second, np.nan).reshape(nplane, -1)
    count = ok.reshape(nplane, -1).sum(axis=1)
    var = np.where(count >= _MIN_PLANE_SAMPLES, (_mad(D) / MAD_GAUSS) ** 2 / 6.0, 0.0)
    cov = np.diag(var)
    std = np.sqrt(var)
    lag = 1
    while lag < nplane:
        a, b = D[lag:], D[:-lag]
        n_pair = (np.isfinite(a) & np.isfinite(b)).sum(axis=1)
        use = (n_pair >= _MIN_PLANE_SAMPLES) & (std[lag:] > 0) & (std[:-lag] > 0)
        if not use.any():
            break
        plus = (_mad(a[use] + b[use]) / MAD_GAUSS) ** 2
        minus = (_mad(a[use] - b[use]) / MAD_GAUSS) ** 2
        c = (plus - minus) / (4.0 * 6.0)  # covariance of the image noise
        rho = c / (std[lag:][use] * std[:-lag][use])
        se = _MAD_CORRELATION_SE / np.sqrt(float(n_pair[use].sum()))
        if abs(float(rho.mean())) < SIGNIFICANCE * se:
            break
        j = np.flatnonzero(use)
        cov[j + lag, j] = cov[j, j + lag] = c
        lag += 1
    return cov, lag


def _factor(cov: FloatArray) -> FloatArray:
    """``L`` with ``L L^T`` the nearest positive semi-definite matrix to ``cov``."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    return np.asarray(v * np.sqrt(np.clip(w, 0.0, None)), dtype=np.float64)


def _tag_geometry(ds: xr.Dataset) -> tuple[FloatArray, IntArray]:
    """Tag frequency vectors (cycles/mm, components z, y, x) and slice-axis indices."""
    direction = np.asarray(ds["tag_direction"].transpose("tag", "axis").values, dtype=np.float64)
    frequency = np.asarray(ds["tag_frequency"].values, dtype=np.float64)
    freq = (frequency[:, None] * direction)[:, [AXES.index(d) for d in GRID_DIMS]]
    axes = np.asarray(ds["slice_axis"].values).ravel()
    return freq, np.array([GRID_DIMS.index(str(s)) for s in axes], dtype=np.int64)


def image_noise(phase: xr.Dataset, tagged: xr.Dataset | None = None) -> ImageNoise:
    r"""Noise model of the images behind a phase dataset (module notes).

    Parameters
    ----------
    phase : xarray.Dataset
        The ``phase/1`` dataset (its ``harmonic_noise``, frame-0 ``magnitude``, tags, mask,
        ``radius`` and ``upsample_factors``).
    tagged : xarray.Dataset, optional
        The ``tagged/1`` images ``phase`` was extracted from. Given, each tag's noise
        covariance between the planes along its slice axis is measured from their first
        frame: on the pixels without tag signal (harmonic magnitude below
        :data:`BACKGROUND` times ``harmonic_noise``) where every plane has enough of them,
        since tissue edges inflate the estimate; a SPAMM magnitude image is Rayleigh there,
        whose variance is :math:`(2 - \pi/2)\sigma^2`. Without ``tagged`` the planes are
        taken as independent at the level of ``harmonic_noise``.

    Returns
    -------
    ImageNoise
        The noise of each tag's images on the acquired grid (that of ``tagged`` if given),
        with the covariance between planes measured or assumed.

    Raises
    ------
    ValueError
        If neither ``tagged`` nor a finite ``harmonic_noise`` gives a noise level, or
        ``tagged`` has other tags than ``phase``.
    SchemaError
        If the phase's extraction attributes are malformed
        (:meth:`~harpx.imaging.phase_parameters.PhaseParameters.from_dataset`).
    """
    freq, slice_index = _tag_geometry(phase)
    ntag = freq.shape[0]
    if tagged is not None:
        validate(tagged, "tagged")
        if [str(t) for t in tagged["tag"].values] != [str(t) for t in phase["tag"].values]:
            raise ValueError(
                f"tagged has tags {list(map(str, tagged['tag'].values))!r} but the phase has "
                f"{list(map(str, phase['tag'].values))!r}; pass the images the phase came from"
            )
    grid = tagged if tagged is not None else acquired_grid(phase)
    coords = [np.asarray(grid[d].values, dtype=np.float64) for d in GRID_DIMS]
    shape = tuple(c.size for c in coords)
    spacing = np.array([grid_step(grid, d) or 1.0 for d in GRID_DIMS])
    params = PhaseParameters.from_dataset(phase)
    radius = params.radius
    sigma_h = _harmonic_noise(phase)
    if tagged is None and sigma_h is None:
        raise ValueError(
            "the phase has no finite 'harmonic_noise' (written by extract_phase) and no "
            "tagged images were given: there is no noise level to propagate; pass tagged="
        )
    image0 = None
    if tagged is not None:
        mask = (
            np.asarray(tagged["mask"].transpose("tag", *GRID_DIMS).values, dtype=bool)
            if "mask" in tagged.variables
            else np.ones((ntag, *shape), dtype=bool)
        )
        image0 = np.asarray(
            tagged["image"].isel(time=0).transpose("tag", *GRID_DIMS).values, dtype=np.float64
        )
        if sigma_h is None:
            sigma_h = harmonic_noise_block(
                image0, freq, slice_index, spacing=tuple(spacing), radius=radius
            )
    else:
        held = phase["mask"] if "mask" in phase.variables else None
        mask = _native_mask(params, ntag, held, shape)
    assert sigma_h is not None
    magnitude0 = phase["magnitude"].isel(time=0)
    spamm = params.sequence == "SPAMM"
    factors, estimated, planes = [], np.zeros(ntag, bool), np.ones(ntag, np.int64)
    background, levels = np.zeros(ntag, bool), np.zeros(ntag)
    for t in range(ntag):  # ≤ 3 tags
        axis = int(slice_index[t])
        white = float(sigma_h[t]) / np.sqrt(band_share(shape, spacing, freq[t], axis, radius))
        levels[t] = white
        cov = None
        if image0 is not None:
            inplane = [a for a in range(3) if a != axis]
            # along the tag lines the tag pattern is constant (as in harpx.imaging.noise)
            along = int(np.argmin(np.abs(freq[t, inplane]) * spacing[inplane]))
            a = inplane[along]
            leak = 2.0 - 2.0 * np.cos(2.0 * np.pi * freq[t, a] * spacing[a])
            below = magnitude0.isel(tag=t) < BACKGROUND * sigma_h[t]
            quiet = _native_mask(params, ntag, below, shape)
            stack = np.moveaxis(image0[t], axis, 0)
            valid = np.moveaxis(mask[t], axis, 0)
            quiet = valid & np.moveaxis(quiet.reshape(shape), axis, 0)
            if along == 1:
                stack, valid, quiet = (np.swapaxes(v, 1, 2) for v in (stack, valid, quiet))
            if leak <= MAX_TAG_LEAK and stack.shape[1] >= 3:
                has = valid.reshape(valid.shape[0], -1).any(axis=1)
                runs = (quiet[:, :-2] & quiet[:, 1:-1] & quiet[:, 2:]).reshape(has.size, -1)
                background[t] = bool((runs.sum(axis=1)[has] >= _MIN_PLANE_SAMPLES).all())
                cov, planes[t] = _plane_covariance(stack, quiet if background[t] else valid)
                if background[t] and spamm:
                    cov = cov / (2.0 - 0.5 * np.pi)  # Rayleigh background (docstring)
                estimated[t] = True
        if cov is None:  # independent planes at the harmonic_noise level
            has = np.moveaxis(mask[t], axis, 0).reshape(shape[axis], -1).any(axis=1)
            cov = np.diag(np.where(has, white**2 if np.isfinite(white) else 0.0, 0.0))
        factors.append(_factor(cov))
    return ImageNoise(
        z=coords[0], y=coords[1], x=coords[2], slice_axis=slice_index, factors=tuple(factors),
        mask=mask, estimated=estimated, correlated_planes=planes, background=background,
        white_level=levels,
    )  # fmt: skip


def _harmonic_noise(phase: xr.Dataset) -> FloatArray | None:
    """The phase's ``harmonic_noise`` per tag, or None where absent or not finite."""
    if "harmonic_noise" not in phase.variables:
        return None
    sigma = np.asarray(phase["harmonic_noise"].values, dtype=np.float64).reshape(-1)
    return sigma if bool(np.all(np.isfinite(sigma) & (sigma >= 0))) else None


def _native_mask(
    params: PhaseParameters, ntag: int, values: xr.DataArray | None, shape: tuple[int, ...]
) -> BoolArray:
    """A boolean field of the phase grid (tag, z, y, x or z, y, x) on the acquired grid:
    the refined voxel at the first corner of each native voxel; all True (ntag, *shape)
    for None."""
    if values is None:
        return np.ones((ntag, *shape), dtype=bool)
    dims = [d for d in ("tag", *GRID_DIMS) if d in values.dims]
    field = np.asarray(values.transpose(*dims).values, dtype=bool)
    step = tuple(slice(None, None, m) for m in params.upsample_factors)
    out = field[(slice(None), *step)] if "tag" in dims else field[step]
    return np.ascontiguousarray(out)
