"""The ``raysim`` console script's entry point.

Loading the command's modules (typer, numpy, Warp, ...) takes about a second, and
:func:`raysim.cli.main` installs its signal handlers only once they are loaded: a Ctrl-C or
SIGTERM in that second printed a KeyboardInterrupt traceback, or nothing at all. Here a
minimal handler comes first. Nothing has been written while the modules load, so it prints the
one ``interrupted:`` line and ends the process at once (130 after SIGINT, 143 after SIGTERM).
"""

from __future__ import annotations

import os
import signal
import sys


def _while_loading(signum: int, frame: object) -> None:
    name = next((a for a in sys.argv[1:] if not a.startswith("-")), "")
    what = "stopped by SIGTERM" if signum == signal.SIGTERM else "stopped"
    os.write(2, f"interrupted: {f'raysim {name}'.strip()} {what}\n".encode())
    os._exit(143 if signum == signal.SIGTERM else 130)


def install_early_handlers() -> None:
    """SIGINT and SIGTERM end the process with the one line until the command's own handlers
    replace these."""
    signal.signal(signal.SIGINT, _while_loading)
    signal.signal(signal.SIGTERM, _while_loading)


def main() -> None:
    """The console script: the early handlers, then :func:`raysim.cli.main`."""
    install_early_handlers()
    from raysim.cli import main as run

    run()
