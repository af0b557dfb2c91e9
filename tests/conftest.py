"""Fixtures shared across test packages."""

from __future__ import annotations

import pytest

from harpx.scenes.lv import lv


@pytest.fixture(scope="session")
def lv_small():
    """The reduced left-ventricle scene (5 frames, 2 mm pixels, a 456-cell tracking model and
    a 1539-cell truth), built once for the modules that track it (about 11 s)."""
    return lv(size="small", seed=0)


@pytest.fixture(scope="session")
def lv_small_infarct():
    """The reduced left-ventricle scene with a hypokinetic infarct in segments 7, 8, 13 and
    14 (half the active tension), built once for the infarct and scanner-path tests."""
    return lv(size="small", infarct=(7, 8, 13, 14), scar_activation=0.5)
