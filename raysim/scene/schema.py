"""Checks of TOML tables against a schema, with one-line messages naming the file and key.

Shared by the scene loader (:mod:`raysim.scene.scene`) and its deformation tables
(:mod:`raysim.scene.deformations`). A schema maps each key to the kind of value it takes.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from raysim.errors import SceneError

NUM, INT, STR, LIST, TABLES, TABLE = "number", "integer", "string", "list", "list of tables", "table"


class KeyChecker:
    """Key checks that name the file and key in each message."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, message: str) -> SceneError:
        return SceneError(f"{self.source}: {where} {message}" if where else f"{self.source}: {message}")

    def check_keys(self, table: Any, section: str, known: Mapping[str, str]) -> None:
        """Refuse keys not in ``known`` (with a suggestion) and values of the wrong kind."""
        if not isinstance(table, dict):
            raise self.fail(f"[{section}]", "must be a table")
        for key, value in table.items():
            if key not in known:
                hint = difflib.get_close_matches(key, list(known), n=1)
                extra = f" (did you mean '{hint[0]}'?)" if hint else f" (known: {', '.join(known)})"
                name = f"{section}.{key}" if section else key
                raise self.fail("", f"unknown key '{name}'{extra}")
            check_kind(self, f"{section}.{key}" if section else key, value, known[key])

    def number(self, table, section, key, default=None, lo=None, hi=None, lo_open=False):
        name = f"{section}.{key}"
        if key not in table:
            if default is None:
                raise self.fail("", f"missing key '{name}'")
            return float(default)
        value = float(table[key])
        if not math.isfinite(value):
            raise self.fail("", f"'{name}' must be finite, got {value}")
        if lo is not None and (value <= lo if lo_open else value < lo):
            raise self.fail("", f"'{name}' must be {'>' if lo_open else '>='} {lo:g}, got {value:g}")
        if hi is not None and value > hi:
            raise self.fail("", f"'{name}' must be <= {hi:g}, got {value:g}")
        return value

    def integer(self, table, section, key, default, lo=None, hi=None) -> int:
        value = int(table.get(key, default))
        name = f"{section}.{key}"
        if lo is not None and value < lo:
            raise self.fail("", f"'{name}' must be >= {lo}, got {value}")
        if hi is not None and value > hi:
            raise self.fail("", f"'{name}' must be <= {hi}, got {value}")
        return value


def check_kind(ctx: KeyChecker, name: str, value: Any, kind: str) -> None:
    ok = {
        NUM: isinstance(value, int | float) and not isinstance(value, bool),
        INT: isinstance(value, int) and not isinstance(value, bool),
        STR: isinstance(value, str),
        LIST: isinstance(value, list),
        TABLES: isinstance(value, list) and all(isinstance(v, dict) for v in value),
        TABLE: isinstance(value, dict),
    }[kind]
    if not ok:
        unit = name.rsplit("_", 1)[-1] if "_" in name else ""
        hint = f" (a bare number in {unit}, no unit text)" if kind == NUM and isinstance(value, str) else ""
        raise ctx.fail("", f"'{name}' must be a {kind}, got {value!r}{hint}")


def resolve(ctx: KeyChecker, base: Path, name: str, key: str) -> Path:
    path = Path(name)
    path = path if path.is_absolute() else base / path
    if not path.is_file():
        raise ctx.fail("", f"'{key}': no such file {path}")
    return path


