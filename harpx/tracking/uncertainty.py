r"""How much the image noise moves a tracked motion: a linearised, sampled uncertainty.

A post-processing step after :func:`harpx.tracking.track.track`: it rebuilds the tracker's
final Gauss–Newton system of every frame and pushes sampled image noise through it.

Linearisation
-------------
At the tracked state :math:`u_n` of frame :math:`n` the residual on the free dofs vanishes,
:math:`R(u_n) = R_{int}(u_n) + R_c(u_n; \phi_n, \phi_0) \,[+\, \text{terms}] = 0`, with the
constraint force of :mod:`harpx.tracking.constraint`. Noise moves the phase the current
frame shows at the current point, :math:`\delta\phi_n(x)`, and the reference phase,
:math:`\delta\phi_0(X)`, so the mismatch :math:`r_t` of every constraint point and tag by
:math:`\delta r_t = \delta\phi_{n,t}(x) - \delta\phi_{0,t}(X)`, and the residual by

.. math::

    \delta R^c_{ai} = \int m\, N_a\, \lambda_n \sum_t s(r_t)\, (\nabla\phi_t)_i\,
        \delta r_t \, dV,
    \qquad s(r) = \max\!\Big(0, \frac{1 - r^2/r_0^2}{(1 + r^2/r_0^2)^2}\Big),

where :math:`s` is the slope of the Cauchy force :math:`r/(1 + r^2/r_0^2)` (1 for the
quadratic penalty) and :math:`\lambda_n` the frame's final penalty. To first order the
equilibrium then moves by

.. math::

    J\, \delta u_n = -\delta R^c\, [+\, K_{mech}(u_{n-1})\, \delta u_{n-1}],
    \qquad J = K_{int}(u_n) + \int m\, \lambda_n\, N N \sum_t s(r_t)\,
        \nabla\phi_t \nabla\phi_t^T\, dV \,[+\, K_{terms}],

with :math:`K_{int}` the consistent hyperelastic tangent (with the pressure's initial
stress) and the bracketed term only for ``regularization="increment"``, whose residual
holds the previous frame's mechanical force. Dirichlet dofs are held (:math:`\delta u = 0`)
and the rigid-body modes no tag sees are removed, both as the tracker holds them
(:mod:`harpx.tracking.equilibrium`). :math:`J` is factorised once per frame.

With the band-pass blur correction (:mod:`harpx.tracking.blur`) the final pass tracked
images from which the correction :math:`c(U_1)` of the previous pass's motion was removed,
and the noise moved that motion too. The previous pass's response is taken as the one
above, :math:`\delta U_1 \approx \delta U`, each sample's correction is recomputed,
:math:`\delta c = c(U + \delta U) - c(U)`, and its phase change at the points, sampled as
the tracker samples the deblurred images, is pushed through the same factorised systems
and added. Since the previous pass's motion is not stored, :math:`c(U)` of the final
motion stands in for :math:`c(U_1)` throughout.

Noise
-----
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
(:math:`\sigma = \sigma_H \sqrt{N / n_d}`, inverting :mod:`harpx.imaging.noise`), and a
:class:`~harpx.errors.HarpxWarning` says so. The result's ``noise_model`` attribute gives,
per tag, how it was modelled and its level relative to ``harmonic_noise``.

Each sample draws image noise :math:`\nu` for every frame, passes it through
:func:`~harpx.imaging.harp.extract_phase` with the phase's ``upsample`` and ``radius`` (the
same band-pass and interpolation as the data), adds the complex harmonic noise :math:`h`
to the harmonic image :math:`H`, and samples :math:`\arg(H + h)` at the tracker's points
with the tracker's sampler: :math:`\delta\phi = W(\arg(H + h) - \arg H)`. One sample keeps
its frame-0 noise in every frame, so the samples are joint over frames (the reference
noise correlates them) and extremes over frames can be taken per sample. The standard
deviation is the root mean square over the :math:`M` samples (the linear response has zero
mean); its relative sampling error is about :math:`1/\sqrt{2M}`.

Not included
------------
Model and regularisation bias (what the mechanics adds where the data are silent, and its
misfit of the true motion); the band-pass blur correction's own model error; the
tracker's per-frame choice of the penalty, which adapts to the data and can differ between
acquisitions by a level (``penalty_sensitivity`` says how far a level lower moves the
motion, and a warning names the frames where that exceeds half the noise); the phase
Hessian dropped by the Gauss–Newton tangent; effects beyond first order (a noise excursion
that carries a point into a neighbouring tag's basin); the noise estimate's own sampling
error; noise that is not white within a slice or is correlated between frames or tags.
The result's attributes repeat this list. How well the standard deviations cover the
spread over repeated acquisitions is measured in
``benchmarks/results/uncertainty_coverage.md``.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray
from scipy.sparse import linalg as spla

from harpx._typing import BoolArray, FloatArray, IntArray
from harpx.errors import HarpxError, HarpxWarning
from harpx.imaging.bandpass import bandpass_mask
from harpx.imaging.harp import extract_phase
from harpx.imaging.noise import MAD_GAUSS, MAX_TAG_LEAK, harmonic_noise_block
from harpx.imaging.sample import PhaseSampler, wrap
from harpx.imaging.stacks import tagged_dataset
from harpx.mechanics.assembly import internal_forces
from harpx.mechanics.linsolve import LinearSolver
from harpx.schema import AXES, GRID_DIMS, validate
from harpx.tracking.blur import blur_correction, deblurred
from harpx.tracking.constraint import ConstraintState, PhaseConstraint
from harpx.tracking.equilibrium import equilibrate, split_dirichlet
from harpx.tracking.results import acquired_grid

__all__ = ["DEFAULT_SAMPLES", "EXCLUDED", "ImageNoise", "image_noise", "tracking_uncertainty"]

#: Noise samples drawn by default (relative sampling error of a standard deviation ≈ 9 %).
DEFAULT_SAMPLES = 64
#: What the uncertainty leaves out (module notes), as written into the result's attributes.
EXCLUDED = (
    "model and regularisation bias; the band-pass blur correction's model error; the "
    "tracker's per-frame choice of the penalty; the phase Hessian; effects beyond first "
    "order (tag jumps); the noise estimate's own error; noise not white in-plane or "
    "correlated between frames or tags"
)
#: Harmonic magnitude, in units of ``harmonic_noise``, below which a pixel has no tag signal.
BACKGROUND = 3.0
#: Standard errors a lag's mean correlation must exceed to count as correlated.
SIGNIFICANCE = 4.0
#: Standard error of a MAD-based correlation from n Gaussian pairs is about this / sqrt(n).
_MAD_CORRELATION_SE = 1.65
#: Fewest second differences in a plane for its own variance estimate.
_MIN_PLANE_SAMPLES = 50
#: Bytes of complex harmonic noise held at once (bounds the samples generated together).
_CHUNK_BYTES = 128e6
#: Motion change at half the penalty, in standard deviations (RMS over the dofs), above
#: which the tracker's penalty choice is flagged as a spread the standard deviations leave
#: out. Below 1, as a level's change is smooth and regional averages feel it more than the
#: nodal noise (why this value: ``benchmarks/results/uncertainty_coverage.md``).
PENALTY_SENSITIVITY = 0.5
#: RMS phase noise of the residual (rad) above which the first-order model is doubtful.
_LINEAR_PHASE_LIMIT = 0.3


# ------------------------------------------------------------------------------ noise model
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
        """``count`` independent image-noise fields per tag, (ntag, count, nz, ny, nx), float32."""
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
        """One line per tag: how its noise was modelled (for the result's attributes)."""
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
        """Noise standard deviation of every plane along each tag's slice axis, image units."""
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


def _kept_fraction(shape: tuple[int, ...], spacing: FloatArray, freq: FloatArray, axis: int,
                   radius: float) -> float:  # fmt: skip
    """Share n_d / N of a slice's DFT samples inside the tag's band-pass disk."""
    plane = [a for a in range(3) if a != axis]
    f = [float(freq[a]) for a in plane]
    n = tuple(shape[a] for a in plane)
    d = [float(spacing[a]) for a in plane]
    kept = bandpass_mask(n, d, f, radius * float(np.hypot(f[0], f[1]))).sum()
    return float(kept) / float(n[0] * n[1])


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

    Raises
    ------
    ValueError
        If neither ``tagged`` nor a finite ``harmonic_noise`` gives a noise level, or
        ``tagged`` has other tags than ``phase``.
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
    spacing = np.array([c[1] - c[0] if c.size > 1 else 1.0 for c in coords])
    radius = float(phase.attrs.get("radius", 0.5))
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
        mask = _native_mask(phase, phase["mask"] if "mask" in phase.variables else None, shape)
    assert sigma_h is not None
    magnitude0 = phase["magnitude"].isel(time=0)
    spamm = str(phase.attrs.get("sequence", "CSPAMM")) == "SPAMM"
    factors, estimated, planes = [], np.zeros(ntag, bool), np.ones(ntag, np.int64)
    background, levels = np.zeros(ntag, bool), np.zeros(ntag)
    for t in range(ntag):  # ≤ 3 tags
        axis = int(slice_index[t])
        white = float(sigma_h[t]) / np.sqrt(_kept_fraction(shape, spacing, freq[t], axis, radius))
        levels[t] = white
        cov = None
        if image0 is not None:
            inplane = [a for a in range(3) if a != axis]
            # along the tag lines the tag pattern is constant (as in harpx.imaging.noise)
            along = int(np.argmin(np.abs(freq[t, inplane]) * spacing[inplane]))
            a = inplane[along]
            leak = 2.0 - 2.0 * np.cos(2.0 * np.pi * freq[t, a] * spacing[a])
            quiet = _native_mask(phase, magnitude0.isel(tag=t) < BACKGROUND * sigma_h[t], shape)
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
    phase: xr.Dataset, values: xr.DataArray | None, shape: tuple[int, ...]
) -> BoolArray:
    """A boolean field of the phase grid (tag, z, y, x or z, y, x) on the acquired grid:
    the refined voxel at the first corner of each native voxel; all True for None."""
    if values is None:
        return np.ones((phase.sizes["tag"], *shape), dtype=bool)
    dims = [d for d in ("tag", *GRID_DIMS) if d in values.dims]
    field = np.asarray(values.transpose(*dims).values, dtype=bool)
    factors = [int(m) for m in np.atleast_1d(phase.attrs.get("upsample_factors", [1, 1, 1]))]
    step = tuple(slice(None, None, m) for m in factors)
    out = field[(slice(None), *step)] if "tag" in dims else field[step]
    return np.ascontiguousarray(out)


