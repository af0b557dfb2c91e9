r"""Sampled image noise through the phase extraction to the tracker's points.

For :mod:`harpx.tracking.uncertainty`: each sample draws image noise :math:`\nu` for every
frame (:meth:`~harpx.tracking.uncertainty_noise.ImageNoise.sample`), passes it through
:func:`~harpx.imaging.harp.extract_phase` with the phase's ``upsample`` and ``radius`` (the
same band-pass and interpolation as the data), adds the complex harmonic noise :math:`h`
to the harmonic image :math:`H`, and samples :math:`\arg(H + h)` at the tracker's points
with the tracker's sampler: :math:`\delta\phi = W(\arg(H + h) - \arg H)`.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import xarray as xr

from harpx._typing import BoolArray, FloatArray
from harpx.errors import HarpxWarning, user_stacklevel
from harpx.imaging.harp import _extract_phase
from harpx.imaging.phase_parameters import PhaseParameters
from harpx.imaging.sample import PhaseSampler, wrap
from harpx.imaging.stacks import tagged_dataset
from harpx.schema import GRID_DIMS
from harpx.tracking.uncertainty_noise import ImageNoise

__all__ = ["NoiseSampleWarning", "frame_harmonic", "harmonic_fields", "perturbed_phases"]

#: Longest excerpt of each distinct warning quoted in a :class:`NoiseSampleWarning`.
_EXCERPT = 240


class NoiseSampleWarning(HarpxWarning):
    """What the phase extraction said about internally sampled image noise, in one warning.

    :func:`harmonic_fields` passes noise images, numbered as frames, through the phase
    extraction; whatever that extraction warns is about those noise samples, not about the
    user's frames, and is gathered into one warning of this class per call.
    :func:`~harpx.tracking.uncertainty.tracking_uncertainty` gathers these in turn into
    one flagged warning.
    """


def harmonic_fields(
    noise: ImageNoise, phase: xr.Dataset, rng: np.random.Generator, count: int
) -> np.ndarray:
    """Complex harmonic noise on the phase grid: image noise through the phase extraction
    the data went through.

    Parameters
    ----------
    noise : ImageNoise
        The noise of the images behind ``phase``
        (:func:`~harpx.tracking.uncertainty_noise.image_noise`).
    phase : xarray.Dataset
        The ``phase/1`` dataset: its tags, grid and extraction parameters (``sequence``,
        ``upsample``, ``radius``).
    rng : numpy.random.Generator
        Source of the noise samples.
    count : int
        Noise fields to draw per tag.

    Returns
    -------
    ndarray of complex64, shape (ntag, count, nz, ny, nx)
        Harmonic noise h of each tag on the grid of ``phase``, in the units of its
        ``magnitude`` (0 for a tag whose image noise is 0 everywhere, which is not
        extracted).

    Raises
    ------
    ValueError
        If the noise's grid, extracted with the phase's ``upsample``, is not the grid of
        ``phase``.

    Warns
    -----
    NoiseSampleWarning
        Once, quoting each distinct warning the phase extraction raised on the noise
        samples (those warnings themselves do not reach the caller).
    """
    params = PhaseParameters.from_dataset(phase)
    direction = np.asarray(phase["tag_direction"].transpose("tag", "axis").values, dtype=float)
    fields = noise.sample(rng, count)  # every tag drawn: the same stream with or without
    # tags whose noise is identically 0: their harmonic noise is 0 (the extraction is
    # linear), and a blank image would only make the extraction warn about it
    live: BoolArray = np.asarray(fields.reshape(fields.shape[0], -1).any(axis=1), dtype=bool)
    out = np.zeros((live.size, count, *(phase.sizes[d] for d in GRID_DIMS)), np.complex64)
    if not live.any():
        return out
    ds = tagged_dataset(
        fields[live],
        tag=[str(t) for t, keep in zip(phase["tag"].values, live, strict=True) if keep],
        tag_frequency=np.asarray(phase["tag_frequency"].values, dtype=np.float64)[live],
        tag_direction=direction[live],
        slice_axis=[GRID_DIMS[int(a)] for a in noise.slice_axis[live]],
        time=np.arange(count, dtype=np.float64),
        z=noise.z, y=noise.y, x=noise.x,
        sequence=params.sequence,
        mask=noise.mask[live],
        check=False,
    )  # fmt: skip
    # noise has no tag pattern whose frequency could be checked; what the extraction warns
    # is about these noise samples (numbered as frames), not the user's frames: gathered
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        harmonic = _extract_phase(
            ds, params.upsample, params.radius, None, "float32", check_tag_frequency=False
        )  # float32: single precision is ample for noise and halves the memory traffic
    if caught:
        said = " / ".join(dict.fromkeys(str(w.message)[:_EXCERPT] for w in caught))  # distinct
        warnings.warn(
            NoiseSampleWarning(
                f"the phase extraction of {count} sampled image-noise image(s) per tag "
                f"(internal samples numbered as frames, not your frames) warned: {said}"
            ),
            stacklevel=user_stacklevel(),
        )
    for d in GRID_DIMS:
        mine, theirs = harmonic[d].values, phase[d].values
        if mine.shape != theirs.shape or not np.allclose(mine, theirs, atol=1e-6):
            raise ValueError(
                f"the images' grid along {d!r}, extracted with upsample="
                f"{params.upsample}, is not the phase's grid; pass the tagged "
                "images the phase was extracted from"
            )
    dims = ("tag", "time", *GRID_DIMS)
    out[live] = _complex(harmonic["magnitude"].transpose(*dims).values,
                         harmonic["phase"].transpose(*dims).values)  # fmt: skip
    return out


def _complex(magnitude: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``magnitude · exp(i angle)`` in single precision."""
    out = np.empty(magnitude.shape, dtype=np.complex64)
    out.real = np.cos(angle, dtype=np.float32)
    out.imag = np.sin(angle, dtype=np.float32)
    out *= magnitude.astype(np.float32, copy=False)
    return out


