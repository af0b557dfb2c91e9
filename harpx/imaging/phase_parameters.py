"""The settings a ``phase/1`` dataset was extracted with, read in one place.

:func:`harpx.imaging.harp.extract_phase` records in the dataset's attributes how it filtered
and interpolated the tagged images: ``sequence``, ``upsample``, ``radius``, ``bandpass`` and
``upsample_factors``. Whatever later depends on them (the tracker's quadrature and blur
correction, the image-fit check, the noise propagation of the uncertainty) reads them
through :meth:`PhaseParameters.from_dataset`, which checks them and fills the documented
defaults of a dataset that lacks them (a ``tagged/1`` dataset, or a phase written by
another tool).
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from harpx.conventions import SEQUENCES
from harpx.errors import HarpxWarning, SchemaError, user_stacklevel

__all__ = [
    "BANDPASS_DISK",
    "DEFAULT_RADIUS",
    "DEFAULT_UPSAMPLE",
    "SPAMM_MAX_RADIUS",
    "PhaseParameters",
    "spamm_dc_message",
    "warn_spamm_dc",
]

#: ``attrs["bandpass"]`` of a phase extracted with the disk band-pass of ``extract_phase``.
BANDPASS_DISK = "disk"
#: ``extract_phase``'s default in-plane upsampling factor (the command line's too)
DEFAULT_UPSAMPLE = 2
#: ``extract_phase``'s default band-pass radius, a fraction of the tag frequency (the
#: command line's too)
DEFAULT_RADIUS = 0.5
#: Largest band-pass radius (a fraction of the tag frequency) that SPAMM images are filtered
#: with without a warning. SPAMM keeps the tissue's untagged signal, a peak at zero
#: frequency that grows as the tags fade (T1); a disk of radius r around the tag peak comes
#: within (1 - r) of the tag frequency of it, and closer than a tenth its leakage swamps the
#: phase (``benchmarks/results/spamm_radius.md``).
SPAMM_MAX_RADIUS = 0.9


def spamm_dc_message(sequence: str, radius: float) -> str:
    """Why a phase of ``sequence`` images band-passed with ``radius`` is distorted, or "".

    Parameters
    ----------
    sequence : str
        ``"SPAMM"`` or ``"CSPAMM"`` (CSPAMM subtracts the zero-frequency peak: always "").
    radius : float
        Disk band-pass radius, a fraction of the tag frequency.

    Returns
    -------
    str
        For SPAMM above :data:`SPAMM_MAX_RADIUS`, a sentence naming the radius, how close
        the pass band comes to the zero-frequency peak and what to use instead; else "".
    """
    if sequence != "SPAMM" or radius <= SPAMM_MAX_RADIUS:
        return ""
    return (
        f"SPAMM images band-passed with radius={radius:g} (a fraction of the tag frequency): "
        f"the band reaches within {1.0 - radius:.2g} of the tag frequency of the "
        "zero-frequency peak (the untagged tissue signal, which SPAMM keeps and which grows "
        f"as the tags fade), whose leakage distorts the phase; use radius <= "
        f"{SPAMM_MAX_RADIUS:g} (the default {DEFAULT_RADIUS:g}), or CSPAMM images"
    )


@dataclass(frozen=True)
class PhaseParameters:
    """How the harmonic phase of a dataset was extracted (its attributes, checked).

    Attributes
    ----------
    sequence : {"SPAMM", "CSPAMM"}, default "CSPAMM"
        Tagging sequence of the images.
    upsample : int, default 1
        In-plane upsampling factor (1: the native grid, as for ``tagged/1`` images).
    radius : float, default 0.5
        Band-pass radius as a fraction of the tag frequency, in (0, 1]
        (``extract_phase``'s default).
    bandpass : str or None, default None
        The band-pass filter's kind, ``"disk"`` for ``extract_phase``; None where none is
        recorded (then no blur correction models it).
    upsample_factors : tuple of int, default (1, 1, 1)
        Refinement factor of each grid axis (z, y, x): every acquired voxel holds that many
        grid voxels along the axis.

    Examples
    --------
    >>> import xarray as xr
    >>> p = PhaseParameters.from_dataset(xr.Dataset(attrs={"upsample": 2, "radius": 0.4}))
    >>> p.upsample, p.radius, p.disk_bandpass
    (2, 0.4, False)
    """

    sequence: str = "CSPAMM"
    upsample: int = 1
    radius: float = 0.5
    bandpass: str | None = None
    upsample_factors: tuple[int, int, int] = (1, 1, 1)

    @property
    def disk_bandpass(self) -> bool:
        """Whether the phase went through ``extract_phase``'s disk band-pass."""
        return self.bandpass == BANDPASS_DISK

    @classmethod
    def from_dataset(cls, ds: xr.Dataset) -> PhaseParameters:
        """Read and check the extraction settings from ``ds.attrs``.

        Parameters
        ----------
        ds : xarray.Dataset
            A ``phase/1`` dataset (or ``tagged/1``: every setting at its default).

        Returns
        -------
        PhaseParameters
            The recorded settings, defaults (class attributes) where one is absent.

        Raises
        ------
        SchemaError
            Naming the attribute and its value: ``sequence`` not one of ``SEQUENCES``,
            ``upsample`` not a whole number ≥ 1, ``radius`` not in (0, 1], ``bandpass``
            not a string, ``upsample_factors`` not three whole numbers ≥ 1.
        """
        attrs = ds.attrs
        problems: list[str] = []
        sequence = attrs.get("sequence", cls.sequence)
        if not (isinstance(sequence, str) and sequence in SEQUENCES):
            problems.append(
                f"dataset attribute 'sequence' is {sequence!r}; expected one of {sorted(SEQUENCES)}"
            )
        upsample = attrs.get("upsample", cls.upsample)
        if not _whole(upsample):
            problems.append(
                f"dataset attribute 'upsample' is {upsample!r}; expected a whole number >= 1 "
                "(the upsampling extract_phase used)"
            )
        radius = attrs.get("radius", cls.radius)
        if not (_real(radius) and 0.0 < float(radius) <= 1.0):
            problems.append(
                f"dataset attribute 'radius' is {radius!r}; expected a number in (0, 1] (the "
                "band-pass radius extract_phase used, a fraction of the tag frequency)"
            )
        bandpass = attrs.get("bandpass", cls.bandpass)
        if bandpass is not None and not isinstance(bandpass, str):
            problems.append(f"dataset attribute 'bandpass' is {bandpass!r}; expected a string")
        factors = np.atleast_1d(np.asarray(attrs.get("upsample_factors", cls.upsample_factors)))
        if factors.shape != (3,) or not all(_whole(m) for m in factors.tolist()):
            problems.append(
                f"dataset attribute 'upsample_factors' is {attrs.get('upsample_factors')!r}; "
                "expected three whole numbers >= 1 (z, y, x)"
            )
        if problems:
            raise SchemaError(problems)
        z, y, x = (int(m) for m in factors.tolist())
        return cls(
            sequence=str(sequence),
            upsample=int(upsample),
            radius=float(radius),
            bandpass=None if bandpass is None else str(bandpass),
            upsample_factors=(z, y, x),
        )


def _real(value: Any) -> bool:
    """A finite real number (not a bool)."""
    real = isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
    return real and math.isfinite(float(value))


def _whole(value: Any) -> bool:
    """A real number that is a whole number >= 1."""
    return _real(value) and float(value) >= 1 and float(value) == int(value)


def warn_spamm_dc(phase: xr.Dataset, tracker: str) -> None:
    """Warn that ``tracker`` tracks from a SPAMM phase band-passed wider than
    :data:`SPAMM_MAX_RADIUS` (a phase archive made elsewhere, or before harpx warned).

    Parameters
    ----------
    phase : xarray.Dataset
        The ``phase/1`` dataset about to be tracked (its ``sequence``, ``radius`` and
        ``bandpass`` attributes are read).
    tracker : str
        Who tracks, for the message (e.g. ``"FE tracking"``).

    Warns
    -----
    HarpxWarning
        With :func:`spamm_dc_message`'s text; the tracked result records ``sequence`` and
        ``phase_radius``.
    """
    params = PhaseParameters.from_dataset(phase)
    message = spamm_dc_message(params.sequence, params.radius) if params.disk_bandpass else ""
    if message:
        warnings.warn(f"{tracker} from {message}", HarpxWarning, stacklevel=user_stacklevel())
