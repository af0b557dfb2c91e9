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

# The tutorials are jupytext percent-format scripts in tutorials/. The guide shows their
# executed copies, docs/tutorials/*.ipynb, with outputs and figures as stored: nothing runs
# here. tests/test_tutorials.py writes those copies from the one run the CI makes of each
# tutorial, and tests/test_docs.py fails when a copy's cells differ from its tutorial.
nb_execution_mode = "off"
nb_merge_streams = True
myst_enable_extensions = ["dollarmath"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
exclude_patterns = ["_build", "conf.py"]

autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"  # the numpydoc sections state the types
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

html_theme = "alabaster"
html_theme_options = {
    "description": "tagged MRI motion estimation",
    "fixed_sidebar": True,
    "page_width": "1200px",  # a 100-character code line fits beside the sidebar
}
# only the style sheet: the gallery's images (docs/_static/gallery) are copied as images
html_static_path = ["_static/harpx.css"]
html_css_files = ["harpx.css"]

# numpydoc renames the citations of each "References" section; docstrings that list
# references without citing them in the text would otherwise warn.
suppress_warnings = ["ref.citation"]

# Every documented object states its contract: each parameter named, typed and described
# (the signatures carry no types here, see autodoc_typehints), a Returns section with a
# description where something is returned, sections in numpydoc order. With -W (make docs,
# the CI) a docstring that drifts from its signature fails the build.
numpydoc_validation_checks = {
    "GL07",  # sections in the wrong order
    "GL08",  # no docstring
    "PR01",  # a parameter is not documented
    "PR02",  # a documented parameter is not in the signature
    "PR03",  # parameters documented in another order than the signature's
    "PR04",  # a parameter has no type
    "PR07",  # a parameter has no description
    "PR10",  # "a: int" without the space before the colon
    "RT01",  # no Returns section
    "RT03",  # a return value has no description
    "YD01",  # no Yields section
}
# A class that lists its fields under "Attributes" is a result that harpx builds; its
# constructor is not a user contract. Exempt from every check: the ds.harp methods on the
# class, pointers to the functions they forward to (on a dataset they carry the function's
# whole docstring), type aliases, which are described by their "#:" comment, and protocols,
# which are never constructed.
numpydoc_validation_overrides = {"PR01": [r"\nAttributes\n----------\n"]}
numpydoc_validation_exclude = {
    r"^harpx\.accessor\.(HarpAccessor|PlotMethods)\.\w+$",
    r"^harpx\.(imaging\.motion\.Motion|mechanics\.cells\.(ElementName|Volumetric))$",
    r"^harpx\.mechanics\.krylov\.Measure$",
    r"^harpx\.mechanics\.loads\.(ResidualTerm|Dirichlet)$",
}
