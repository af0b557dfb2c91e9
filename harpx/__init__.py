"""harpx: motion estimation from tagged cine MRI with hyperelastic finite-element models.

Importing harpx registers the ``ds.harp`` accessor on :class:`xarray.Dataset`. Public names
are loaded on first use so that ``import harpx`` stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

import harpx.accessor  # noqa: F401  (registers ds.harp)
from harpx._moved import install as _install_moved
from harpx.errors import (
    ArchiveError,
    ConvergenceError,
    ElementInversionError,
    HarpxError,
    HarpxWarning,
    SchemaError,
)

_install_moved()  # old module paths of harpx 0.1 still import, with a warning

__version__ = "0.1.0"  # the only place the version is written (pyproject reads it)

_LAZY: dict[str, str] = {
    "validate": "harpx.schema",
    "open_dataset": "harpx.io.netcdf",
    "to_netcdf": "harpx.io.netcdf",
    "extract_phase": "harpx.imaging.harp",
    "synthesize_tagged": "harpx.imaging.synth",
    "track_harp": "harpx.imaging.harptrack",
    "Body": "harpx.mechanics.body",
    "NeoHookean": "harpx.mechanics.materials",
    "Guccione": "harpx.mechanics.materials",
    "ActiveContraction": "harpx.mechanics.materials",
    "FiberGrowth": "harpx.mechanics.materials",
    "solve": "harpx.mechanics.newton",
    "track": "harpx.tracking.track",
    "TrackingSettings": "harpx.tracking.settings",
    "SolverTuning": "harpx.tracking.settings",
    "scenes": "harpx.scenes",
    "datasets": "harpx.datasets",
}

__all__ = [
    "ArchiveError",
    "ConvergenceError",
    "ElementInversionError",
    "HarpxError",
    "HarpxWarning",
    "SchemaError",
    "__version__",
    *_LAZY,
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'harpx' has no attribute {name!r}")
    mod = importlib.import_module(module)
    return mod if module.endswith(name) else getattr(mod, name)


def __dir__() -> list[str]:
    return sorted(__all__)
