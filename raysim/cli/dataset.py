"""``raysim dataset``: training and validation data on Dask (raysim.dataset)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn

from raysim.cli.common import app, progress_bar, say


@app.command()
def dataset(
    spec: Path = typer.Argument(..., help="Dataset spec TOML, or a shipped example's name "
                                          "(dataset_demo)."),
    output: Path = typer.Option(..., "-o", "--output", help="Zarr store to write (a folder, data.zarr)."),
    workers: int | None = typer.Option(
        None, "--workers",
        help="Local worker processes (default: the usable cores divided by --threads, and no more "
             "than the samples to compute)."),
    scheduler: str | None = typer.Option(None, "--scheduler",
                                         help="Address of a running Dask scheduler (tcp://host:port) "
                                              "instead of a local cluster; it must answer within "
                                              "20 s."),
    resume: bool = typer.Option(False, "--resume", help="Complete an interrupted store of the same spec."),
    device: str = typer.Option("cpu", "--device", help="Warp device of the workers: cpu or cuda."),
    threads: int = typer.Option(1, "--threads", help="CPU threads of each Warp launch in a worker."),
) -> None:
    """Simulate a dataset of random surface errors into a Zarr store, on Dask.

    Each sample's deformation (m) and intensity on the probe sphere are written by the worker
    that made it; a failed sample is recorded with its reason and the others go on. Exit
    status 1 when some samples failed (rerun with --resume to retry them).
    """
    from raysim.dataset import generate, load_spec
    from raysim.dataset.run import check_run_options

    loaded = load_spec(spec)
    check_run_options(loaded, output, workers=workers, scheduler=scheduler, device=device,
                      threads=threads, resume=resume)
    with progress_bar(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn()) as bar:
        task = bar.add_task(f"dataset {loaded.name}", total=loaded.samples)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=round(fraction * loaded.samples),
                       description=f"dataset {loaded.name}: {stage}")

        result = generate(loaded, output, workers=workers, scheduler=scheduler, resume=resume,
                          device=device, threads=threads, progress=report)
    say(result.summary())
    if result.failed or result.ideal_failures:
        raise typer.Exit(code=1)
