"""The user guide stays true to the code; the package has one version and stands alone.

The guide itself is built with warnings as errors by ``make docs`` (run by .ci/run); these
checks are the fast part, including that the executed tutorials and the gallery figures the
guide shows are current (tests/test_tutorials.py writes them).
"""

from __future__ import annotations

import ast
import importlib
import importlib.metadata
import inspect
import pkgutil
import re
import textwrap
import tomllib
import types
from pathlib import Path

import nbformat

import harpx
from tests._notebooks import (
    GALLERY_IMAGES,
    GALLERY_PAGE,
    STORED,
    TUTORIALS,
    cells,
    gallery_entries,
    gallery_image_source,
    read_tutorial,
    stored_notebook,
)

ROOT = Path(__file__).resolve().parents[1]
SOURCE = "\n".join(p.read_text() for p in sorted((ROOT / "harpx").rglob("*.py")))


def test_troubleshooting_quotes_messages_harpx_really_raises():
    """Every quoted fragment in a heading of the troubleshooting page is in harpx's source."""
    page = (ROOT / "docs" / "troubleshooting.md").read_text()
    headings = [line for line in page.splitlines() if line.startswith("### ")]
    fragments = [f for line in headings for f in re.findall(r"`([^`]+)`", line)]
    assert len(fragments) >= 25
    assert [f for f in fragments if f not in SOURCE] == []


def test_the_version_is_written_once():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert importlib.metadata.version("harpx") == harpx.__version__
    assert len(re.findall(r"^__version__ = ", SOURCE, flags=re.M)) == 1


def test_no_docstring_cites_documents_outside_the_repository():
    assert re.findall(r"(?:DESIGN|REFERENCES)(?: §| section)", SOURCE) == []


def _public_names() -> list[tuple[types.ModuleType, str]]:
    """(module, name) of every name a public harpx module lists in ``__all__``."""
    found = []
    for info in pkgutil.walk_packages(harpx.__path__, "harpx."):
        if any(part.startswith("_") for part in info.name.split(".")[1:]):
            continue
        module = importlib.import_module(info.name)
        found += [(module, name) for name in getattr(module, "__all__", [])]
    return found


def _public_functions() -> list[tuple[str, object]]:
    """(dotted name, function) of every function a public harpx module lists in ``__all__``."""
    found = []
    for module, name in _public_names():
        obj = getattr(module, name)
        if inspect.isfunction(obj) and obj.__module__ == module.__name__:
            found.append((f"{module.__name__}.{name}", obj))
    return found


def _public_methods() -> list[tuple[str, object, str | None]]:
    """(name, method, docstring) of the public methods of the public classes; a
    constructor's contract is its class's docstring. Protocols are never constructed."""
    found = []
    for module, name in _public_names():
        cls = getattr(module, name)
        if not inspect.isclass(cls) or cls.__module__ != module.__name__:
            continue
        if getattr(cls, "_is_protocol", False):
            continue
        for attr, member in vars(cls).items():
            constructor = attr in ("__init__", "__post_init__")
            if attr.startswith("_") and not constructor:
                continue
            method = getattr(member, "__func__", getattr(member, "fget", member))
            # a dataclass's generated __init__ has no source (its checks are in
            # __post_init__)
            if inspect.isfunction(method) and method.__code__.co_filename != "<string>":
                doc = inspect.getdoc(cls if constructor else method)
                found.append((f"{module.__name__}.{name}.{attr}", method, doc))
    return found


def test_a_public_function_or_method_that_raises_documents_it():
    """A ``raise`` in a public function's or method's own body has a Raises section.

    numpydoc's validation (docs/conf.py, run by ``make docs``) checks parameters and
    returns, not exceptions; this is the check for those. Exceptions raised in helpers the
    function calls are not seen here.
    """
    functions = [(n, f, inspect.getdoc(f)) for n, f in _public_functions()]
    methods = _public_methods()
    assert len(functions) > 200 and len(methods) > 140
    silent = []
    for name, function, doc in functions + methods:
        tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
        raises = any(isinstance(n, ast.Raise) and n.exc is not None for n in ast.walk(tree))
        if raises and "\nRaises\n------\n" not in (doc or ""):
            silent.append(name)
    assert silent == []


def test_every_guide_page_and_tutorial_is_in_the_table_of_contents():
    index = (ROOT / "docs" / "index.md").read_text()
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} - {"index"}
    pages |= {f"tutorials/{p.stem}" for p in (ROOT / "tutorials").glob("*.py")}
    listed = set(re.findall(r"^([\w/]+)$", index, flags=re.M))
    assert pages - listed == set()


# functions of harpx.plotting that draw nothing, so have no figure in the gallery
NOT_DRAWINGS = {"segment_wedges"}
STALE = "stale: `pytest tests/test_tutorials.py -k {}` rewrites it; commit the result"


def test_the_guide_shows_each_tutorial_as_it_is_now():
    """The guide renders docs/tutorials/*.ipynb as stored: one executed copy per tutorial,
    whose cells are the tutorial's current ones, every code cell run, no error, figures."""
    assert sorted(p.name for p in STORED.iterdir()) == [f"{t.stem}.ipynb" for t in TUTORIALS]
    for tutorial in TUTORIALS:
        path = stored_notebook(tutorial)
        nb = nbformat.read(path, as_version=4)
        assert cells(nb) == cells(read_tutorial(tutorial)), STALE.format(tutorial.stem)
        code = [cell for cell in nb.cells if cell.cell_type == "code" and cell.source.strip()]
        assert all(cell.execution_count for cell in code), STALE.format(tutorial.stem)
        outputs = [output for cell in code for output in cell.outputs]
        assert [o for o in outputs if o.output_type == "error"] == []
        assert any("image/png" in o.get("data", {}) for o in outputs)
        # figures at 80 dpi (tests/test_tutorials.py): the largest copy is about 220 kB
        assert path.stat().st_size < 400_000, f"{path.name}: {path.stat().st_size} bytes"


def test_the_gallery_shows_every_plotting_function_drawn_by_its_code():
    """docs/gallery.md: one figure per drawing function of harpx.plotting, each image drawn
    by the code above it (tests/test_tutorials.py records that code in the PNG)."""
    import harpx.plotting

    entries = gallery_entries()
    names = [entry.name for entry in entries]
    assert len(names) == len(set(names))
    assert set(harpx.plotting.__all__) - NOT_DRAWINGS - set(names) == set()
    assert len(re.findall(r"!\[", GALLERY_PAGE.read_text())) == len(entries)  # each parsed
    assert {entry.tutorial for entry in entries} <= {t.name for t in TUTORIALS}
    assert sorted(p.stem for p in GALLERY_IMAGES.glob("*.png")) == sorted(names)
    for entry in entries:
        assert entry.image.exists(), STALE.format(entry.tutorial.removesuffix(".py"))
        stale = STALE.format(entry.tutorial.removesuffix(".py"))
        assert gallery_image_source(entry.image) == entry.code, f"{entry.name}: {stale}"
        assert entry.image.stat().st_size < 100_000
