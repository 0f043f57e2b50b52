"""The one way the tests run the ``raysim`` command: in this process (fast) or as a real
subprocess (signals, kills, a fresh interpreter). Both give a :class:`Result`."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


@dataclass(frozen=True)
class Result:
    """Exit status and the two streams of one command."""

    code: int
    stdout: str
    stderr: str

    @property
    def returncode(self) -> int:  # the name subprocess uses
        return self.code

    def __iter__(self):  # code, out, err = result
        return iter((self.code, self.stdout, self.stderr))

    def error(self) -> str:
        """The single line on stderr of a failed command (asserts there is exactly one)."""
        return error_line(self.stderr)


def error_line(stderr: str) -> str:
    """The single line of ``stderr`` (asserts there is exactly one, no blank lines around)."""
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].strip(), f"expected one line on stderr, got:\n{stderr}"
    return lines[0]


def cli_env(**extra: str) -> dict[str, str]:
    """The environment of a subprocess: this checkout first on the path, wide columns."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    env["COLUMNS"] = "200"
    env.update(extra)
    return env


def command(*args: str) -> list[str]:
    """The argv of ``raysim ARGS`` run by this interpreter."""
    return [sys.executable, "-m", "raysim.cli", *map(str, args)]


def run_cli(*args: str | os.PathLike[str], cwd: str | os.PathLike[str] | None = None,
            timeout: float = 300.0, env: dict[str, str] | None = None) -> Result:
    """``raysim ARGS`` as a subprocess."""
    done = subprocess.run(command(*args), cwd=cwd or ROOT, env=env or cli_env(),
                          capture_output=True, text=True, timeout=timeout)
    return Result(done.returncode, done.stdout, done.stderr)


def popen_cli(*args: str | os.PathLike[str], cwd: str | os.PathLike[str] | None = None,
              **kwargs) -> subprocess.Popen:
    """``raysim ARGS`` started as a subprocess (for signals and kills)."""
    kwargs.setdefault("env", cli_env())
    return subprocess.Popen(command(*args), cwd=cwd or ROOT, **kwargs)


def run_in_process(capture, *args: str | os.PathLike[str]) -> Result:
    """``raysim ARGS`` through :func:`raysim.cli.main` in this process; ``capture`` is pytest's
    ``capfd`` (every byte written to the two file descriptors) or ``capsys``. Every warning is
    shown, so a warning before an error counts as a line."""
    from raysim import cli

    capture.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        try:
            cli.main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    out, err = capture.readouterr()
    return Result(code, out, err)
