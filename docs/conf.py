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

from sphinx.ext.napoleon import Config as NapoleonConfig  # noqa: E402
from sphinx.ext.napoleon import NumpyDocstring  # noqa: E402

from raysim.version import __version__  # noqa: E402

project = "raysim"
author = "the raysim authors"
copyright = "the raysim authors, BSD-3-Clause"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
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
# a role in a docstring whose name several modules define (:func:`load`) links to the first
# match, with a warning ("more than one target found") that is not shown; nitpicky stays off,
# so a role that resolves to nothing is shown as code
suppress_warnings += ["ref.python"]

html_theme = "furo"
html_title = f"raysim {release}"

autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True,
                           "ignore-module-all": True}  # a package documents its own names only
autodoc_typehints = "signature"
autodoc_mock_imports = ["torch", "jax"]
# numpydoc sections are parsed by napoleon's NumpyDocstring from plain_docstring below, for
# docstrings that have them only (napoleon as an extension would also parse every plain
# docstring, and read the text before a colon in an attribute's docstring as its type).
# raysim's entries read ``name : description (unit)``, not ``name : type``: what napoleon
# takes for a type is prose and must not become cross-references (the Python domain would
# link words such as "m" or "E" to unrelated attributes), so parameters are made name and
# description, and whatever napoleon still reads as a type (Returns) is emphasised text.
NAPOLEON = NapoleonConfig(napoleon_numpy_docstring=True, napoleon_google_docstring=False,
                          napoleon_use_param=False, napoleon_use_rtype=False,
                          napoleon_use_ivar=False, napoleon_preprocess_types=False,
                          napoleon_type_aliases=None)

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
# reStructuredText. Each is shown as its first paragraph (the summary, inline markup escaped
# except ``literals`` and roles such as :func:`x`, which stay live) and the rest verbatim in a
# literal block, where roles are written as their names, so no docstring can break the build
# or render wrongly. Docstrings with numpydoc sections go to napoleon (NAPOLEON), escaped inline
# (roles stay live there too), their parameters' "name : description" entries made name and
# description.
_ROLE = r":[a-z]+(?::[a-z]+)?:`[^`]+`"
_SPECIAL = re.compile(r"([\\|*`_\[\]<>])")
_SPECIAL_NUMPYDOC = re.compile(r"([|*])")
_LIVE = re.compile(rf"(``.+?``|{_ROLE})")
_ROLE_PARTS = re.compile(r":[a-z]+(?::[a-z]+)?:`(?:([^`<]*?)\s*<([^`>]+)>|([^`]+))`")
_SECTION = re.compile(r"^\s*(Parameters|Returns|Yields|Raises|Attributes|Examples)\s*$")
_ENTRY = re.compile(r"^(\s*)([^\s:][^:]*?) : (.+)$")


def _escape(line: str, special: re.Pattern = _SPECIAL) -> str:
    """``line`` with reStructuredText's inline markup escaped outside ``literals`` and roles."""
    parts = _LIVE.split(line)
    return "".join(p if i % 2 else special.sub(r"\\\1", p) for i, p in enumerate(parts))


def _role_name(match: re.Match) -> str:
    """A role as plain text: its title, else its target (``~a.b.c``: ``c``, as Sphinx shows it)."""
    title, _, target = match.groups()
    if title:
        return title
    return target[1:].rpartition(".")[2] if target.startswith("~") else target.lstrip("!")


def _numpydoc(lines: list[str]) -> bool:
    return any(_SECTION.match(a) and set(b.strip()) == {"-"} for a, b in itertools.pairwise(lines))


def _parameters(lines: list[str]) -> list[str]:
    """``lines`` with each entry ``name : description`` of a Parameters section split into
    ``name`` and the description indented below it, as numpydoc writes a parameter without
    a type (napoleon would take the description for a type)."""
    out: list[str] = []
    section, indent = None, None
    for i, line in enumerate(lines):
        head = _SECTION.match(line)
        if head and i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"}:
            section, indent = head.group(1), len(line) - len(line.lstrip())
            out.append(line)
            continue
        entry = _ENTRY.match(line) if section == "Parameters" else None
        if entry and len(entry.group(1)) == indent:
            out += [entry.group(1) + entry.group(2), entry.group(1) + "    " + entry.group(3)]
        else:
            out.append(line)
    return out


def plain_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    """Render a plain-text docstring safely (see above); edits ``lines`` in place."""
    if not lines:
        return
    if _numpydoc(lines):
        escaped = [_escape(line, _SPECIAL_NUMPYDOC) for line in _parameters(lines)]
        lines[:] = NumpyDocstring(escaped, NAPOLEON, app, what, name, obj, options).lines()
        return
    end = next((i for i, line in enumerate(lines) if not line.strip()), len(lines))
    summary = [_escape(line.strip()) for line in lines[:end]]
    rest = _ROLE_PARTS.sub(_role_name, "\n".join(lines[end:])).split("\n")  # roles span lines
    while rest and not rest[0].strip():
        rest = rest[1:]
    lines[:] = summary + (["", "::", ""] + ["    " + line for line in rest] if rest else [])


def setup(app):
    app.connect("autodoc-process-docstring", plain_docstring, priority=100)
