"""The ``raysim`` command: a thin typer layer over the Python API.

Units at this edge: lengths in metres, frequencies in Hz, angles in degrees where an option
name ends in ``-deg``. Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import sys
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
        from raysim import __version__

        out.print(f"raysim {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Reflector surface deformation from one intensity scan on a hemisphere at the focus."""


def fail(message: str) -> typer.Exit:
    """Print one line for the user and return the exit to raise (status 2)."""
    console.print(f"[bold red]error:[/] {message}", highlight=False, soft_wrap=True)
    return typer.Exit(code=2)


def output_path(path: Path) -> Path:
    """Check an output path's folder can be written before hours of work go into it."""
    parent = path.expanduser().resolve().parent
    parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir():
        raise RaysimError(f"{path}: is a folder, give a file name")
    return path


# --- simulate (raysim.go, raysim.po, raysim.ptd) ------------------------------------------
@app.command()
def simulate(
    scene: Path = typer.Argument(..., help="Scene TOML file (see scenes/)."),
    output: Path = typer.Option(..., "-o", "--output", help="FieldMap NetCDF file to write."),
    method: str = typer.Option("go", "--method", help="go (geometric optics), po, or po+ptd."),
    frequency: float | None = typer.Option(None, "--frequency", help="Override the scene's frequency (Hz)."),
    n_theta: int | None = typer.Option(None, "--n-theta", help="Cells in theta (polar angle from -z)."),
    n_phi: int | None = typer.Option(None, "--n-phi", help="Cells in phi (azimuth)."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
) -> None:
    """Simulate a scene: intensity of the ideal and deformed reflector on the probe sphere.

    Writes a FieldMap (NetCDF): intensity relative to the incident plane wave on (theta, phi)
    cells, theta from -z at the focus and phi = atan2(y, x), both in radians in the file.
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from raysim.field import save
    from raysim.scene import load_scene
    from raysim.simulate import simulate as run
    from raysim.simulate import summary

    loaded = load_scene(scene).with_overrides(frequency, n_theta, n_phi)
    output_path(output)
    with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                  console=console, transient=True) as bar:
        task = bar.add_task(f"{method} {loaded.name}", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"{method} {loaded.name}: {stage}")

        ds = run(loaded, method=method, device=device, progress=report)
    save(ds, output)
    out.print(f"{output}: {summary(ds)}", highlight=False)



# --- invert, paper (solver) ------------------------------------------------------------


# --- render, report (raysim.render) ----------------------------------------------------


# --- scan, rig (hardware) --------------------------------------------------------------


# --- dataset (raysim.dataset) ----------------------------------------------------------
@app.command()
def dataset(
    spec: Path = typer.Argument(..., help="Dataset spec TOML (see scenes/dataset_demo.toml)."),
    output: Path = typer.Option(..., "-o", "--output", help="Zarr store to write (a folder, data.zarr)."),
    workers: int | None = typer.Option(None, "--workers",
                                       help="Local worker processes (default: one per usable core)."),
    scheduler: str | None = typer.Option(None, "--scheduler",
                                         help="Address of a running Dask scheduler (tcp://host:port) "
                                              "instead of a local cluster."),
    resume: bool = typer.Option(False, "--resume", help="Complete an interrupted store of the same spec."),
    device: str = typer.Option("cpu", "--device", help="Warp device of the workers: cpu or cuda."),
    threads: int = typer.Option(1, "--threads", help="CPU threads of each Warp launch in a worker."),
) -> None:
    """Simulate a dataset of random surface errors into a Zarr store, on Dask.

    Each sample's deformation (m) and intensity on the probe sphere are written by the worker
    that made it; a failed sample is recorded with its reason and the others go on. Exit
    status 1 when some samples failed (rerun with --resume to retry them).
    """
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from raysim.dataset import generate, load_spec

    loaded = load_spec(spec)
    if "://" not in str(output):
        output.expanduser().resolve().parent.mkdir(parents=True, exist_ok=True)
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                  TimeElapsedColumn(), console=console, transient=True) as bar:
        task = bar.add_task(f"dataset {loaded.name}", total=loaded.samples)

        def report(done: int, failed: int, total: int) -> None:
            note = f" ({failed} failed)" if failed else ""
            bar.update(task, completed=done + failed, description=f"dataset {loaded.name}{note}")

        result = generate(loaded, output, workers=workers, scheduler=scheduler, resume=resume,
                          device=device, threads=threads, progress=report)
    out.print(result.summary(), highlight=False, soft_wrap=True)
    if result.failed or result.ideal_failures:
        raise typer.Exit(code=1)



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


if __name__ == "__main__":
    main()
