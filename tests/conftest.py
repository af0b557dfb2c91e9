"""Fixtures shared across test packages."""

from __future__ import annotations

import pytest

from harpx.scenes.lv import lv


@pytest.fixture(scope="session")
def lv_small():
    """The reduced left-ventricle scene (5 frames, 2 mm pixels, a 456-cell tracking model and
    a 1539-cell truth), built once for the modules that track it (about 11 s)."""
    return lv(size="small", seed=0)
