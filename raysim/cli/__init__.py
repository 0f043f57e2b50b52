"""The ``raysim`` command: a thin typer layer over the Python API, one module per command.

- ``common``: the app, the consoles, the progress bar, output-path checks.
- ``simulate``, ``invert`` (and ``paper``), ``correct``, ``render`` (and ``report``), ``check``,
  ``scan`` (and ``rig park``), ``dataset``, ``scenes``: the commands, each a wrapper of one API
  call.

Units at this edge: lengths in metres, frequencies in Hz, angles in degrees where an option
name ends in ``-deg``. Every error a user can cause (a bad option value, an unknown option, a
bad file, an unreachable instrument) ends with exactly one line on stderr and exit status 2.
"""

from __future__ import annotations

import sys

import typer

from raysim.cli import (  # noqa: F401  (register commands)
    budget,
    campaign,
    check,
    correct,
    dataset,
    invert,
    render,
    scan,
    scenes,
    simulate,
)
from raysim.cli.common import app, error_line, say_error
from raysim.errors import RaysimError

__all__ = ["app", "main"]


def _usage_error(exc: Exception) -> bool:
    """Whether ``exc`` is the CLI framework's usage error (click's, or typer's own copy)."""
    return hasattr(exc, "format_message") and isinstance(getattr(exc, "exit_code", None), int)


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: user errors become one line and exit status 2."""
    command = typer.main.get_command(app)
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        code = command.main(args=args, prog_name="raysim", standalone_mode=False)
    except RaysimError as exc:
        say_error(str(exc))
        sys.exit(2)
    except OSError as exc:
        name = f"{exc.filename}: " if exc.filename else ""
        say_error(f"{name}{exc.strerror or exc}")
        sys.exit(2)
    except KeyboardInterrupt:
        say_error("interrupted", prefix="")
        sys.exit(130)
    except Exception as exc:
        if type(exc).__name__ == "Abort":  # Ctrl-C while the framework parsed or prompted
            say_error("interrupted", prefix="")
            sys.exit(130)
        if type(exc).__name__ == "NoArgsIsHelpError":  # help was shown
            sys.exit(0)
        if not _usage_error(exc):
            raise
        say_error(error_line(exc))
        sys.exit(2)
    sys.exit(code if isinstance(code, int) else 0)