def frame_harmonic(phase: xr.Dataset, n: int) -> np.ndarray:
    """The complex harmonic image of frame ``n``.

    Parameters
    ----------
    phase : xarray.Dataset
        A ``phase/1`` dataset (its ``magnitude`` and ``phase``).
    n : int
        Index of the frame along ``time``.

    Returns
    -------
    ndarray of complex64, shape (ntag, nz, ny, nx)
        ``magnitude · exp(i phase)`` of the frame.
    """
    frame = phase.isel(time=n)
    dims = ("tag", *GRID_DIMS)
    return _complex(frame["magnitude"].transpose(*dims).values,
                    frame["phase"].transpose(*dims).values)  # fmt: skip


def perturbed_phases(
    phase: xr.Dataset, harmonic: np.ndarray, fields: np.ndarray, points: FloatArray,
    baseline: FloatArray, order: int,
) -> FloatArray:  # fmt: skip
    """Phase change W(arg(H + h) − arg H) at ``points`` for each noise field, sampled as the
    tracker samples.

    The samples are stacked as further tags of one image, so that one sampler locates the
    points once for all of them.

    Parameters
    ----------
    phase : xarray.Dataset
        The ``phase/1`` dataset ``harmonic`` comes from (its tags, grid and ``mask``).
    harmonic : ndarray of complex, shape (ntag, nz, ny, nx)
        Harmonic image H of one frame (:func:`frame_harmonic`).
    fields : ndarray of complex, shape (ntag, count, nz, ny, nx)
        Harmonic noise h (:func:`harmonic_fields`), in the units of ``harmonic``.
    points : ndarray, shape (n, 3)
        Positions (x, y, z) at which to sample, mm.
    baseline : ndarray, shape (n, ntag)
        arg H at ``points``, rad, as the tracker's sampler gives it.
    order : int
        Spline order of the sampler (:class:`~harpx.imaging.sample.PhaseSampler`).

    Returns
    -------
    ndarray, shape (count, n, ntag)
        Phase change of each noise field, rad (0 where the perturbed image is not valid).
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
