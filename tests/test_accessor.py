"""The ds.harp accessor: thin, cached, documented, and in step with the functions it forwards to."""

from __future__ import annotations

import inspect
import pickle
import subprocess
import sys

import pytest
import xarray as xr

import harpx  # noqa: F401  (registers ds.harp)
from harpx import plotting
from harpx.accessor import Forward, HarpAccessor, PlotMethods
from harpx.cardiac.strain import cardiac_strain
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.io.mesh import to_meshio
from harpx.io.netcdf import to_netcdf
from harpx.schema import validate
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track
from harpx.tracking.uncertainty import tracking_uncertainty

FORWARDS = [
    pytest.param("validate", validate, id="validate"),
    pytest.param("phase", extract_phase, id="phase"),
    pytest.param("track", track, id="track"),
    pytest.param("track_harp", track_harp, id="track_harp"),
    pytest.param("error", tracking_error, id="error"),
    pytest.param("to_netcdf", to_netcdf, id="to_netcdf"),
    pytest.param("to_meshio", to_meshio, id="to_meshio"),
    pytest.param("cardiac_strain", cardiac_strain, id="cardiac_strain"),
    pytest.param("uncertainty", tracking_uncertainty, id="uncertainty"),
]
PLOTS = [
    pytest.param("tag_image", plotting.tag_image, id="tag_image"),
    pytest.param("phase", plotting.phase_map, id="phase"),
    pytest.param("displacement", plotting.displacement_map, id="displacement"),
    pytest.param("strain", plotting.strain_map, id="strain"),
    pytest.param("fiber_stretch", plotting.fiber_stretch_by_region, id="fiber_stretch"),
    pytest.param("bullseye", plotting.bullseye, id="bullseye"),
    pytest.param("segment_curves", plotting.segment_curves, id="segment_curves"),
]


def _public_methods(cls):
    return {n for n, v in vars(cls).items() if isinstance(v, Forward)}


def test_every_method_is_checked_here():
    # A method added to the accessor without a row above would escape the checks below.
    assert _public_methods(HarpAccessor) == {p.values[0] for p in FORWARDS}
    assert _public_methods(PlotMethods) == {p.values[0] for p in PLOTS}


def _rest(callable_):
    return [str(p) for p in list(inspect.signature(callable_).parameters.values())[1:]]


@pytest.mark.parametrize(("method", "function"), FORWARDS)
def test_method_on_a_dataset_is_the_function_without_its_dataset(method, function):
    bound = getattr(xr.Dataset().harp, method)
    assert [str(p) for p in inspect.signature(bound).parameters.values()] == _rest(function)
    assert bound.__doc__ == function.__doc__  # the whole contract, for help() and "?"
    assert bound.__name__ == function.__name__


@pytest.mark.parametrize(("method", "function"), FORWARDS)
def test_method_on_the_class_points_to_the_function(method, function):
    unbound = getattr(HarpAccessor, method)
    assert list(inspect.signature(unbound).parameters)[0] == "self"
    assert _rest(unbound) == _rest(function)
    assert f"{function.__module__}.{function.__name__}" in unbound.__doc__
    assert unbound.__doc__.startswith(inspect.getdoc(function).split("\n\n")[0])


@pytest.mark.parametrize(("method", "function"), PLOTS)
def test_plot_method_on_a_dataset_is_the_function_without_its_dataset(method, function):
    bound = getattr(xr.Dataset().harp.plot, method)
    assert [str(p) for p in inspect.signature(bound).parameters.values()] == _rest(function)
    assert bound.__doc__ == function.__doc__


def test_method_passes_the_dataset_and_the_arguments(monkeypatch):
    seen = {}

    def fake(ds, *args, **kwargs):
        seen.update(ds=ds, args=args, kwargs=kwargs)
        return "result"

    import harpx.schema

    monkeypatch.setattr(harpx.schema, "validate", fake)
    ds = xr.Dataset({"a": ("x", [1.0])})
    assert ds.harp.validate("tagged", extra=1) == "result"
    assert seen["ds"] is ds and seen["args"] == ("tagged",) and seen["kwargs"] == {"extra": 1}
    assert HarpAccessor.validate(ds.harp, kind="phase") == "result"
    assert seen["ds"] is ds and seen["kwargs"] == {"kind": "phase"}


def test_import_harpx_loads_no_heavy_module():
    # The methods import their modules at first use, so "import harpx" stays light.
    code = (
        "import sys, harpx, xarray as xr; xr.Dataset().harp; "
        "print(sorted(m for m in ('matplotlib', 'skfem', 'pyfftw', 'harpx.tracking.track') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_accessor_is_cached_and_pickles():
    ds = xr.Dataset({"a": ("x", [1.0, 2.0])})
    assert ds.harp is ds.harp
    assert isinstance(pickle.loads(pickle.dumps(ds)).harp, HarpAccessor)
    assert HarpAccessor.__doc__ and "harp" in xr.Dataset.harp.__doc__


def test_attribute_error_inside_the_accessor_surfaces_as_runtime_error(monkeypatch):
    # harpx's own accessor: an AttributeError while ds.harp is built must not pass for a
    # missing attribute (it would fall through to __getattr__ and say "no attribute 'harp'").
    # Fails if ds.harp is not registered through xarray's accessor machinery.
    def broken(self, ds):
        raise AttributeError("broken")

    monkeypatch.setattr(HarpAccessor, "__init__", broken)
    with pytest.raises(RuntimeError, match="error initializing 'harp' accessor") as info:
        _ = xr.Dataset().harp
    assert isinstance(info.value.__cause__, AttributeError)
