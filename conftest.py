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
