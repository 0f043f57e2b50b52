"""What every command shares: the consoles, the app, the progress bar, output checks.

Units at this edge: lengths in metres, frequencies in Hz, angles in degrees where an option
name ends in ``-deg``. Errors a user can cause end with one line on stderr and exit status 2.
Text that comes from users or from messages is printed as it is (never read as rich markup,
so ``[track]`` stays ``[track]``) and never wrapped.
"""

from __future__ import annotations

import inspect
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, ProgressColumn, TextColumn, TimeElapsedColumn
from rich.text import Text

from raysim.errors import RaysimError
from raysim.files import check_output, probe_writable

app = typer.Typer(
    name="raysim",
    help=(
        "Reflector surface deformation from one intensity scan on a hemisphere around the "
        "focus. Lengths in metres, frequencies in Hz, angles in degrees (options ending in "
        "-deg). Inputs are TOML files or the name of a shipped example (raysim scenes lists "
        "them)."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
console = Console(stderr=True, soft_wrap=True, highlight=False)
out = Console(soft_wrap=True, highlight=False)


def say(text: str) -> None:
    """One line of output on stdout, printed as it is."""
    out.print(text, markup=False, highlight=False, soft_wrap=True)


def note(text: str) -> None:
    """One line of progress on stderr, printed as it is."""
    console.print(text, markup=False, highlight=False, soft_wrap=True)


#: what the interrupted command adds to its one line ("12 of 40 steps are in J"), see
#: :func:`raysim.cli.interrupted_line`
interrupt_notes: list[str] = []
#: set when the interrupted command has nothing to resume (a scan stopped before its first
#: step keeps no journal): its line then does not say "resume with --resume"
nothing_to_resume: list[bool] = []


def note_interrupt(text: str, resumable: bool = True) -> None:
    """Add ``text`` to the line an interrupt (SIGINT, SIGTERM) ends the command with; the
    command then lets the KeyboardInterrupt go on. ``resumable=False``: the command kept
    nothing a ``--resume`` could continue, so the line does not offer one."""
    interrupt_notes.append(" ".join(text.split()))
    if not resumable:
        nothing_to_resume.append(True)


def say_error(message: str, prefix: str = "error:") -> None:
    """The one line of a failed command on stderr (the message collapsed onto one line)."""
    line = " ".join(str(message).split())
    console.print(Text.assemble((prefix, "bold red"), " " if prefix else "", line),
                  soft_wrap=True, highlight=False)


def output_file(text: str) -> Path:
    """An output file's name as typed (typer's ``parser``): a trailing slash names a folder
    (``Path`` drops it, and ``-o x.nc/`` wrote the file ``x.nc``)."""
    if text.endswith(("/", os.sep)):
        raise typer.BadParameter(f"{text}: ends in a slash, so it names a folder: give a file name")
    return Path(text)


def error_line(exc: Exception, command: Any = None, args: Sequence[str] = ()) -> str:
    """The one line of a usage error of the CLI framework: command, problem, where to look.
    The framework names the command where it knows it; where it does not (an option missing its
    value), the subcommands of ``command`` (the root click group) that ``args`` name."""
    ctx = getattr(exc, "ctx", None)
    where = getattr(ctx, "command_path", None) or command_path(command, args)
    return f"{where}: {exc.format_message()} (see '{where} --help')"  # type: ignore[attr-defined]


def command_path(command: Any, args: Sequence[str]) -> str:
    """``raysim`` and the subcommands (of the click group ``command``) that lead ``args``."""
    path = ["raysim"]
    for arg in args:
        commands = getattr(command, "commands", None)
        if not commands or arg not in commands:
            break
        command = commands[arg]
        path.append(arg)
    return " ".join(path)


def reflow_help(typer_app: typer.Typer) -> None:
    """Join the lines of each paragraph of every command's docstring, so that the help wraps
    them to the terminal (the framework keeps a docstring's line breaks: at 80 columns a
    sentence broke mid-way, leaving fragments of a word or two on lines of their own)."""
    for info in typer_app.registered_commands:
        text = info.help or (info.callback.__doc__ if info.callback else None)
        if text:
            info.help = "\n\n".join(" ".join(p.split()) for p in inspect.cleandoc(text).split("\n\n"))
    for group in typer_app.registered_groups:
        if group.typer_instance is not None:
            reflow_help(group.typer_instance)


def _version(value: bool) -> None:
    if value:
        from raysim.version import __version__

        say(f"raysim {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Reflector surface deformation from one intensity scan on a hemisphere at the focus."""


class _NoBar:
    """What :func:`progress_bar` gives off a terminal: the same calls, nothing printed (a
    disabled rich bar still ends with a newline in some rich versions)."""

    def __enter__(self) -> _NoBar:
        return self

    def __exit__(self, *exc: object) -> None:
        return None

    def add_task(self, *args: object, **kwargs: object) -> int:
        return 0

    def update(self, *args: object, **kwargs: object) -> None:
        return None

    def reset(self, *args: object, **kwargs: object) -> None:
        return None


def progress_bar(*columns: ProgressColumn, transient: bool = True) -> Progress | _NoBar:
    """A progress bar on stderr, shown only on a terminal (a pipe or a log gets no bar and no
    blank line before an error)."""
    if not console.is_terminal:
        return _NoBar()
    columns = columns or (TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn())
    return Progress(*columns, console=console, transient=transient)


def output_path(path: Path, inputs: Iterable[tuple[str, str | os.PathLike[str] | None]] = ()) -> Path:
    """Check an output file can be written before any work goes into it; return it.

    Refuses a folder, an output that is one of the command's ``inputs`` ((what, path) pairs,
    symbolic links and relative paths resolved), and a folder where nothing can be written.
    """
    path = path.expanduser()
    if path.is_dir():
        raise RaysimError(f"{path}: is a folder, give a file name")
    check_output(path, inputs)
    parent = path.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RaysimError(f"{path}: cannot create its folder ({exc.strerror})") from exc
    try:
        probe_writable(parent)
    except OSError as exc:
        raise RaysimError(f"{path}: cannot write in {parent} ({exc.strerror})") from exc
    return path


def file_attrs(path: Path) -> dict[str, Any] | None:
    """The global attributes of the NetCDF file ``path``, or None where it is not a readable
    regular file: a look ahead of the command's own reader, which says in one line what is
    wrong (a folder, a missing file, not NetCDF).

    Only a regular file is opened, with the backends' warnings silenced: given a Zarr folder,
    xarray printed a five-line RuntimeWarning before the reader's one line.
    """
    import warnings

    import xarray as xr

    if not Path(path).is_file():
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with xr.open_dataset(path) as ds:
                return dict(ds.attrs)
    except Exception:  # not a NetCDF file: its reader says so, in one line
        return None


def scene_inputs(field: Path) -> list[tuple[str, Path]]:
    """(what, path) of the files the scene recorded in the FieldMap ``field`` names
    (:func:`raysim.scene.scene.recorded_files`), for a command's output checks; nothing for a
    file that cannot be read as one (the command's own reading says what is wrong with it)."""
    from raysim.scene.scene import recorded_files

    attrs = file_attrs(field)
    if attrs is None:
        return []
    try:
        return recorded_files(attrs)
    except Exception:  # a scene the reader refuses, in one line
        return []
