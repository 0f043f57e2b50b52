"""The package's version, a leaf module: anything may import it without importing raysim's API.

Read from the installed distribution's metadata, so that it is written in one place
(``pyproject.toml``); a source tree that was never installed says ``0+unknown``.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("raysim")
except PackageNotFoundError:  # pragma: no cover - running from an uninstalled source tree
    __version__ = "0+unknown"

VERSION_ATTR = "raysim_version"
"""The attribute under which every output (FieldMap, SurfaceMap, dataset store) records it."""

__all__ = ["VERSION_ATTR", "__version__"]