def _harmonic_fields(
    noise: ImageNoise, phase: xr.Dataset, rng: np.random.Generator, count: int
) -> np.ndarray:
    """Complex harmonic noise (tag, count, z, y, x) on the phase grid: image noise through
    the phase extraction the data went through."""
    freq, _ = _tag_geometry(phase)
    direction = np.asarray(phase["tag_direction"].transpose("tag", "axis").values, dtype=float)
    ds = tagged_dataset(
        noise.sample(rng, count),
        tag=[str(t) for t in phase["tag"].values],
        tag_frequency=np.asarray(phase["tag_frequency"].values, dtype=np.float64),
        tag_direction=direction,
        slice_axis=[GRID_DIMS[int(a)] for a in noise.slice_axis],
        time=np.arange(count, dtype=np.float64),
        z=noise.z, y=noise.y, x=noise.x,
        sequence=str(phase.attrs.get("sequence", "CSPAMM")),
        mask=noise.mask,
        check=False,
    )  # fmt: skip
    harmonic = extract_phase(
        ds,
        upsample=int(phase.attrs.get("upsample", 1)),
        radius=float(phase.attrs.get("radius", 0.5)),
        dtype="float32",  # noise: single precision is ample and halves the memory traffic
    )
    for d in GRID_DIMS:
        mine, theirs = harmonic[d].values, phase[d].values
        if mine.shape != theirs.shape or not np.allclose(mine, theirs, atol=1e-6):
            raise ValueError(
                f"the images' grid along {d!r}, extracted with upsample="
                f"{phase.attrs.get('upsample', 1)!r}, is not the phase's grid; pass the tagged "
                "images the phase was extracted from"
            )
    dims = ("tag", "time", *GRID_DIMS)
    return _complex(harmonic["magnitude"].transpose(*dims).values,
                    harmonic["phase"].transpose(*dims).values)  # fmt: skip


