"""Old import paths of harpx 0.1 still work for one release, each with a DeprecationWarning."""

from __future__ import annotations

import importlib
import sys

import pytest

import harpx  # noqa: F401  (installs the finder of the old paths)
from harpx._moved import MOVED_MODULES, MOVED_NAMES


@pytest.mark.parametrize(("old", "new"), sorted(MOVED_MODULES.items()))
def test_an_old_module_path_warns_and_gives_the_new_module(old, new):
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=new.replace(".", r"\.")):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    sys.modules.pop(old, None)
    parent, _, child = old.rpartition(".")
    vars(sys.modules[parent]).pop(child, None)  # the import bound it on the package


@pytest.mark.parametrize(("where", "new"), sorted(MOVED_NAMES.items()))
def test_an_old_name_warns_and_gives_the_new_object(where, new):
    package, name = where
    with pytest.warns(DeprecationWarning, match=name):
        value = getattr(importlib.import_module(package), name)
    assert value is getattr(importlib.import_module(new), name)


def test_a_name_that_never_existed_is_still_an_attribute_error():
    import harpx.mechanics

    with pytest.raises(AttributeError, match="no attribute 'frobnicate'"):
        harpx.mechanics.frobnicate  # noqa: B018


def test_the_new_paths_import_without_a_warning(recwarn):
    for new in sorted(set(MOVED_MODULES.values())):
        importlib.import_module(new)
    assert not [w for w in recwarn if issubclass(w.category, DeprecationWarning)]
