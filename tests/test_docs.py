"""The user guide stays true to the code; the package has one version and stands alone.

The guide itself is built with warnings as errors by ``make docs`` (run by .ci/run); these
checks are the fast part.
"""

from __future__ import annotations

import importlib.metadata
import re
import tomllib
from pathlib import Path

import harpx

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


def test_every_guide_page_and_tutorial_is_in_the_table_of_contents():
    index = (ROOT / "docs" / "index.md").read_text()
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} - {"index"}
    pages |= {f"tutorials/{p.stem}" for p in (ROOT / "tutorials").glob("*.py")}
    listed = set(re.findall(r"^([\w/]+)$", index, flags=re.M))
    assert pages - listed == set()
