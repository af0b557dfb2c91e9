"""Root pytest configuration: seeded RNG and doctest namespace."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")


@pytest.fixture
def rng() -> np.random.Generator:
    """A seeded random generator; every random draw in the tests goes through it."""
    return np.random.default_rng(20261123)


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace: dict) -> None:
    import xarray as xr

    import harpx

    doctest_namespace["np"] = np
    doctest_namespace["xr"] = xr
    doctest_namespace["harpx"] = harpx


def _shared_builds(module_name: str, name: str) -> None:
    """Build each small scene once per test session and hand every caller its own copy.

    Tests and tutorials build the same deterministic scenes (the small LV in its tests and in
    tutorials 02 and 04; the small tongue in its tests and tutorial 03); building is most of
    their cost. Wrapping the builder here, before any test module imports it, lets them share
    one build; each call still gets a deep copy, so no test sees another's changes, and
    anything unhashable or raising goes straight to the real builder.
    """
    import copy
    import functools
    import importlib
    import inspect

    module = importlib.import_module(module_name)
    build = getattr(module, name)
    built: dict = {}

    @functools.wraps(build)
    def shared(*args, **kwargs):
        try:
            bound = inspect.signature(build).bind(*args, **kwargs)
            bound.apply_defaults()
            key = tuple(bound.arguments.items())
            hash(key)
        except TypeError:
            return build(*args, **kwargs)
        if key not in built:
            built[key] = build(*args, **kwargs)
        return copy.deepcopy(built[key])

    setattr(module, name, shared)


_shared_builds("harpx.scenes.lv", "lv")
_shared_builds("harpx.scenes.tongue", "tongue")
