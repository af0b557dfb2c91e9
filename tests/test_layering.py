"""Dependencies point one way: imaging → tracking ← mechanics, then scenes/inverse, then cli."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "harpx"

# subpackage -> harpx subpackages it must never import
FORBIDDEN = {
    "imaging": {"mechanics", "tracking", "scenes", "inverse", "cli", "batch", "cardiac"},
    "mechanics": {"imaging", "tracking", "scenes", "inverse", "cli", "batch", "cardiac"},
    "tracking": {"scenes", "inverse", "cli", "batch", "cardiac"},
    "io": {"tracking", "scenes", "inverse", "cli", "batch", "cardiac"},
    "cardiac": {"scenes", "inverse", "cli", "batch"},
}


def _harpx_imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    found = set()
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                raise AssertionError(f"{path}: relative import (harpx uses absolute imports only)")
            names = [node.module or ""]
        for name in names:
            parts = name.split(".")
            if parts[0] == "harpx" and len(parts) > 1:
                found.add(parts[1])
    return found


@pytest.mark.parametrize("subpackage", sorted(FORBIDDEN))
def test_no_upstream_module_imports_downstream(subpackage):
    offenders = []
    for path in sorted((PACKAGE / subpackage).glob("*.py")):
        bad = _harpx_imports(path) & FORBIDDEN[subpackage]
        if bad:
            offenders.append(f"{path.name} imports harpx.{sorted(bad)}")
    assert not offenders, offenders
