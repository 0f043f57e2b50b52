"""The one TOML schema checker: typed, bounded look-ups that name the file and the key.

Every TOML input (scenes, dataset specs, scan plans, rig files) is read through
:func:`read_toml` and checked through :class:`Table`; each domain passes its own error type
(:class:`~raysim.errors.SceneError`, ``DatasetError``, ``PlanError``), so a defect is one line
``FILE: 'table.key' must be ..., got ...`` of that type. A table remembers which keys were
asked for; :meth:`Table.done` refuses the rest (with a suggestion for a misspelt key), so a
typo is an error and never a silently ignored setting.

Degrees exist only at this edge: :meth:`Table.angle` reads a ``*_deg`` key and returns radians.
A leaf module: it imports nothing of raysim but the error base class.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from raysim.errors import RaysimError

__all__ = ["REQUIRED", "Table", "parse_toml", "read_text", "read_toml"]


class _Required:
    def __repr__(self) -> str:
        return "REQUIRED"


REQUIRED: Any = _Required()  # default meaning "the key must be given"


def read_text(path: str | Path, what: str, error: type[RaysimError]) -> str:
    """The text of the ``what`` file at ``path`` (UTF-8); one-line ``error`` when unreadable."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{path}: is a folder, give a {what} file")
    if not path.is_file():
        raise error(f"{path}: no such {what} file")
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a text file (byte {exc.start} is not UTF-8); a {what} file is "
                    "TOML text") from exc
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} file ({exc.strerror or exc})") from exc