def _complex(magnitude: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``magnitude · exp(i angle)`` in single precision."""
    out = np.empty(magnitude.shape, dtype=np.complex64)
    out.real = np.cos(angle, dtype=np.float32)
    out.imag = np.sin(angle, dtype=np.float32)
    out *= magnitude.astype(np.float32, copy=False)
    return out


def _frame_harmonic(phase: xr.Dataset, n: int) -> np.ndarray:
    """The complex harmonic image of frame ``n`` (tag, z, y, x)."""
    frame = phase.isel(time=n)
    dims = ("tag", *GRID_DIMS)
    return _complex(frame["magnitude"].transpose(*dims).values,
                    frame["phase"].transpose(*dims).values)  # fmt: skip


def _perturbed_phases(
    phase: xr.Dataset, harmonic: np.ndarray, fields: np.ndarray, points: FloatArray,
    baseline: FloatArray, order: int,
) -> FloatArray:  # fmt: skip
    """Phase change W(arg(H + h) − arg H) at ``points`` for each noise field, (sample, n,
    ntag), sampled as the tracker samples (0 where the perturbed image is not valid).

    The samples are stacked as further tags of one image, so that one sampler locates the
    points once for all of them.
    """
    ntag, count = fields.shape[:2]
    H = (harmonic[:, None] + fields).swapaxes(0, 1).reshape(count * ntag, 1, *fields.shape[2:])
    dims = ("tag", "time", *GRID_DIMS)
    labels = [f"{t}/{m}" for m in range(count) for t in phase["tag"].values]
    direction = np.tile(phase["tag_direction"].transpose("tag", "axis").values, (count, 1))
    coords: dict[str, Any] = {
        "tag": labels, "axis": phase["axis"].values, "time": [0.0],
        "tag_direction": (("tag", "axis"), direction),
        "tag_frequency": ("tag", np.tile(phase["tag_frequency"].values, count)),
        **{d: phase[d].values for d in GRID_DIMS},
    }  # fmt: skip
    variables: dict[str, Any] = {"phase": (dims, np.angle(H)), "magnitude": (dims, np.abs(H))}
    if "mask" in phase.variables:
        mask = phase["mask"].transpose("tag", *GRID_DIMS).values
        variables["mask"] = (("tag", *GRID_DIMS), np.tile(mask, (count, 1, 1, 1)))
    sampler = PhaseSampler(xr.Dataset(variables, coords=coords), 0, order=order)
    phi, ok = sampler.phase(points, per_tag=True)
    phi = phi.reshape(-1, count, ntag).swapaxes(0, 1)
    ok = ok.reshape(-1, count, ntag).swapaxes(0, 1)
    return np.where(ok, wrap(phi - baseline), 0.0)


# ------------------------------------------------------------------------------ linear model
def _slope(residual: FloatArray, scale: float | None) -> FloatArray | None:
    """Slope s(r) of the (Cauchy) constraint force (module notes); None when quadratic."""
    if scale is None:
        return None
    q = (residual / scale) ** 2
    return np.asarray(np.clip((1.0 - q) / (1.0 + q) ** 2, 0.0, None), dtype=np.float64)


def _setting(tracked: xr.Dataset, name: str, default: Any) -> Any:
    value = tracked.attrs.get(f"setting_{name}", default)
    return value.item() if isinstance(value, np.generic) else value


def _mechanical_tangent(body: Any, u: FloatArray, terms: Sequence[Any]) -> tuple[Any, FloatArray]:
    """Consistent internal tangent plus term tangents, and the matching force, at ``u``."""
    internal = internal_forces(body, u)
    if internal.r is None or internal.K is None:
        raise ValueError(
            "the tracked displacement inverts cells of this body; pass the body that was tracked"
        )
    K, r = internal.K.copy(), np.array(internal.r, dtype=np.float64)
    for term in terms:
        rt, Kt = term.residual_tangent(body, u, 1.0)
        r = r + rt
        if Kt is not None:
            K = K + Kt
    return K.tocsr(), r


def _check_inputs(tracked: xr.Dataset, body: Any) -> None:
    validate(tracked, "tracked")
    if "dof_displacement" not in tracked.variables:
        raise ValueError("tracked has no 'dof_displacement'; pass the result of harpx track")
    if tracked.sizes["dof"] != body.ndof or not np.allclose(
        tracked["points"].values, body.dof_points, atol=1e-6
    ):
        raise ValueError(
            f"the body ({body.ndof} dofs) is not the one tracked ({tracked.sizes['dof']} dofs "
            "or other node positions); pass the body given to track"
        )
    method = _setting(tracked, "method", "penalty")
    if method != "penalty":
        raise ValueError(
            f"the result was tracked with method={method!r}; the uncertainty linearises the "
            "penalty method (the augmented-Lagrangian multipliers move with the data too)"
        )


def tracking_uncertainty(
    tracked: xr.Dataset,
    body: Any,
    images: xr.Dataset,
    *,
    tagged: xr.Dataset | None = None,
    dirichlet: Sequence[Any] = (),
    terms: Sequence[Any] = (),
    samples: int = DEFAULT_SAMPLES,
    seed: int | None = None,
    keep_samples: bool = False,
) -> xr.Dataset:
    r"""Standard deviation of a tracked displacement due to the image noise (module notes).

    Parameters
    ----------
    tracked : xarray.Dataset
        ``tracked/1`` result of :func:`~harpx.tracking.track.track` (penalty method).
    body : Body
        The body that was tracked (reference configuration, mm).
    images : xarray.Dataset
        What was tracked: the ``phase/1`` dataset, or ``tagged/1`` images (their phase is
        then extracted with the defaults, as ``track`` does, and they also serve as
        ``tagged``).
    tagged : xarray.Dataset, optional
        The ``tagged/1`` images the phase came from: they give the noise covariance across
        the slices (:func:`image_noise`). Without them the planes of the grid are taken as
        independent, which understates the noise of slices thicker than the grid spacing
        (warned).
    dirichlet, terms : sequence, optional
        The Dirichlet conditions and residual terms given to ``track``.
    samples : int, default 64
        Noise samples M (≥ 2); the relative sampling error of each standard deviation is
        about :math:`1/\sqrt{2M}`.
    seed : int, optional
        Seed of the noise samples.
    keep_samples : bool, default False
        Also return the sampled displacement changes (``dof_displacement_samples``).

    Returns
    -------
    xarray.Dataset
        ``displacement_std`` (time, node, axis), mm: standard deviation of each node's
        displacement; ``noise_residual`` (time), rad: mean :math:`|\delta r|` of the sampled
        noise over the valid points and tags, weighted as ε (compare ``epsilon_floor``);
        ``equilibrium_step`` (time), mm: largest change a further Newton step would make at
        the rebuilt state (about the tracking tolerance when body, conditions and images
        are the tracked ones; with the blur correction also the change from recomputing it
        from the final motion, since the previous pass's motion is not stored);
        ``penalty_sensitivity`` (time): root-mean-square change of the motion had the frame
        stopped at half its final penalty, over its root-mean-square standard deviation
        (the tracker's discrete, data-dependent penalty choice, not in the σ); with
        ``keep_samples`` ``dof_displacement_samples`` (sample, time, dof), mm.
        Attributes: ``samples``, ``seed``, ``relative_sampling_error``, ``noise_model``
        per tag, ``excludes`` (what is left out) and ``flags`` (the warnings raised, "" if
        none).

    Raises
    ------
    ValueError
        If ``tracked`` is not a penalty-method result of this body, ``samples`` < 2, the
        Dirichlet conditions differ from the tracked ones (the held dofs moved, or another
        number of rigid modes is unseen), or there is no noise level (no
        ``harmonic_noise`` and no ``tagged``).

    Warns
    -----
    HarpxWarning
        When the noise across slices is assumed rather than measured, a frame missed its
        target or did not converge, the rebuilt state is not in equilibrium, the noise is
        too large for a first-order model, or half the penalty moves a frame's motion by
        more than its standard deviation (each also listed in ``flags``).

    Notes
    -----
    Cost per frame: one factorisation, the image noise of M frames through the phase
    extraction, M phase samplings of the constraint points and M back-substitutions; with
    the blur correction also M corrections of the whole motion (usually the largest part).
    """
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 2:
        raise ValueError(f"samples={samples!r} must be a whole number ≥ 2")
    if images.attrs.get("harpx_schema") == "tagged/1":
        tagged = images if tagged is None else tagged
        images = extract_phase(images)
    validate(images, "phase")
    flags: list[str] = []

    def flag(message: str) -> None:
        flags.append(message)
        warnings.warn(message, HarpxWarning, stacklevel=3)

    problem = _rebuild(tracked, body, images, dirichlet, terms)
    noise = image_noise(images, tagged)
    if not noise.estimated.all():
        unmeasured = [str(t) for t, e in zip(images["tag"].values, noise.estimated, strict=True)
                      if not e]  # fmt: skip
        flag(
            f"the image noise of tag(s) {unmeasured} is taken as independent between the "
            "grid's planes along the slice axis (no tagged images, or tags oblique to every "
            "grid axis): slices thicker than the grid spacing make it correlated and the "
            "standard deviations too small; pass tagged="
        )
    _warn_frames(tracked, flag)
    dU, noise_residual, step = _sample_response(problem, noise, int(samples), seed)
    std = np.sqrt(np.mean(dU**2, axis=0))  # (time, dof): the linear response has zero mean
    _check_result(problem, std, step, noise_residual, flag)
    sensitivity = _penalty_sensitivity(problem, std)
    ramp, limit = _setting(tracked, "ramp", 2), _setting(tracked, "penalty_limit", np.inf)
    if not (int(ramp) == 1 and float(limit) < 2.0 * float(_setting(tracked, "penalty", 1.0))):
        _check_penalty(sensitivity, flag)  # else the penalty was fixed: no choice to flag
    ntime = dU.shape[1]
    out = xr.Dataset(coords={"time": tracked["time"], "axis": tracked["axis"]})
    out["displacement_std"] = xr.DataArray(
        std.reshape(ntime, -1, 3), dims=("time", "node", "axis"),
        attrs={"units": "mm", "long_name": "displacement standard deviation due to image noise"},
    )  # fmt: skip
    out["noise_residual"] = xr.DataArray(
        noise_residual, dims="time",
        attrs={"units": "rad", "long_name": "mean |phase residual| of the sampled image noise"},
    )  # fmt: skip
    out["equilibrium_step"] = xr.DataArray(
        step, dims="time",
        attrs={"units": "mm", "long_name": "largest Newton step at the rebuilt tracked state"},
    )  # fmt: skip
    out["penalty_sensitivity"] = xr.DataArray(
        sensitivity, dims="time",
        attrs={"units": "1", "long_name": "RMS displacement change at half the penalty / RMS sd"},
    )  # fmt: skip
    if keep_samples:
        out["dof_displacement_samples"] = xr.DataArray(
            dU, dims=("sample", "time", "dof"),
            attrs={"units": "mm", "long_name": "sampled displacement change due to image noise"},
        )  # fmt: skip
    out.attrs.update(
        samples=int(samples),
        seed=-1 if seed is None else int(seed),
        relative_sampling_error=float(1.0 / np.sqrt(2.0 * samples)),
        noise_model=noise.describe([str(t) for t in images["tag"].values]),
        excludes=EXCLUDED,
        flags=" | ".join(flags),
    )
    return out


@dataclass
class _Problem:
    """The tracker's problem rebuilt from a result (what every frame's solve needs)."""

    body: Any
    dirichlet: Sequence[Any]
    terms: Sequence[Any]
    constraint: PhaseConstraint
    raw: xr.Dataset  # the phase as given (the constraint may hold the deblurred one)
    U: FloatArray  # (time, dof) tracked displacement, mm
    penalty: FloatArray  # (time,) absolute final penalty, kPa/rad²
    robust_scale: float | None
    increment: bool
    tolerance: float
    free: IntArray
    correction: np.ndarray | None = None  # blur correction of U (tag, time, z, y, x), rad
    linear_solver: str = "auto"
    max_iterations: int = 20

    def remove_unseen(self, du: FloatArray) -> FloatArray:
        """Rows of ``du`` (k, ndof) with the unseen rigid modes removed, as the tracker does."""
        seen = self.constraint.observability
        if seen is None or not seen.unseen_modes.shape[0]:
            return du
        amplitude = (du * seen.mode_weights) @ seen.unseen_modes.T
        return du - amplitude @ seen.unseen_modes


def _rebuild(
    tracked: xr.Dataset, body: Any, phase: xr.Dataset, dirichlet: Sequence[Any],
    terms: Sequence[Any],
) -> _Problem:  # fmt: skip
    """The constraint, held dofs and penalties the tracker ended with (checked)."""
    _check_inputs(tracked, body)
    U = np.asarray(tracked["dof_displacement"].transpose("time", "dof").values, dtype=np.float64)
    intorder = int(_setting(tracked, "intorder", -1))
    robust = _setting(tracked, "robust_scale", "none")
    robust_scale = None if isinstance(robust, str) else float(robust)
    constraint = PhaseConstraint(
        body, phase, intorder=None if intorder < 0 else intorder, robust_scale=robust_scale
    )
    fixed, values = split_dirichlet(body, dirichlet)
    if fixed.size and np.abs(U[1:, fixed] - values).max(initial=0.0) > 1e-6:
        raise ValueError(
            "the tracked displacement does not hold the given Dirichlet dofs at their values; "
            "pass the dirichlet= given to track"
        )
    seen = constraint.observe(fixed)
    recorded = tracked.attrs.get("rigid_modes_removed")
    removed = seen.unseen_modes.shape[0] if recorded is None else int(recorded)
    if removed != seen.unseen_modes.shape[0]:
        raise ValueError(
            f"with these Dirichlet conditions {seen.unseen_modes.shape[0]} rigid mode(s) are "
            f"unseen, but tracking removed {removed}; pass the dirichlet= given to track"
        )
    correction = None
    if int(tracked.attrs.get("blur_passes_applied", 0)) > 0:
        # the final pass tracked images deblurred with the previous pass's motion, which is
        # not stored: the correction of the final motion stands in for it
        correction = blur_correction(phase, body, U)
        constraint.replace_images(deblurred(phase, correction))
    penalty = np.asarray(tracked["penalty"].values, dtype=np.float64)
    return _Problem(
        body=body, dirichlet=dirichlet, terms=terms, constraint=constraint, raw=phase, U=U,
        penalty=penalty * constraint.penalty_scale(), robust_scale=robust_scale,
        increment=_setting(tracked, "regularization", "total") == "increment",
        tolerance=float(_setting(tracked, "tolerance", 0.01)),
        free=np.setdiff1d(np.arange(body.ndof), np.union1d(fixed, seen.pinned_dofs)),
        correction=correction, linear_solver=str(tracked.attrs.get("linear_solver", "auto")),
        max_iterations=int(_setting(tracked, "max_iterations", 20)),
    )  # fmt: skip


@dataclass
class _Frame:
    """One frame's linearised system (module notes), factorised."""

    state: ConstraintState  # at the tracked state, with the slopes s(r) as weights
    lu: Any  # factorised J on the free dofs
    mechanical: Any  # K_mech(u_n), needed by the next frame with increment regularisation
    step: float  # largest nodal change of a Newton step from the tracked state, mm
    penalty: float  # the frame's absolute penalty, kPa/rad²


def _frame_system(problem: _Problem, n: int) -> _Frame:
    """Assemble and factorise frame ``n``'s J, and the Newton step at its tracked state."""
    constraint, U, free = problem.constraint, problem.U, problem.free
    constraint.set_frame(n)
    st = constraint.state(U[n])
    constraint.penalty = float(problem.penalty[n])
    constraint.multipliers[:] = 0.0
    slope = _slope(st.residual, problem.robust_scale)
    linear = ConstraintState(st.residual, st.gradient, st.weight, st.tag_valid, slope)
    _, Kc = constraint.assemble(linear)
    K, r = _mechanical_tangent(problem.body, U[n], problem.terms)
    R = r + constraint.force(st)
    if problem.increment:
        R = R - _mechanical_tangent(problem.body, U[n - 1], problem.terms)[1]
    lu = spla.splu((K + Kc)[free][:, free].tocsc())
    newton = np.zeros((1, U.shape[1]))
    newton[0, free] = -lu.solve(R[free])
    step = float(np.abs(problem.remove_unseen(newton)).max())
    return _Frame(linear, lu, K if problem.increment else None, step, float(problem.penalty[n]))


def _sample_response(
    problem: _Problem, noise: ImageNoise, samples: int, seed: int | None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Sampled displacement changes (sample, time, dof), the mean |δr| per frame and the
    Newton step of each frame's rebuilt state."""
    constraint, raw, U = problem.constraint, problem.raw, problem.U
    rng = np.random.default_rng(seed)
    order = constraint.spline_order
    nvox = int(np.prod([raw.sizes[d] for d in GRID_DIMS]))
    per_sample = (24.0 + (4.0 * U.shape[0] if problem.correction is not None else 0.0)) * nvox
    chunk = int(max(1, min(samples, _CHUNK_BYTES // (per_sample * constraint.ntag))))
    starts = [(s, min(chunk, samples - s)) for s in range(0, samples, chunk)]
    # frame 0: one reference-noise field per sample, shared by all its frames
    dphi0 = np.zeros((samples, *constraint.reference_valid.shape), dtype=np.float32)
    H0 = _frame_harmonic(raw, 0)
    for s, count in starts:
        fields = _harmonic_fields(noise, raw, rng, count)
        dphi0[s : s + count] = _perturbed_phases(
            raw, H0, fields, constraint.points, constraint.reference_phase, order
        )
    ntime, ndof = U.shape
    dU = np.zeros((samples, ntime, ndof))
    noise_residual = np.full(ntime, np.nan)
    step = np.zeros(ntime)
    previous = None
    frames: dict[int, _Frame] = {}
    for n in range(1, ntime):
        frame = frames[n] = _frame_system(problem, n)
        step[n] = frame.step
        st = frame.state
        points = constraint.current_points(U[n])
        baseline, _ = PhaseSampler(raw, n, order=order).phase(points, per_tag=True)
        Hn = _frame_harmonic(raw, n)
        w = st.weight[:, None] * st.tag_valid
        mean_abs = 0.0
        for s, count in starts:
            fields = _harmonic_fields(noise, raw, rng, count)
            dphi = _perturbed_phases(raw, Hn, fields, points, baseline, order)
            delta = np.where(st.tag_valid, dphi - dphi0[s : s + count], 0.0)
            mean_abs += float((w * np.abs(delta)).sum()) / max(float(w.sum()), 1e-300)
            dU[s : s + count, n] = _respond(
                problem, frame, delta, previous, dU[s : s + count, n - 1]
            )
        noise_residual[n] = mean_abs / samples
        previous = frame.mechanical
    if problem.correction is not None:
        for s, count in starts:
            dU[s : s + count] += _blur_feedback(problem, frames, dU[s : s + count])
    return dU, noise_residual, step


def _respond(
    problem: _Problem, frame: _Frame, delta: FloatArray, previous: Any, last: FloatArray
) -> FloatArray:
    """Displacement changes (k, ndof) of a frame for residual changes ``delta`` (k, nq, ntag);
    ``previous`` K_mech of the last frame and ``last`` its changes (increment
    regularisation), else None."""
    st, constraint = frame.state, problem.constraint
    constraint.penalty = frame.penalty
    rhs = np.empty((problem.free.size, delta.shape[0]))
    for m in range(delta.shape[0]):  # one force assembly per sample (vectorised over points)
        moved = ConstraintState(delta[m], st.gradient, st.weight, st.tag_valid,
                                st.robust_weight)  # fmt: skip
        force = -constraint.force(moved)
        if previous is not None:  # increment regularisation: the last frame's change
            force += previous @ last[m]
        rhs[:, m] = force[problem.free]
    du = np.zeros((delta.shape[0], problem.U.shape[1]))
    du[:, problem.free] = frame.lu.solve(rhs).T
    return problem.remove_unseen(du)


def _blur_feedback(problem: _Problem, frames: dict[int, _Frame], dU: FloatArray) -> FloatArray:
    """The further change (k, time, dof) of the motions ``U + dU`` (k samples) through the blur
    correction: the final pass tracked images deblurred by the correction of the previous
    pass's motion, which the noise moved too (module notes)."""
    constraint, U, raw = problem.constraint, problem.U, problem.raw
    assert problem.correction is not None
    count, ntime, _ = dU.shape
    # the correction of each perturbed motion, less that of the tracked one (tag, time, ...)
    change = [blur_correction(raw, problem.body, U + dU[m]) - problem.correction
              for m in range(count)]  # fmt: skip
    out = np.zeros_like(dU)
    previous = None
    for n in range(1, ntime):
        points = constraint.current_points(U[n])
        baseline, _ = PhaseSampler(constraint.phase, n, order=constraint.spline_order).phase(
            points, per_tag=True
        )
        deblurred_n = _frame_harmonic(constraint.phase, n)
        # the deblurred image with the perturbed correction removed instead: H e^{-i δc}
        fields = np.stack([deblurred_n * np.expm1(-1j * c[:, n]).astype(np.complex64)
                           for c in change], axis=1)  # fmt: skip
        dphi = _perturbed_phases(constraint.phase, deblurred_n, fields, points, baseline,
                                 constraint.spline_order)  # fmt: skip
        delta = np.where(frames[n].state.tag_valid, dphi, 0.0)
        out[:, n] = _respond(problem, frames[n], delta, previous, out[:, n - 1])
        previous = frames[n].mechanical
    return out


def _penalty_sensitivity(problem: _Problem, std: FloatArray) -> FloatArray:
    """Per frame, the root-mean-square displacement change between the equilibria at the
    final penalty and at half of it (both solved from the tracked state with the rebuilt
    images, so that the difference is the penalty's alone), in units of the
    root-mean-square standard deviation (NaN in frame 0 or where a solve fails)."""
    constraint, U = problem.constraint, problem.U
    solver = LinearSolver(problem.linear_solver)
    out = np.full(U.shape[0], np.nan)
    for n in range(1, U.shape[0]):
        constraint.set_frame(n)
        constraint.multipliers[:] = 0.0
        offset = None
        if problem.increment:
            offset = -_mechanical_tangent(problem.body, U[n - 1], problem.terms)[1]
        states: list[FloatArray] = []
        try:
            for factor in (1.0, 0.5):
                constraint.penalty = factor * float(problem.penalty[n])
                states.append(equilibrate(
                    problem.body, constraint, states[-1] if states else U[n],
                    dirichlet=problem.dirichlet, terms=problem.terms, solver=solver,
                    tolerance=problem.tolerance, max_iterations=problem.max_iterations,
                    offset=offset,
                ).u)  # fmt: skip
        except HarpxError:  # an inverting step at the lower penalty: no estimate
            continue
        scale = float(np.sqrt(np.mean(std[n] ** 2)))
        if scale > 0:
            out[n] = float(np.sqrt(np.mean((states[1] - states[0]) ** 2))) / scale
    return out


def _check_penalty(sensitivity: FloatArray, flag: Any) -> None:
    """Flag frames whose motion moves by more than ``PENALTY_SENSITIVITY`` standard
    deviations between neighbouring penalty levels."""
    frames = [n for n in range(sensitivity.size) if sensitivity[n] > PENALTY_SENSITIVITY]
    if frames:
        flag(
            f"in frame(s) {frames} half the final penalty moves the motion by up to "
            f"{np.nanmax(sensitivity[frames]):.2g} times its standard deviation (RMS): the "
            "tracker picks the penalty per frame from the data, so another acquisition may "
            "stop at a neighbouring level, and that spread is not in the standard deviations "
            "(see 'penalty_sensitivity'; tracking at a fixed penalty, ramp=1 and "
            "penalty_limit= equal to penalty=, removes the choice)"
        )


def _warn_frames(tracked: xr.Dataset, flag: Any) -> None:
    """Flag frames whose state is not the tracker's converged equilibrium at its target."""
    bad = []
    for name in ("target_reached", "converged"):
        if name in tracked.variables:
            values = np.asarray(tracked[name].values, dtype=bool)
            bad += [n for n in range(1, values.size) if not values[n]]
    if bad:
        flag(
            f"frame(s) {sorted(set(bad))} missed the tracking target or did not converge: "
            "there the linearisation is about a state that is not the tracker's equilibrium"
        )


def _check_result(
    problem: _Problem, std: FloatArray, step: FloatArray, noise_residual: FloatArray, flag: Any
) -> None:
    """Flag a rebuilt state out of equilibrium and noise too large for a first-order model."""
    largest = std.max(axis=1)
    period = 2.0 * np.pi / problem.constraint.max_wavenumber
    # recomputing the blur correction from the final motion (module notes) moves the
    # equilibrium by up to a few tenths of a mm on its own: a looser limit then
    recomputed = problem.correction is not None
    limit = max(10.0 * problem.tolerance, period / (8.0 if recomputed else 16.0))
    off = [n for n in range(1, step.size) if step[n] > limit]
    if off:
        flag(
            f"the rebuilt state of frame(s) {off} is not in equilibrium (a Newton step would "
            f"move it by up to {step[off].max():.3g} mm, more than {limit:.3g} mm): body, "
            "Dirichlet conditions, terms or images differ from those tracked"
        )
    rms = np.sqrt(np.pi / 2.0) * np.nan_to_num(noise_residual)  # mean |Gaussian| → its sd
    if rms.max(initial=0.0) > _LINEAR_PHASE_LIMIT or 2.0 * largest.max() > 0.25 * period:
        flag(
            f"the noise is large for a first-order model (phase residual sd up to "
            f"{rms.max():.2g} rad, displacement sd up to {largest.max():.2g} mm against a "
            f"{period:.3g} mm tag period): the standard deviations may be too small"
        )
