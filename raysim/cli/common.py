"""What every command shares: the consoles, the app, output checks.

Units at this edge: lengths in metres, frequencies in Hz, angles in degrees where an option
name ends in ``-deg``. Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import typer
from rich.console import Console

from raysim.errors import RaysimError

app = typer.Typer(
    name="raysim",
    help=(
        "Reflector surface deformation from one intensity scan on a hemisphere around the "
        "focus. Lengths in metres, frequencies in Hz, angles in degrees (options ending in "
        "-deg); scenes are TOML files (see scenes/)."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console(stderr=True)
out = Console()


def _version(value: bool) -> None:
    if value:
        from raysim.version import __version__

        out.print(f"raysim {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Reflector surface deformation from one intensity scan on a hemisphere at the focus."""


def output_path(path: Path) -> Path:
    """Check an output file can be written before any work goes into it; return it."""
    path = path.expanduser()
    if path.is_dir():
        raise RaysimError(f"{path}: is a folder, give a file name")
    parent = path.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RaysimError(f"{path}: cannot create its folder ({exc.strerror})") from exc
    try:  # a real probe: permissions alone do not tell (root, read-only mounts, /proc)
        with tempfile.NamedTemporaryFile(dir=parent, prefix=".raysim-probe-"):
            pass
    except OSError as exc:
        raise RaysimError(f"{path}: cannot write in {parent} ({exc.strerror})") from exc
    return path
