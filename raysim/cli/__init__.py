"""The ``raysim`` command: a thin typer layer over the Python API, one module per command.

- ``common``: the app, the consoles, output-path checks.
- ``simulate``, ``invert`` (and ``paper``), ``render`` (and ``report``), ``scan`` (and
  ``rig park``), ``dataset``: the commands, each a wrapper of one API call.

Units at this edge: lengths in metres, frequencies in Hz, angles in degrees where an option
name ends in ``-deg``. Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import sys

from raysim.cli import dataset, invert, render, scan, simulate  # noqa: F401  (register commands)
from raysim.cli.common import app, console
from raysim.errors import RaysimError

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point: user errors become one line and exit status 2."""
    try:
        app()
    except RaysimError as exc:
        console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except OSError as exc:
        name = f"{exc.filename}: " if exc.filename else ""
        console.print(f"[bold red]error:[/] {name}{exc.strerror or exc}", highlight=False)
        sys.exit(2)
    except KeyboardInterrupt:
        console.print("[bold red]interrupted[/]")
        sys.exit(130)

