"""The ``ds.harp`` accessor: a thin layer that forwards to plain functions.

Every method is one call; the full documentation lives on the function it forwards to.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Literal

import xarray as xr

if TYPE_CHECKING:
    from pathlib import Path

    from numpy.typing import ArrayLike

    from harpx._typing import PathLike

from harpx.tracking.settings import TrackingSettings


def _plot(function: str, summary: str) -> Callable[..., Any]:
    """A :class:`PlotMethods` method: ``harpx.plotting.<function>(ds, **kwargs)``.

    The plotting package is imported at the first call (matplotlib stays unloaded until a
    picture is asked for); ``summary`` is the method's docstring before its pointer to the
    function.
    """

    def method(self: PlotMethods, **kwargs: Any) -> Any:
        import harpx.plotting

        return getattr(harpx.plotting, function)(self._ds, **kwargs)

    method.__doc__ = f"{summary} See Also: harpx.plotting.{function}."
    return method


class PlotMethods:
    """``ds.harp.plot``: matplotlib pictures of harpx datasets (see :mod:`harpx.plotting`).

    Each method forwards the dataset and its keywords to the plotting function named in its
    docstring (built by :func:`_plot`).
    """

    def __init__(self, ds: xr.Dataset) -> None:
        self._ds = ds

    tag_image = _plot("tag_image", "One slice of a tagged image.")
    phase = _plot("phase_map", "One slice of a harmonic phase.")
    displacement = _plot("displacement_map", "Tracked displacement on a slice.")
    strain = _plot(
        "strain_map",
        "Strain on a slice (radial, circumferential, longitudinal or Cartesian, %).",
    )
    fiber_stretch = _plot("fiber_stretch_by_region", "Fibre stretch per region.")
    bullseye = _plot("bullseye", "AHA 17-segment bull's-eye of a segment value.")
    segment_curves = _plot("segment_curves", "AHA segment strain over time by ring.")


@xr.register_dataset_accessor("harp")
class HarpAccessor:
    """harpx methods on an :class:`xarray.Dataset` (``ds.harp``)."""

    def __init__(self, ds: xr.Dataset) -> None:
        self._ds = ds

    @property
    def plot(self) -> PlotMethods:
        """Pictures: ``ds.harp.plot.tag_image()``, ``.phase()``, ``.displacement()``,
        ``.strain()``, ``.fiber_stretch()`` (see :mod:`harpx.plotting`)."""
        return PlotMethods(self._ds)

    def validate(self, kind: str | None = None) -> None:
        """Check the dataset against the harpx conventions.

        See Also
        --------
        harpx.schema.validate
        """
        from harpx.schema import validate

        return validate(self._ds, kind=kind)

    def phase(
        self,
        *,
        upsample: int = 2,
        radius: float = 0.5,
        threads: int | None = None,
        dtype: Literal["float32", "float64"] = "float32",
    ) -> xr.Dataset:
        """Harmonic phase of a ``tagged/1`` dataset.

        See Also
        --------
        harpx.imaging.harp.extract_phase
        """
        from harpx.imaging.harp import extract_phase

        return extract_phase(
            self._ds, upsample=upsample, radius=radius, threads=threads, dtype=dtype
        )

    def to_netcdf(self, path: PathLike) -> Path:
        """Write the dataset atomically to a NetCDF archive.

        See Also
        --------
        harpx.io.netcdf.to_netcdf
        """
        from harpx.io.netcdf import to_netcdf

        return to_netcdf(self._ds, path)

    def track(
        self,
        body: Any,
        *,
        settings: TrackingSettings | None = None,
        dirichlet: Sequence[Any] = (),
        terms: Sequence[Any] = (),
        **overrides: Any,
    ) -> xr.Dataset:
        """Track a finite-element body through the phase images.

        ``settings`` and the keyword ``overrides`` (any field of
        :class:`~harpx.tracking.settings.TrackingSettings`) are forwarded unchanged.

        See Also
        --------
        harpx.tracking.track.track
        """
        from harpx.tracking.track import track

        return track(
            self._ds, body, settings=settings, dirichlet=dirichlet, terms=terms, **overrides
        )

    def track_harp(
        self, *, points: ArrayLike | xr.Dataset | None = None, iterations: int = 10
    ) -> xr.Dataset:
        """Conventional HARP tracking (fixed-point phase matching per material point).

        See Also
        --------
        harpx.imaging.harptrack.track_harp
        """
        from harpx.imaging.harptrack import track_harp

        return track_harp(self._ds, points=points, iterations=iterations)

    def error(self, truth: xr.Dataset, *, where: xr.DataArray | None = None) -> xr.Dataset:
        """Displacement error of a tracked dataset against ground truth.

        See Also
        --------
        harpx.tracking.results.tracking_error
        """
        from harpx.tracking.results import tracking_error

        return tracking_error(self._ds, truth, where=where)

    def cardiac_strain(
        self,
        template: Any,
        *,
        anterior: float | None = None,
        body: xr.DataArray | None = None,
        min_coverage: float = 0.1,
        heart_size: tuple[float, float] = (20.0, 150.0),
    ) -> xr.Dataset:
        """LV-frame strain, AHA segments, twist and torsion.

        See Also
        --------
        harpx.cardiac.strain.cardiac_strain
        """
        from harpx.cardiac.strain import cardiac_strain

        return cardiac_strain(
            self._ds,
            template,
            anterior=anterior,
            body=body,
            min_coverage=min_coverage,
            heart_size=heart_size,
        )

    def to_meshio(self, path: PathLike, *, series: Literal["vtu", "xdmf"] = "xdmf") -> list[Path]:
        """Write a tracked result as a ParaView time series (XDMF, or VTU files and a PVD).

        See Also
        --------
        harpx.io.mesh.to_meshio
        """
        from harpx.io.mesh import to_meshio

        return to_meshio(self._ds, path, series=series)

    def uncertainty(
        self,
        body: Any,
        images: xr.Dataset,
        *,
        tagged: xr.Dataset | None = None,
        dirichlet: Sequence[Any] = (),
        terms: Sequence[Any] = (),
        samples: int = 64,
        seed: int | None = None,
        keep_samples: bool = False,
    ) -> xr.Dataset:
        """Standard deviation of a tracked displacement due to the image noise.

        See Also
        --------
        harpx.tracking.uncertainty.tracking_uncertainty
        harpx.cardiac.uncertainty.segment_uncertainty : the AHA segment measures from it.
        """
        from harpx.tracking.uncertainty import tracking_uncertainty

        return tracking_uncertainty(
            self._ds, body, images, tagged=tagged, dirichlet=dirichlet, terms=terms,
            samples=samples, seed=seed, keep_samples=keep_samples,
        )  # fmt: skip
