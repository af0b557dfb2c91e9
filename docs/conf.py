"""Sphinx configuration of the harpx user guide and API reference (``make docs``)."""

from __future__ import annotations

import harpx

project = "harpx"
author = "harpx developers"
copyright = "2026, harpx developers"
release = version = harpx.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_nb",
]

# The tutorials are jupytext percent-format scripts (docs/tutorials links to ../tutorials);
# myst-nb reads them as notebooks. They are rendered without running them: the scenes take
# minutes on a small machine, and the tests run every tutorial anyway.
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:percent"}]}
nb_execution_mode = "off"
myst_enable_extensions = ["dollarmath"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".py": "myst-nb"}
exclude_patterns = ["_build", "conf.py"]

autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"  # the numpydoc sections state the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

html_theme = "alabaster"
html_theme_options = {"description": "tagged MRI motion estimation", "fixed_sidebar": True}
html_static_path: list[str] = []

# numpydoc renames the citations of each "References" section; docstrings that list
# references without citing them in the text would otherwise warn.
suppress_warnings = ["ref.citation"]
