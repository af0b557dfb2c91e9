"""Imaging: synthetic tagged MRI, harmonic phase, wrap-safe phase sampling, conventional HARP.

Public names are loaded on first use so that importing one submodule (e.g.
:mod:`harpx.imaging.fft`) stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY: dict[str, str] = {
    "extract_phase": "harpx.imaging.harp",
    "refinement_factors": "harpx.imaging.harp",
    "synthesize_tagged": "harpx.imaging.synth",
    "invert_motion": "harpx.imaging.motion",
    "gridded_displacement": "harpx.imaging.motion",
    "PhaseSampler": "harpx.imaging.sample",
    "track_harp": "harpx.imaging.harptrack",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'harpx.imaging' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


def __dir__() -> list[str]:
    return sorted(__all__)
