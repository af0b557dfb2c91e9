"""The ``ds.harp`` accessor: a thin layer that forwards to plain functions.

Every method is one call, ``function(ds, ...)``, built by :class:`Forward` from a table of
names: nothing of the function's signature or defaults is copied here. On a dataset, the
method carries the function's own signature (without the dataset) and its whole docstring,
so ``ds.harp.track?`` in a notebook shows the full contract and tab completion offers the
function's keywords.
"""

from __future__ import annotations

import functools
import importlib
import inspect
from collections.abc import Callable
from typing import Any

import xarray as xr

__all__ = ["Forward", "HarpAccessor", "PlotMethods"]


class Forward:
    """A method that calls ``<module>.<function>(ds, *args, **kwargs)`` on its dataset.

    The module is imported at the first use of the method, so that ``import harpx`` stays
    light (matplotlib, scikit-fem and pyfftw load when a method needs them).

    Parameters
    ----------
    target : str
        ``"package.module.function"``; the function takes the dataset as its first
        positional argument.

    Notes
    -----
    Read from a dataset's accessor (``ds.harp.phase``), the method is bound to the dataset
    and carries the function's name, docstring and signature without its first parameter.
    Read from the class (``HarpAccessor.phase``, as the API reference does), it is an
    unbound method ``(self, ...)`` whose docstring is the function's summary line and a
    pointer to it.
    """

    def __init__(self, target: str) -> None:
        self.target = target
        self.name = target.rpartition(".")[2]

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def function(self) -> Callable[..., Any]:
        """The function forwarded to (importing its module).

        Returns
        -------
        callable
            ``<module>.<function>`` of :attr:`target`.
        """
        module, _, function = self.target.rpartition(".")
        found: Callable[..., Any] = getattr(importlib.import_module(module), function)
        return found

    def __get__(self, instance: Any, owner: type | None = None) -> Callable[..., Any]:
        target = self.function()
        signature = inspect.signature(target)
        rest = list(signature.parameters.values())[1:]
        if instance is None:
            return self._unbound(target, signature, rest)
        ds = instance._ds

        @functools.wraps(target)
        def method(*args: Any, **kwargs: Any) -> Any:
            return target(ds, *args, **kwargs)

        method.__signature__ = signature.replace(parameters=rest)  # type: ignore[attr-defined]
        return method

    def _unbound(
        self, target: Callable[..., Any], signature: inspect.Signature, rest: list[Any]
    ) -> Callable[..., Any]:
        def method(self: Any, *args: Any, **kwargs: Any) -> Any:
            return target(self._ds, *args, **kwargs)

        summary = (inspect.getdoc(target) or "").split("\n\n")[0]
        method.__name__ = method.__qualname__ = self.name
        method.__doc__ = f"{summary}\n\nSee Also\n--------\n{self.target}\n"
        first = inspect.Parameter("self", inspect.Parameter.POSITIONAL_ONLY)
        method.__signature__ = signature.replace(  # type: ignore[attr-defined]
            parameters=[first, *rest]
        )
        return method


class PlotMethods:
    """``ds.harp.plot``: matplotlib pictures of harpx datasets (see :mod:`harpx.plotting`).

    Each method forwards the dataset and its keywords to the plotting function named in its
    docstring. The plotting package is imported at the first call, so matplotlib stays
    unloaded until a picture is asked for.

    Parameters
    ----------
    ds : xarray.Dataset
        The dataset to draw (a ``tagged/1``, ``phase/1`` or ``tracked/1`` dataset, as each
        picture needs).
    """

    def __init__(self, ds: xr.Dataset) -> None:
        self._ds = ds

    tag_image = Forward("harpx.plotting.tag_image")
    phase = Forward("harpx.plotting.phase_map")
    displacement = Forward("harpx.plotting.displacement_map")
    strain = Forward("harpx.plotting.strain_map")
    fiber_stretch = Forward("harpx.plotting.fiber_stretch_by_region")
    bullseye = Forward("harpx.plotting.bullseye")
    segment_curves = Forward("harpx.plotting.segment_curves")


@xr.register_dataset_accessor("harp")
class HarpAccessor:
    """harpx methods on an :class:`xarray.Dataset` (``ds.harp``).

    Each method forwards the dataset to the function named in its docstring; on a dataset,
    ``help(ds.harp.track)`` shows that function's whole documentation.

    Parameters
    ----------
    ds : xarray.Dataset
        The dataset the methods act on (xarray passes it when ``ds.harp`` is first read).
    """

    def __init__(self, ds: xr.Dataset) -> None:
        self._ds = ds

    @property
    def plot(self) -> PlotMethods:
        """Pictures: ``ds.harp.plot.tag_image()``, ``.phase()``, ``.displacement()``,
        ``.strain()``, ``.fiber_stretch()``, ``.bullseye()``, ``.segment_curves()`` (see
        :mod:`harpx.plotting`)."""
        return PlotMethods(self._ds)

    validate = Forward("harpx.schema.validate")
    phase = Forward("harpx.imaging.harp.extract_phase")
    to_netcdf = Forward("harpx.io.netcdf.to_netcdf")
    track = Forward("harpx.tracking.track.track")
    track_harp = Forward("harpx.imaging.harptrack.track_harp")
    error = Forward("harpx.tracking.results.tracking_error")
    cardiac_strain = Forward("harpx.cardiac.strain.cardiac_strain")
    to_meshio = Forward("harpx.io.mesh.to_meshio")
    uncertainty = Forward("harpx.tracking.uncertainty.tracking_uncertainty")
