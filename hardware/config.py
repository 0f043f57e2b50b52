"""Reading the rig's TOML files: typed look-ups that name the file and key in every error.

Degrees exist only here, at the edge: a key ending in ``_deg`` is read in degrees and handed
on in radians. Every table rejects keys it does not know, so a misspelt key is an error and
not a silently ignored setting.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hardware.errors import PlanError


def read_toml(path: str | Path, what: str) -> tuple[dict[str, Any], str]:
    """Parse a TOML file; return (the table, the file's text). ``what`` names it in errors."""
    path = Path(path)
    if not path.is_file():
        raise PlanError(f"{path}: no such {what} file")
    text = path.read_text(encoding="utf-8")
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise PlanError(f"{path}: not valid TOML ({exc})") from exc


class Table:
    """One TOML table with checked, typed access; call :meth:`done` to reject unknown keys."""

    def __init__(self, data: Mapping[str, Any] | None, where: str) -> None:
        if data is not None and not isinstance(data, Mapping):
            raise PlanError(f"{where}: must be a table")
        self.data = dict(data or {})
        self.where = where
        self.used: set[str] = set()

    def sub(self, key: str, required: bool = True) -> Table:
        """The sub-table ``key`` (an empty one when absent and not required)."""
        if key not in self.data and required:
            raise PlanError(f"{self.where}: missing table [{key}]")
        self.used.add(key)
        return Table(self.data.get(key), f"{self.where} [{key}]")

    def has(self, key: str) -> bool:
        return key in self.data

    def number(self, key: str, default: float | None = None, *, low: float | None = None,
               high: float | None = None, strict_low: bool = False) -> float:
        """A finite number, optionally bounded (``strict_low``: the bound ``low`` excluded)."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise PlanError(f"{self.where}: missing key '{key}'")
            return float(default)
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise PlanError(f"{self.where}: '{key}' must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise PlanError(f"{self.where}: '{key}' must be finite, got {value}")
        if low is not None and (value < low or (strict_low and value == low)):
            sign = ">" if strict_low else ">="
            raise PlanError(f"{self.where}: '{key}' must be {sign} {low:g}, got {value:g}")
        if high is not None and value > high:
            raise PlanError(f"{self.where}: '{key}' must be <= {high:g}, got {value:g}")
        return value

    def angle(self, key: str, default_deg: float | None = None, **bounds: float) -> float:
        """A ``*_deg`` (or ``*_deg_s``) key read in degrees (bounds in degrees too), returned
        in radians (per second)."""
        if not key.endswith(("_deg", "_deg_s")):
            raise AssertionError(f"angle keys end in _deg: {key}")
        return math.radians(self.number(key, default_deg, **bounds))

    def integer(self, key: str, default: int | None = None, *, low: int | None = None) -> int:
        """An integer, optionally bounded below."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise PlanError(f"{self.where}: missing key '{key}'")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, int):
            raise PlanError(f"{self.where}: '{key}' must be an integer, got {value!r}")
        if low is not None and value < low:
            raise PlanError(f"{self.where}: '{key}' must be >= {low}, got {value}")
        return value

    def boolean(self, key: str, default: bool) -> bool:
        self.used.add(key)
        value = self.data.get(key, default)
        if not isinstance(value, bool):
            raise PlanError(f"{self.where}: '{key}' must be true or false, got {value!r}")
        return value

    def string(self, key: str, default: str | None = None) -> str | None:
        self.used.add(key)
        value = self.data.get(key, default)
        if value is not None and not isinstance(value, str):
            raise PlanError(f"{self.where}: '{key}' must be a string, got {value!r}")
        return value

    def vector3(self, key: str, default: tuple[float, float, float]) -> tuple[float, float, float]:
        """Three finite numbers (a length vector in m, x y z in the reflector frame)."""
        self.used.add(key)
        value = self.data.get(key, list(default))
        if (not isinstance(value, list | tuple) or len(value) != 3
                or not all(isinstance(v, int | float) and not isinstance(v, bool)
                           and math.isfinite(v) for v in value)):
            raise PlanError(f"{self.where}: '{key}' must be three numbers [x, y, z], got {value!r}")
        return (float(value[0]), float(value[1]), float(value[2]))

    def done(self) -> None:
        """Reject keys nobody asked for."""
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise PlanError(f"{self.where}: unknown key '{unknown[0]}'")
