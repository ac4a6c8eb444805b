"""Sphinx configuration of the cogblocks documentation.

Build: ``python -m sphinx -W --keep-going -b html docs docs/_build/html``.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))
sys.path.insert(0, str(HERE.parent))

import cogblocks  # noqa: E402

project = "cogblocks"
author = "cogblocks developers"
release = version = cogblocks.__version__
copyright = "cogblocks developers"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "cogblocks_reference",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_ext", "Thumbs.db", ".DS_Store"]

# Internal links: a link to a missing page or anchor is a warning, and the build turns warnings into errors.
myst_heading_anchors = 4
myst_enable_extensions = ["dollarmath", "colon_fence"]
# Python-domain references that resolve to several re-exports of one object (``Signal`` is both
# ``cogblocks.Signal`` and ``cogblocks.sim.Signal``) pick one; that is not a broken link.
suppress_warnings = ["ref.python"]

autosummary_generate = False  # the reference pages are written by cogblocks_reference
autodoc_member_order = "bysource"
autodoc_inherit_docstrings = False  # inherited gymnasium/torch docstrings are not ours to format
autodoc_typehints = "description"
autodoc_default_options = {"undoc-members": False}
napoleon_numpy_docstring = True
napoleon_google_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = True  # attributes as fields, so a dataclass field is not described twice
napoleon_custom_sections = [("Ports", "params_style")]  # a block's ports, listed like its parameters

html_theme = "alabaster"
html_title = "cogblocks"


def setup(app):  # noqa: D103
    from pygments.lexers.special import TextLexer

    app.add_lexer("mermaid", TextLexer)  # diagrams drawn by `Diagram.to_mermaid()`, shown as text
