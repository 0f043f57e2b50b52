"""Tables on stdout: full column text off a terminal, and the same numbers as JSON (``--json``).

A rich table sized to the terminal folds or cuts its cells ("readin…") when stdout is a pipe
or a log (rich then assumes 80 columns). Off a terminal the table is given as much width as
it needs, so every cell keeps its full text. ``--json FILE`` writes the table's numbers with
full precision in SI units (metres, seconds, Hz, fractions rather than per cent) beside the
printed text; ``--json -`` writes them to stdout instead of the table.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import typer
from rich.console import Console

from raysim.cli.common import out, output_path
from raysim.files import write_text

# the widest table printed off a terminal (characters); wider tables would be cut past it
OFF_TERMINAL_WIDTH = 10_000

JSON_OPTION_HELP = ("Also write the table's numbers (SI units, full precision) as JSON to this "
                    "file; '-' writes them to stdout instead of the table.")


def json_option() -> Any:
    """The ``--json`` option every table-printing command shares."""
    return typer.Option(None, "--json", help=JSON_OPTION_HELP)


def json_to_stdout(path: str | None) -> bool:
    """Whether ``--json`` asks for stdout (the human table and lines are then left out)."""
    return path == "-"


def check_json_path(path: str | None, inputs=()) -> None:
    """Refuse an unwritable ``--json`` file before any work goes into the table."""
    if path not in (None, "-"):
        output_path(Path(path), inputs)


def print_table(title: str, rows: list[list[str]]) -> None:
    """A header row and data rows as a rich table on stdout; full text off a terminal."""
    from rich.table import Table

    table = Table(*rows[0], title=title)
    for row in rows[1:]:
        table.add_row(*row)
    if out.is_terminal:
        out.print(table)
        return
    wide = Console(file=out.file, width=OFF_TERMINAL_WIDTH, highlight=False, color_system=None)
    wide.print(table, crop=False)


def _plain(value: Any) -> Any:
    """A JSON-ready copy: NaN and infinities as null, tuples as lists, numpy scalars as floats."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, bool) or value is None or isinstance(value, str | int):
        return value
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    return number if math.isfinite(number) else None


def write_json(path: str | None, command: str, title: str, records: list[dict[str, Any]],
               table: list[list[str]] | None = None, **extra: Any) -> None:
    """``--json``: ``records`` (one dict of SI numbers per row of the table), the printed
    ``table`` (header row first; as ``columns`` and text ``rows``) and ``extra`` keys to
    ``path``, or to stdout for ``-``; nothing for None."""
    if path is None:
        return
    payload: dict[str, Any] = {"command": command, "title": title, "records": records}
    if table is not None:
        payload |= {"columns": table[0], "rows": table[1:]}
    payload |= extra
    text = json.dumps(_plain(payload), indent=2, allow_nan=False) + "\n"
    if path == "-":
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    write_text(Path(path).expanduser(), text)
