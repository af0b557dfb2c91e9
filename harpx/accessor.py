"""The ``ds.harp`` accessor: a thin layer that forwards to plain functions.

Every method is one call; the full documentation lives on the function it forwards to.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import xarray as xr

if TYPE_CHECKING:
    from pathlib import Path

    from harpx._typing import PathLike


@xr.register_dataset_accessor("harp")
class HarpAccessor:
    """harpx methods on an :class:`xarray.Dataset` (``ds.harp``)."""

    def __init__(self, ds: xr.Dataset) -> None:
        self._ds = ds

    def validate(self, kind: str | None = None) -> None:
        """Check the dataset against the harpx conventions.

        See Also
        --------
        harpx.schema.validate
        """
        from harpx.schema import validate

        return validate(self._ds, kind=kind)

    def phase(
        self, *, upsample: int = 2, radius: float = 0.5, threads: int | None = None
    ) -> xr.Dataset:
        """Harmonic phase of a ``tagged/1`` dataset.

        See Also
        --------
        harpx.imaging.harp.extract_phase
        """
        from harpx.imaging.harp import extract_phase

        return extract_phase(self._ds, upsample=upsample, radius=radius, threads=threads)

    def to_netcdf(self, path: PathLike) -> Path:
        """Write the dataset atomically to a NetCDF archive.

        See Also
        --------
        harpx.io.netcdf.to_netcdf
        """
        from harpx.io.netcdf import to_netcdf

        return to_netcdf(self._ds, path)
