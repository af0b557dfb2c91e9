"""Dependencies point one way, for every subpackage and top-level module of harpx.

    _typing, _blas, errors, conventions,    foundation (no harpx imports above it)
    schema, _moved
    imaging        mechanics                independent of each other (mechanics: the FE engine)
    physiology                              experiments on the engine (activation, growth, cuts)
    tracking                                joins images and engine (images pull the mechanics)
    io                                      files in and out
    anatomy                                 models from images and templates (reads labels)
    scenes, inverse, plotting, batch        built on the layers below
    accessor, cli (its printing: cli_output) on top

Each unit may import only the units listed for it in ``ALLOWED`` (an AST scan of every
import, including those inside functions and ``TYPE_CHECKING`` blocks); a new unit without
a rule fails the test until its place is decided.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "harpx"

FOUNDATION = {"_typing", "_blas", "errors", "conventions", "schema", "_progress", "_moved"}
# unit -> the harpx units it may import
ALLOWED: dict[str, set[str]] = {
    "_typing": set(),
    "_blas": set(),
    "_progress": set(),
    "_moved": set(),
    "errors": set(),
    "conventions": {"_typing", "errors"},
    "schema": {"_typing", "errors", "conventions"},
    "imaging": FOUNDATION,
    "mechanics": FOUNDATION,
    "physiology": FOUNDATION | {"mechanics"},
    "tracking": FOUNDATION | {"imaging", "mechanics"},
    "io": FOUNDATION | {"imaging", "mechanics", "tracking"},
    "anatomy": FOUNDATION | {"mechanics", "physiology", "io"},
    "scenes": FOUNDATION | {"imaging", "mechanics", "physiology", "anatomy", "tracking"},
    "inverse": FOUNDATION | {"imaging", "mechanics", "physiology", "tracking"},
    "cardiac": FOUNDATION | {"imaging", "mechanics", "anatomy", "tracking", "io"},
    "plotting": FOUNDATION | {"cardiac"},
    "batch": FOUNDATION | {"imaging", "mechanics", "tracking", "io"},
    "accessor": FOUNDATION
    | {"imaging", "mechanics", "tracking", "io", "inverse", "plotting", "cardiac"},
    "cli": FOUNDATION
    | {"imaging", "mechanics", "tracking", "scenes", "inverse", "io", "plotting", "batch"}
    | {"accessor", "cardiac", "datasets", "cli_output"},
    "cli_output": FOUNDATION,
    "datasets": FOUNDATION | {"imaging", "mechanics", "tracking", "scenes", "io"},
    "__init__": FOUNDATION | {"accessor"},
    "__main__": {"cli"},
}


def _unit(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


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


MODULES = sorted(PACKAGE.rglob("*.py"))
UNITS = sorted({_unit(p) for p in MODULES})


def test_every_unit_has_a_rule():
    assert set(UNITS) <= set(ALLOWED), sorted(set(UNITS) - set(ALLOWED))


@pytest.mark.parametrize("unit", UNITS)
def test_no_unit_imports_above_itself(unit):
    offenders = []
    for path in MODULES:
        if _unit(path) != unit:
            continue
        bad = _harpx_imports(path) - ALLOWED.get(unit, set()) - {unit}
        if bad:
            offenders.append(f"{path.relative_to(PACKAGE)} imports harpx.{sorted(bad)}")
    assert not offenders, offenders


def test_the_scan_sees_a_forbidden_import(tmp_path):
    # the guard itself: a module importing upward is reported
    bad = tmp_path / "bad.py"
    bad.write_text("from harpx.tracking.track import track\nimport harpx.scenes.lv\n")
    assert _harpx_imports(bad) == {"tracking", "scenes"}


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def _module_graph() -> dict[str, set[str]]:
    """harpx module -> harpx modules it imports (submodules named in ``from a import b``
    count as imports of ``a.b``; package ``__init__`` files are left out as targets, since
    importing a submodule runs its package first by Python's rules, not by choice)."""
    names = {_module_name(p): p for p in MODULES}
    graph: dict[str, set[str]] = {}
    for name, path in names.items():
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module:
                found.add(node.module)
                found.update(f"{node.module}.{a.name}" for a in node.names)
        graph[name] = {m for m in found if m in names and m != name}
        graph[name] -= {m for m in graph[name] if names[m].name == "__init__.py"}
    return graph


def test_no_import_circle_between_modules():
    # Tarjan's strongly connected components: a component of more than one module is a circle
    graph = _module_graph()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not circles, circles


def test_the_circle_check_sees_a_circle(tmp_path, monkeypatch):
    # the guard itself: two modules importing each other form one component
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("from harpx.b import f\n")
    b.write_text("import harpx.a\n")
    monkeypatch.setattr(sys.modules[__name__], "PACKAGE", tmp_path / "harpx")
    (tmp_path / "harpx").mkdir()
    a.rename(tmp_path / "harpx" / "a.py")
    b.rename(tmp_path / "harpx" / "b.py")
    monkeypatch.setattr(sys.modules[__name__], "MODULES", sorted((tmp_path / "harpx").glob("*.py")))
    assert _module_graph() == {"harpx.a": {"harpx.b"}, "harpx.b": {"harpx.a"}}
