"""The tutorials, their executed copies in the user guide, and the gallery's figures.

Shared by tests/test_tutorials.py (which runs each tutorial in a Jupyter kernel and writes
what the guide shows) and tests/test_docs.py (which checks, without running anything, that
what the guide shows is current).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parents[1]
TUTORIALS = sorted((ROOT / "tutorials").glob("*.py"))
# executed copies of the tutorials (outputs and figures): the pages of the user guide
STORED = ROOT / "docs" / "tutorials"
GALLERY_PAGE = ROOT / "docs" / "gallery.md"
GALLERY_IMAGES = ROOT / "docs" / "_static" / "gallery"
# PNG text chunk of a gallery image: the code that drew it
SOURCE_KEY = "harpx gallery source"
# what `HARPX_WRITE_NOTEBOOKS=1 pytest tests/test_tutorials.py` refreshes
REFRESH = "HARPX_WRITE_NOTEBOOKS"


def stored_notebook(tutorial: Path) -> Path:
    """Where the guide keeps the executed copy of ``tutorial``."""
    return STORED / f"{tutorial.stem}.ipynb"


def read_tutorial(tutorial: Path):
    """The tutorial as a notebook (jupytext percent format)."""
    import jupytext

    return jupytext.reads(tutorial.read_text(), fmt="py:percent")


def cells(nb) -> list[tuple[str, str]]:
    """What a reader sees of the cells of a notebook: their kind and source."""
    return [(cell.cell_type, cell.source) for cell in nb.cells]


class GalleryEntry(NamedTuple):
    name: str  # the plotting function drawn; the image is _static/gallery/<name>.png
    tutorial: str  # the tutorial whose namespace the code runs in, e.g. "01_phantom.py"
    code: str  # the code shown on the page (without its first comment line)

    @property
    def image(self) -> Path:
        return GALLERY_IMAGES / f"{self.name}.png"


# a gallery entry: a python block whose first line names the tutorial, then the image
_ENTRY = re.compile(
    r"```python\n# with the data of tutorials/(?P<tutorial>\w+\.py)\n(?P<code>.*?)```\s*\n"
    r"!\[[^\]]*\]\(_static/gallery/(?P<name>\w+)\.png\)",
    flags=re.S,
)


def gallery_entries() -> list[GalleryEntry]:
    """The figures of docs/gallery.md, in page order."""
    text = GALLERY_PAGE.read_text()
    return [
        GalleryEntry(m["name"], m["tutorial"], m["code"].strip("\n")) for m in _ENTRY.finditer(text)
    ]


def gallery_image_source(path: Path) -> str | None:
    """The code a stored gallery image was drawn by (None if it records none)."""
    from PIL import Image

    with Image.open(path) as image:
        return image.text.get(SOURCE_KEY)  # type: ignore[attr-defined]
