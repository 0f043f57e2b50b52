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

import logging
import signal
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
from raysim.cli.common import (
    app,
    error_line,
    interrupt_notes,
    nothing_to_resume,
    reflow_help,
    say_error,
)
from raysim.errors import RaysimError

__all__ = ["app", "main"]

reflow_help(app)


def _usage_error(exc: Exception) -> bool:
    """Whether ``exc`` is the CLI framework's usage error (click's, or typer's own copy)."""
    return hasattr(exc, "format_message") and isinstance(getattr(exc, "exit_code", None), int)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the program is (so the same clean-up runs as for Ctrl-C)."""


_received: list[int] = []  # the signals that interrupted this command


def _on_signal(signum: int, frame: object) -> None:
    """Record the signal, then raise where the program is (the framework turns a
    KeyboardInterrupt into exit status 130 silently; the record says what happened)."""
    _received.append(signum)
    logging.disable(logging.CRITICAL)  # the cluster's complaints about workers going away
    raise Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


#: options that make ``simulate`` resumable (its blocks on Dask)
_BLOCK_OPTIONS = ("--scheduler", "--workers", "--resume", "--block-size", "--threads")


def interrupted_line(args: list[str], terminated: bool, notes: list[str] | None = None,
                     resumable: bool = True) -> str:
    """The one line of an interrupted command: what stopped (with the command's ``notes``),
    and how to resume where it can (``resumable=False``: the command kept nothing to resume)."""
    name = next((a for a in args if not a.startswith("-")), "")
    what = f"raysim {name}".strip() + (" stopped by SIGTERM" if terminated else " stopped")
    if notes:
        what += f" ({'; '.join(notes)})"
    resumable = resumable and (name in ("dataset", "scan") or (name == "simulate" and any(
        a.split("=")[0] in _BLOCK_OPTIONS for a in args)))
    return f"interrupted: {what}; resume with --resume" if resumable else f"interrupted: {what}"


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: user errors become one line and exit status 2; SIGINT
    (Ctrl-C) and SIGTERM one line ``interrupted: ...`` and exit status 130 and 143, after the
    clean-up of the running command (its ``finally`` blocks) has run."""
    command = typer.main.get_command(app)
    args = sys.argv[1:] if argv is None else list(argv)
    # what a command run before in this process (tests, the API) received and said is its own
    _received.clear()
    interrupt_notes.clear()
    nothing_to_resume.clear()
    if argv is None:  # the real command (not a test calling main in its own process)
        signal.signal(signal.SIGTERM, _on_signal)
        signal.signal(signal.SIGINT, _on_signal)
        _printable_streams()
    try:
        code = command.main(args=args, prog_name="raysim", standalone_mode=False)
    except RaysimError as exc:
        _if_interrupted(args)  # an error the interrupt itself caused
        say_error(str(exc))
        sys.exit(2)
    except OSError as exc:
        _if_interrupted(args)
        name = f"{exc.filename}: " if exc.filename else ""
        say_error(f"{name}{exc.strerror or exc}")
        sys.exit(2)
    except KeyboardInterrupt as exc:
        _interrupted(args, isinstance(exc, Terminated))
    except Exception as exc:
        _if_interrupted(args)
        if type(exc).__name__ == "Abort":  # Ctrl-C while the framework parsed or prompted
            _interrupted(args, isinstance(exc.__context__, Terminated))
        if type(exc).__name__ == "NoArgsIsHelpError":  # help was shown
            sys.exit(0)
        if not _usage_error(exc):
            raise
        say_error(error_line(exc, command, args))
        sys.exit(2)
    _if_interrupted(args)
    sys.exit(code if isinstance(code, int) else 0)


def _printable_streams() -> None:
    """Print what the terminal's encoding cannot hold as escapes (a um sign, a degree sign, a
    file name in another script): under an ASCII locale with Python's UTF-8 mode off, a command
    that had written its output ended in a UnicodeEncodeError traceback when it named it."""
    for stream in (sys.stdout, sys.stderr):
        reconfigure = getattr(stream, "reconfigure", None)
        if reconfigure is not None:
            reconfigure(errors="backslashreplace")


def _if_interrupted(args: list[str]) -> None:
    """End the command as interrupted when a signal arrived during it (whatever it raised)."""
    if _received:
        _interrupted(args, _received[0] == signal.SIGTERM)


def _interrupted(args: list[str], terminated: bool) -> None:
    """End an interrupted command: one line, 143 after SIGTERM, 130 after SIGINT; a second
    signal while the line is printed changes nothing."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    say_error(interrupted_line(args, terminated, interrupt_notes, not nothing_to_resume), prefix="")
    sys.exit(143 if terminated else 130)
