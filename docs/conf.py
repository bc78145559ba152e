"""Sphinx configuration of windrig's documentation site (``make docs``).

Sphinx rather than MkDocs: every public name carries a numpydoc docstring, and numpydoc is
written for Sphinx (its sections render as the reference tables readers of numpy and scipy know);
MyST lets the guides stay in Markdown, readable on the repository's web view as well. The API
reference is not typed: :mod:`docs._apiref` writes one page per public module of daq, ident and
simulators before each build (``reference/api/``, not committed), and ``tests/test_docs.py``
checks that none is missing.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))

import _apiref  # noqa: E402 - after the path it lives on

project = "windrig"
author = "the windrig developers"
copyright = "2026, the windrig developers"  # noqa: A001 - Sphinx's name

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinxarg.ext",
]

source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "examples", "Thumbs.db", ".DS_Store"]
html_theme = "furo"
html_title = "windrig"
html_static_path: list[str] = []

myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
myst_heading_anchors = 3

# Each public module's page documents the names defined there (_apiref.reexported_names).
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types and units
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False


def setup(app):  # noqa: ANN001, ANN201 - Sphinx's hook
    """Write the API pages before each build (:func:`_apiref.write_pages`)."""
    app.connect("builder-inited", lambda app: _apiref.write_pages(HERE / "reference" / "api"))
