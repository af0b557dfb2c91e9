"""Shared pieces of the synthetic scenes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import xarray as xr
from numpy.typing import ArrayLike

from harpx.imaging.stacks import tagged_dataset


def cspamm_dataset(
    image: ArrayLike,
    mask: ArrayLike,
    truth: ArrayLike,
    attrs: dict[str, Any],
    snr: float | None,
    *,
    tag: Sequence[str],
    tag_period: float,
    slice_axis: Sequence[str],
    times: ArrayLike,
    grid: tuple[ArrayLike, ArrayLike, ArrayLike],
    body: ArrayLike,
) -> xr.Dataset:
    """The ``tagged/1`` dataset of a CSPAMM scene resampled to the grid ``(z, y, x)``, mm.

    ``truth`` is the true displacement (mm), ``body`` the body density on the grid; ``attrs``
    gains ``snr`` when one is given (``None``: noise-free).
    """
    if snr is not None:
        attrs["snr"] = float(snr)
    z, y, x = grid
    return tagged_dataset(
        image,
        tag=list(tag),
        tag_frequency=1.0 / tag_period,
        slice_axis=list(slice_axis),
        time=times,
        z=z,
        y=y,
        x=x,
        sequence="CSPAMM",
        mask=mask,
        body=body,
        displacement_true=truth,
        attrs=attrs,
    )
