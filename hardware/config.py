"""Reading the rig's TOML files (scan plans, rig files) through the one schema checker.

:class:`raysim.tomlschema.Table` does the checking; here it is bound to the rig's error type,
:class:`~hardware.errors.PlanError`. Degrees exist only at this edge: a key ending in ``_deg``
is read in degrees and handed on in radians. Every table rejects keys it does not know.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from hardware.errors import PlanError
from raysim import tomlschema
from raysim.files import find_input
from raysim.tomlschema import Table

__all__ = ["Table", "plan_table", "read_toml"]


def read_toml(path: str | Path, what: str) -> tuple[dict[str, Any], str, Path]:
    """Parse a TOML file: (the table, the file's text, the file's path). A name that is not an
    existing path may name a shipped example (``scan_demo``, ``rig``)."""
    path = find_input(path)
    data, text = tomlschema.read_toml(path, what, PlanError)
    return data, text, path


def plan_table(data: Any, source: str, where: str = "") -> Table:
    """A checked table of a plan or rig file named ``source``, failing with :class:`PlanError`."""
    return Table(data, where, source=source, error=PlanError)
