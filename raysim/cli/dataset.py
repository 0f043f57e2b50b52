"""``raysim dataset``: training and validation data on Dask (raysim.dataset)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, console, out


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

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=round(fraction * loaded.samples),
                       description=f"dataset {loaded.name}: {stage}")

        result = generate(loaded, output, workers=workers, scheduler=scheduler, resume=resume,
                          device=device, threads=threads, progress=report)
    out.print(result.summary(), highlight=False, soft_wrap=True)
    if result.failed or result.ideal_failures:
        raise typer.Exit(code=1)
