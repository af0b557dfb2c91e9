"""Old import paths of modules and names that moved, with a deprecation warning.

harpx 0.2 split the finite-element engine (:mod:`harpx.mechanics`) from the building of
anatomy (:mod:`harpx.anatomy`: segmentation mesher, ventricle and tongue templates, the
template fit) and the physiological experiments (:mod:`harpx.physiology`: active
contraction, growth, cuts). The old paths keep working for one release: importing one
emits a :class:`DeprecationWarning` naming the new path and returns the new module (the
same object, so ``isinstance`` checks and monkeypatching see one module).

Only harpx's own old names are intercepted (a finder on ``sys.meta_path`` that answers
for the names in :data:`MOVED_MODULES` and for nothing else).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Callable
from types import ModuleType
from typing import Any

#: old module path -> new module path
MOVED_MODULES: dict[str, str] = {
    "harpx.mechanics.segmentation": "harpx.anatomy.segmentation",
    "harpx.mechanics.ventricle": "harpx.anatomy.ventricle",
    "harpx.mechanics.ventricle_fit": "harpx.anatomy.ventricle_fit",
    "harpx.mechanics.tongue_mesh": "harpx.anatomy.tongue_mesh",
    "harpx.mechanics.active": "harpx.physiology.active",
    "harpx.mechanics.growth": "harpx.physiology.growth",
    "harpx.mechanics.cut": "harpx.physiology.cut",
}

#: (old module, name) -> new module that defines the name (names the old module still
#: imports for its own use, such as ``ELEMENTS`` in ``harpx.mechanics.body``, resolve there
#: without a warning)
MOVED_NAMES: dict[tuple[str, str], str] = {
    ("harpx.mechanics", "ventricle"): "harpx.anatomy.ventricle",
    ("harpx.mechanics", "cavity_volume"): "harpx.anatomy.ventricle",
    ("harpx.mechanics.body", "check_fits_image"): "harpx.tracking.image_fit",
    ("harpx.mechanics.body", "ElementKind"): "harpx.mechanics.cells",
    ("harpx.mechanics.body", "curved_tet_mesh"): "harpx.mechanics.cells",
    ("harpx.mechanics.materials", "ActiveContraction"): "harpx.mechanics.fiber_laws",
    ("harpx.mechanics.materials", "FiberGrowth"): "harpx.mechanics.fiber_laws",
    ("harpx.inverse", "simulate_activation"): "harpx.physiology.active",
    ("harpx.inverse", "simulate_history"): "harpx.physiology.active",
}


def _warn(old: str, new: str) -> None:
    warnings.warn(
        f"{old} moved to {new} in harpx 0.2; import it from there (the old path will be "
        "removed in harpx 0.3)",
        DeprecationWarning,
        stacklevel=3,
    )


def moved_attribute(package: str, name: str) -> Any:
    """The moved ``package.name`` from its new module, with a deprecation warning.

    Raises
    ------
    AttributeError
        If ``name`` never lived in ``package`` (the usual error of a missing attribute).
    """
    new = MOVED_NAMES.get((package, name))
    if new is None:
        raise AttributeError(f"module {package!r} has no attribute {name!r}")
    _warn(f"{package}.{name}", f"{new}.{name}")
    return getattr(importlib.import_module(new), name)


def moved_getattr(package: str) -> Callable[[str], Any]:
    """A module ``__getattr__`` that answers the moved names of ``package``.

    ``__getattr__ = moved_getattr(__name__)`` at the end of a module that lost names
    resolves each of them through :func:`moved_attribute` (with its warning and its
    :class:`AttributeError` for a name that never lived there).
    """

    def __getattr__(name: str) -> Any:
        return moved_attribute(package, name)

    return __getattr__


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Answers the imports of the old module paths with the new modules."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> Any:
        if fullname not in MOVED_MODULES:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return None

    def exec_module(self, module: ModuleType) -> None:
        new = MOVED_MODULES[module.__name__]
        _warn(module.__name__, new)
        sys.modules[module.__name__] = importlib.import_module(new)


def install() -> None:
    """Register the finder of the old module paths (once per interpreter)."""
    if not any(isinstance(f, _Alias) for f in sys.meta_path):
        sys.meta_path.append(_Alias())
