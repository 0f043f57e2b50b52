"""TOML text from a parsed table: turns a spec's inline ``[scene]`` back into a scene file.

Only what ``tomllib`` produces from a scene is needed: strings, integers, floats, booleans,
lists and tables. Top-level tables become ``[section]``, lists of tables ``[[section]]``,
anything deeper is written inline. The text reads back to the same table (checked).
"""

from __future__ import annotations

import json
import math
import re
import tomllib
from typing import Any

_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def dumps(table: dict[str, Any]) -> str:
    """TOML text whose ``tomllib.loads`` equals ``table``."""
    head, sections = [], []
    for key, value in table.items():
        if isinstance(value, dict):
            sections.append(f"[{_key(key)}]\n" + _body(value))
        elif isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            sections.extend(f"[[{_key(key)}]]\n" + _body(v) for v in value)
        else:
            head.append(f"{_key(key)} = {_value(value)}\n")
    text = "".join(head) + "".join("\n" + s for s in sections)
    if tomllib.loads(text) != table:  # pragma: no cover - a guard on this module itself
        raise ValueError("scene table does not survive a TOML round trip")
    return text


def _body(table: dict[str, Any]) -> str:
    return "".join(f"{_key(k)} = {_value(v)}\n" for k, v in table.items())


def _key(key: str) -> str:
    return key if _BARE.match(key) else json.dumps(key)


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + "}"
    raise ValueError(f"cannot write {type(value).__name__} {value!r} as TOML")
