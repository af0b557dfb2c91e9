"""The ds.harp accessor: thin, cached, documented, and in step with the functions it forwards to."""

from __future__ import annotations

import inspect
import pickle

import pytest
import xarray as xr

import harpx  # noqa: F401  (registers ds.harp)
from harpx.accessor import HarpAccessor
from harpx.cardiac.strain import cardiac_strain
from harpx.imaging.harp import extract_phase
from harpx.imaging.harptrack import track_harp
from harpx.io.mesh import to_meshio
from harpx.io.netcdf import to_netcdf
from harpx.schema import validate
from harpx.tracking.results import tracking_error
from harpx.tracking.track import track

FORWARDS = [
    pytest.param("validate", validate, id="validate"),
    pytest.param("phase", extract_phase, id="phase"),
    pytest.param("track", track, id="track"),
    pytest.param("track_harp", track_harp, id="track_harp"),
    pytest.param("error", tracking_error, id="error"),
    pytest.param("to_netcdf", to_netcdf, id="to_netcdf"),
    pytest.param("to_meshio", to_meshio, id="to_meshio"),
    pytest.param("cardiac_strain", cardiac_strain, id="cardiac_strain"),
]


@pytest.mark.parametrize(("method", "function"), FORWARDS)
def test_signature_matches_the_function_it_forwards_to(method, function):
    expected = list(inspect.signature(function).parameters.values())[1:]
    actual = list(inspect.signature(getattr(HarpAccessor, method)).parameters.values())[1:]
    assert [str(p) for p in actual] == [str(p) for p in expected]


@pytest.mark.parametrize(("method", "function"), FORWARDS)
def test_docstring_points_to_the_function(method, function):
    doc = getattr(HarpAccessor, method).__doc__
    assert f"{function.__module__}.{function.__name__}" in doc


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
