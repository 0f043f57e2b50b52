"""Sphinx configuration of the raysim documentation site (``make docs``).

Pages: the Markdown files under docs/ (MyST); tutorials: the scripts in examples/, run at
every build by sphinx-gallery on small grids; API reference: autosummary over the raysim,
solver and hardware packages. Built with warnings as errors (``-W --keep-going``).
"""

from __future__ import annotations

import itertools
import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
os.environ.setdefault("MPLBACKEND", "Agg")

from raysim.version import __version__  # noqa: E402

project = "raysim"
author = "the raysim authors"
copyright = "the raysim authors, BSD-3-Clause"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx_gallery.gen_gallery",
]

root_doc = "index"
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
# sphinx-gallery's table of run times is written (docs/sg_execution_times.rst), not published
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "sg_execution_times.rst"]
myst_enable_extensions = ["dollarmath"]
myst_heading_anchors = 4
# links to files of the repository outside docs/ (scenes, benchmarks, the README) are plain
# references to the repository, not pages of the site
suppress_warnings = ["myst.xref_missing", "myst.header"]
# plain-text docstrings name fields such as ``n`` or ``x`` that several classes share; the
# reference would pick one at random, so none is linked (nitpicky stays off)
suppress_warnings += ["ref.python"]

html_theme = "furo"
html_title = f"raysim {release}"

autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True,
                           "ignore-module-all": True}  # a package documents its own names only
autodoc_typehints = "signature"
autodoc_mock_imports = ["torch", "jax"]
napoleon_numpy_docstring = True
napoleon_google_docstring = False

sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "tutorials",
    "filename_pattern": r"/plot_",
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("matplotlib",),
    "show_memory": False,
}


# --- docstrings -------------------------------------------------------------------------
# raysim's docstrings are plain text with ``literals`` (|E|^2, *args, indented lists), not
# reStructuredText. Each is shown as its first paragraph (the summary, inline markup
# escaped) and the rest verbatim in a literal block, so no docstring can break the build or
# render wrongly. Docstrings with numpydoc sections are left to napoleon, escaped inline.
_SPECIAL = re.compile(r"([\\|*`_\[\]<>])")
_SPECIAL_NUMPYDOC = re.compile(r"([|*])")  # roles such as :func:`x` stay live there
_LITERAL = re.compile(r"(``.+?``)")
_SECTION = re.compile(r"^\s*(Parameters|Returns|Yields|Raises|Attributes|Examples)\s*$")


def _escape(line: str, special: re.Pattern = _SPECIAL) -> str:
    """``line`` with reStructuredText's inline markup escaped outside ``literals``."""
    parts = _LITERAL.split(line)
    return "".join(p if i % 2 else special.sub(r"\\\1", p) for i, p in enumerate(parts))


def _numpydoc(lines: list[str]) -> bool:
    return any(_SECTION.match(a) and set(b.strip()) == {"-"} for a, b in itertools.pairwise(lines))


def plain_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    """Render a plain-text docstring safely (see above); edits ``lines`` in place."""
    if not lines:
        return
    if _numpydoc(lines):
        lines[:] = [_escape(line, _SPECIAL_NUMPYDOC) for line in lines]
        return
    end = next((i for i, line in enumerate(lines) if not line.strip()), len(lines))
    summary = [_escape(line.strip()) for line in lines[:end]]
    rest = lines[end:]
    while rest and not rest[0].strip():
        rest = rest[1:]
    lines[:] = summary + ([ "", "::", ""] + ["    " + line for line in rest] if rest else [])


def setup(app):
    app.connect("autodoc-process-docstring", plain_docstring, priority=100)