def parse_toml(text: str, source: str, error: type[RaysimError]) -> dict[str, Any]:
    """Parse TOML ``text``; ``source`` names it in the one-line ``error``."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML ({' '.join(str(exc).split())})") from exc
    except RecursionError:  # arrays or inline tables nested hundreds of levels deep
        raise error(f"{source}: nested too deeply (arrays or inline tables within each other "
                    "hundreds of levels down); no raysim file nests more than a few") from None


def read_toml(path: str | Path, what: str, error: type[RaysimError]) -> tuple[dict[str, Any], str]:
    """Read and parse a TOML file: (the table, the file's text)."""
    text = read_text(path, what, error)
    return parse_toml(text, str(path), error), text


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


class Table:
    """One TOML table with checked, typed access to its keys.

    ``where`` is the table's dotted path in the file (``""`` for the top level, ``sphere``,
    ``deformation[0]``); ``source`` names the file; ``error`` is the domain's error type.
    ``keys``, when given, are all the keys the table may hold: any other is refused at once
    (before a missing key is reported), otherwise at :meth:`done`.
    """

    def __init__(self, data: Any, where: str = "", *, source: str,
                 error: type[RaysimError], keys: Sequence[str] | None = None,
                 files: list[Path] | None = None) -> None:
        self.source = source
        self.files: list[Path] = [] if files is None else files  # every file read through file()
        self.error = error
        self.where = where
        if data is not None and not isinstance(data, Mapping):
            raise self.fail(f"'{where}' must be a table, got {data!r}" if where else
                            "must be a table")
        self.data: dict[str, Any] = dict(data or {})
        self.used: set[str] = set()
        if keys is not None:
            self.refuse_unknown(set(keys))

    # --- naming and failing ------------------------------------------------------------------
    def name(self, key: str) -> str:
        """The dotted name of ``key`` in messages: ``sphere.n_theta``."""
        return f"{self.where}.{key}" if self.where else key

    def fail(self, message: str) -> RaysimError:
        """The domain's error, one line naming the file."""
        return self.error(f"{self.source}: {message}")

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any) -> tuple[bool, Any]:
        """(present, value); marks the key as known; missing required keys fail."""
        self.used.add(key)
        if key in self.data:
            return True, self.data[key]
        if default is REQUIRED:
            stray = difflib.get_close_matches(key, [k for k in self.data if k not in self.used], n=1)
            if stray:  # a misspelt key explains the missing one better
                raise self.fail(f"unknown key '{self.name(stray[0])}' (did you mean '{key}'?)")
            raise self.fail(f"missing key '{self.name(key)}'")
        return False, default

    # --- values ------------------------------------------------------------------------------
    def raw(self, key: str, default: Any = None) -> Any:
        """The value as TOML gave it (for values another parser checks)."""
        return self._get(key, default)[1]

    def sub(self, key: str, required: bool = False, keys: Sequence[str] | None = None) -> Table:
        """The sub-table ``key`` (empty when absent and not required)."""
        if required and key not in self.data:
            self.used.add(key)
            raise self.fail(f"missing table [{self.name(key)}]")
        _, value = self._get(key, None)
        return Table(value, self.name(key), source=self.source, error=self.error, keys=keys,
                     files=self.files)

    def tables(self, key: str, *, required: bool = False,
               keys: Sequence[str] | None = None) -> list[Table]:
        """An array of tables ``[[key]]`` (empty when absent)."""
        _, value = self._get(key, REQUIRED if required else [])
        if not isinstance(value, list) or not all(isinstance(v, Mapping) for v in value):
            raise self.fail(f"'{self.name(key)}' must be a list of tables ([[{self.name(key)}]])")
        return [Table(v, f"{self.name(key)}[{i}]", source=self.source, error=self.error, keys=keys,
                      files=self.files) for i, v in enumerate(value)]

    def number(self, key: str, default: Any = REQUIRED, *, lo: float | None = None,
               hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
               unit: str = "") -> float:
        """A finite number in [lo, hi] (``lo_open``/``hi_open``: that bound excluded)."""
        present, value = self._get(key, default)
        if not present:
            return float(value)
        name = self.name(key)
        if not _is_number(value):
            hint = ""
            if isinstance(value, str):
                hint = f" (a bare number{f' in {unit}' if unit else ''}, no unit text)"
            raise self.fail(f"'{name}' must be a number, got {value!r}{hint}")
        value = float(value)
        if not math.isfinite(value):
            raise self.fail(f"'{name}' must be a finite number, got {value}")
        self._bounds(name, value, lo, hi, lo_open, hi_open)
        return value

    def _bounds(self, name: str, value: float, lo, hi, lo_open=False, hi_open=False) -> None:
        if lo is not None and (value <= lo if lo_open else value < lo):
            raise self.fail(f"'{name}' must be {'>' if lo_open else '>='} {lo:g}, got {value:g}")
        if hi is not None and (value >= hi if hi_open else value > hi):
            raise self.fail(f"'{name}' must be {'<' if hi_open else '<='} {hi:g}, got {value:g}")

    def integer(self, key: str, default: Any = REQUIRED, *, lo: int | None = None,
                hi: int | None = None) -> int:
        """An integer in [lo, hi]."""
        present, value = self._get(key, default)
        if not present:
            return int(value)
        name = self.name(key)
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"'{name}' must be an integer, got {value!r}")
        self._bounds(name, value, lo, hi)
        return int(value)

    def string(self, key: str, default: Any = REQUIRED, *,
               choices: Sequence[str] | None = None) -> str | None:
        """A string, optionally one of ``choices``."""
        present, value = self._get(key, default)
        if not present:
            return value
        name = self.name(key)
        if not isinstance(value, str):
            raise self.fail(f"'{name}' must be a string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.fail(f"'{name}' must be one of {', '.join(choices)}, got {value!r}")
        return value

    def boolean(self, key: str, default: Any = REQUIRED) -> bool:
        present, value = self._get(key, default)
        if present and not isinstance(value, bool):
            raise self.fail(f"'{self.name(key)}' must be true or false, got {value!r}")
        return bool(value)

    def angle(self, key: str, default_deg: Any = REQUIRED, **bounds: Any) -> float:
        """A ``*_deg`` (or ``*_deg_s``) key read in degrees (bounds in degrees), in rad (/s)."""
        if not key.endswith(("_deg", "_deg_s")):
            raise AssertionError(f"angle keys end in _deg: {key}")
        return math.radians(self.number(key, default_deg, **bounds))

    def numbers(self, key: str, default: Any = REQUIRED, *, length: int | None = None,
                min_length: int = 0, integer: bool = False, lo: float | None = None,
                hi: float | None = None, lo_open: bool = False, what: str = "") -> tuple:
        """A list of finite numbers (integers with ``integer``), each in [lo, hi]."""
        present, value = self._get(key, default)
        if not present:
            return tuple(value)
        name = self.name(key)
        kind = "integers" if integer else "numbers"
        ok = isinstance(value, list) and all(
            (isinstance(v, int) and not isinstance(v, bool)) if integer else _is_number(v)
            for v in value)
        shape = f"{length} {kind}" if length is not None else f"a list of {kind}"
        if not ok or (length is not None and len(value) != length):
            raise self.fail(f"'{name}' must be {shape}{what}, got {value!r}")
        if len(value) < min_length:
            raise self.fail(f"'{name}' needs at least {min_length} {kind}, got {value!r}")
        for v in value:
            if not math.isfinite(v):
                raise self.fail(f"'{name}' must hold finite numbers, got {value!r}")
            self._bounds(name, float(v), lo, hi, lo_open)
        return tuple(int(v) if integer else float(v) for v in value)

    def vector3(self, key: str, default: Any = REQUIRED) -> tuple[float, float, float]:
        """Three finite numbers [x, y, z] (a length vector in m in the reflector frame)."""
        values = self.numbers(key, list(default) if default is not REQUIRED else default,
                              length=3, what=" [x, y, z]")
        return (values[0], values[1], values[2])

    def done(self) -> None:
        """Refuse the keys nobody asked for (naming the table, suggesting a close key)."""
        self.refuse_unknown(self.used)

    def refuse_unknown(self, known_keys: set[str]) -> None:
        for key in self.data:
            if key not in known_keys:
                known = sorted(known_keys)
                hint = difflib.get_close_matches(key, known, n=1)
                extra = (f" (did you mean '{hint[0]}'?)" if hint else
                         f" (known: {', '.join(known)})" if known else " (the table takes no keys)")
                raise self.fail(f"unknown key '{self.name(key)}'{extra}")

    def file(self, key: str, base: Path, default: Any = REQUIRED) -> Path | None:
        """A file name relative to ``base`` (the folder of the TOML file); it must exist."""
        name = self.string(key, default)
        if name is None:
            return None
        path = Path(name).expanduser()
        path = path if path.is_absolute() else base / path
        if not path.is_file():
            raise self.fail(f"'{self.name(key)}': no such file {path}")
        self.files.append(path)
        return path
