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
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from harpx.conventions import SEQUENCES
from harpx.errors import SchemaError

__all__ = ["BANDPASS_DISK", "DEFAULT_RADIUS", "DEFAULT_UPSAMPLE", "PhaseParameters"]

#: ``attrs["bandpass"]`` of a phase extracted with the disk band-pass of ``extract_phase``.
BANDPASS_DISK = "disk"
#: ``extract_phase``'s default in-plane upsampling factor (the command line's too)
DEFAULT_UPSAMPLE = 2
#: ``extract_phase``'s default band-pass radius, a fraction of the tag frequency (the
#: command line's too)
DEFAULT_RADIUS = 0.5


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
