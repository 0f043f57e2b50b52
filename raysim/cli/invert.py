"""``raysim invert`` (solver.run) and ``raysim paper`` (raysim.pipeline.paper)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import typer

from raysim.cli.common import (
    app,
    file_attrs,
    note,
    output_file,
    output_path,
    progress_bar,
    say,
    scene_inputs,
)
from raysim.cli.tables import check_json_path, json_option, json_to_stdout, write_json
from raysim.optics.fast import DEFAULT_TOL


@app.command("invert")
def invert_command(
    field: Path = typer.Argument(..., help="FieldMap NetCDF (simulated or measured scan)."),
    output: Path = typer.Option(..., "-o", "--output", parser=output_file,
                                help="SurfaceMap NetCDF to write."),
    solver: str = typer.Option("multigrid", help="direct, multigrid, gauss-seidel, sor or fft."),
    grid: int = typer.Option(256, help="Aperture grid points across the diameter, 16 to 4096."),
    rim: Path | None = typer.Option(None, help="Rim targets, CSV with header x,y,dz (m), at least 8 "
                                               "between 0.8 and 1.05 times the rim radius."),
    remove: str = typer.Option("", help="Terms to remove, e.g. piston,tilt,focus."),
    refine: int = typer.Option(3, help="Model refinement iterations, 0 to 50 (0: the paper's "
                                       "linear answer)."),
    model: str | None = typer.Option(
        None, help="Forward model of the refinement: go, po, po+ptd or go+edge (default: the one "
                   "that made the data, its FieldMap method; go for a measured scan). Each PO "
                   "iteration is a PO run: a few seconds at 0.3 GHz on the paper's dish on two "
                   "cores, about f^2 log f beyond; go+edge (geometric wave plus rim "
                   "diffraction) takes seconds, growing with f."),
    refine_method: str = typer.Option(
        "auto", "--refine-method",
        help="auto (the default: Gauss-Newton with the model's exact Jacobian where at least 20 "
             "LSQR iterations fit about 10 min on two cores (4.4e10 pair evaluations of a po or "
             "po+ptd model with its radiator), as many as fit in as few steps as they fill: the "
             "paper's dish on 90 x 360 at 0.1 GHz 3 x 60, 0.3 GHz 2 x 51, 0.6 GHz 1 x 31; else the "
             "defect correction, and the SurfaceMap's gn_choice says why), defect "
             "(the defect correction alone) or gauss-newton (then Gauss-Newton whatever the cost; "
             "po or po+ptd models, in this process)."),
    gn_steps: int | None = typer.Option(
        None, "--gn-steps",
        help="gauss-newton: outer steps, 1 to 50 (default 3; each relinearises the model; the "
             "loop also stops at the noise level or when the misfit stalls)."),
    gn_lsqr: int | None = typer.Option(
        None, "--gn-lsqr",
        help="gauss-newton: LSQR iterations per step, 1 to 1000 (default 60; each two PO "
             "radiations; LSQR stops earlier when the misfit reaches the noise level)."),
    gn_coarse: int | None = typer.Option(
        None, "--gn-coarse",
        help="gauss-newton: how many of the first steps solve their LSQR problem on one sphere "
             "cell in eight (every 2nd theta ring, every 4th phi column; each iteration about eight "
             "times cheaper), their step still judged on all cells (default 0; fewer than "
             "--gn-steps)."),
    radiator: str | None = typer.Option(
        None, "--radiator",
        help="po, po+ptd model: fast (the multilevel sum of the elements' fields, in the model's "
             "fields and Gauss-Newton's Jacobian, where its cost estimate beats the direct sum) "
             "or direct (the reference sum); default fast."),
    radiator_tol: float | None = typer.Option(
        None, "--radiator-tol",
        help=f"po, po+ptd model: relative RMS accuracy of the fast radiator, in [1e-12, 1); "
             f"default {DEFAULT_TOL:g}."),
    panels_csv: Path | None = typer.Option(None, help="Write the per-panel adjustment table."),
    gain: str = typer.Option(
        "auto", help="auto (known for simulated data, estimated for a measured scan), known "
                     "(trust the scan's scale) or power (estimate it from the total power; the "
                     "map then has the unobservable delta_c shape removed, its coefficient "
                     "recorded)."),
    iterations: int | None = typer.Option(None, help="Fixed sweeps for gauss-seidel / sor."),
    device: str = typer.Option("cpu", help="Warp device of the refinement's model: cpu or cuda."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="po, po+ptd model: compute each model field in blocks of sphere "
                                  "points on the Dask scheduler at tcp://HOST:PORT."),
    workers: int | None = typer.Option(
        None, "--workers", help="po, po+ptd model: blocks on a local Dask cluster of N worker "
                                "processes (started when the model first runs)."),
) -> None:
    """Recover the surface deformation from an intensity scan (FieldMap -> SurfaceMap)."""
    from solver.gauss_newton import GaussNewtonOptions
    from solver.options import check_options
    from solver.run import run_invert, summary

    given = {"iterations": gn_steps, "inner": gn_lsqr, "coarse": gn_coarse}
    gauss_newton = GaussNewtonOptions(**{k: v for k, v in given.items() if v is not None})
    check_options(solver=solver, N=grid, refine=refine, gain=gain, iterations=iterations,
                  remove=remove, model=model, refine_method=refine_method,
                  blocks=bool(scheduler) or workers is not None, radiator=radiator,
                  radiator_tol=radiator_tol)
    if (radiator, radiator_tol) != (None, None):
        _radiator_applies(field, model, refine)
    radiator = "fast" if radiator is None else radiator
    radiator_tol = DEFAULT_TOL if radiator_tol is None else radiator_tol
    inputs = [("FieldMap", field), ("rim-target file", rim), *scene_inputs(field)]
    output_path(output, inputs)
    if panels_csv is not None:
        output_path(panels_csv, [*inputs, ("SurfaceMap output", output)])
    with progress_bar() as bar:
        task = bar.add_task("invert", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"refine: {stage}")

        with _model_blocks(scheduler, workers, device):
            result = run_invert(field, output, solver=solver, N=grid, rim_csv=rim, remove=remove,
                                refine=refine, gain=gain, iterations=iterations, device=device,
                                panels_csv=panels_csv, model=model, progress=report,
                                refine_method=refine_method, gauss_newton=gauss_newton,
                                log=note, radiator=radiator, radiator_tol=radiator_tol)
    for line in summary(result):
        say(line)
    say(f"wrote {output}")


def _radiator_applies(field: Path, model: str | None, refine: int) -> None:
    """Refuse --radiator and --radiator-tol where no po or po+ptd model runs (they were
    accepted and did nothing, where simulate refuses them): the refinement's model is the one
    named, else the data's (its FieldMap's method). A FieldMap that cannot be read is left to
    the inversion's own message."""
    from solver.forward import model_for_method

    attrs = file_attrs(field)
    if attrs is None:  # the inversion says what is wrong with the file
        return
    method = str(attrs.get("method", ""))
    name = "none (--refine 0)" if refine == 0 else (model or model_for_method(method))
    if name not in ("po", "po+ptd"):
        from solver.errors import SolverError

        raise SolverError(f"--radiator and --radiator-tol apply to a po or po+ptd refinement model; "
                          f"this run's model is {name}" + ("" if model or refine == 0 else
                                                           f" (from the data's method {method!r}); "
                                                           "choose one with --model"))


@contextlib.contextmanager
def _model_blocks(scheduler: str | None, workers: int | None, device: str) -> Iterator[None]:
    """With --scheduler or --workers, the wave models run in blocks on Dask (raysim.distributed)."""
    if not scheduler and workers is None:
        yield
        return
    from raysim.distributed import block_runner
    from solver.forward import distributed

    with block_runner(scheduler, workers=workers, device=device) as runner, distributed(runner):
        yield


#: paper's options that only the PO & PTD sweep reads
_PO_OPTIONS = ("frequencies", "coarse_3ghz", "fields", "wave_max_ghz", "radiator", "radiator_tol")


def _only_with_po(ctx: typer.Context) -> None:
    """Refuse the --po options given on the command line without --po."""
    from raysim.errors import RaysimError

    # by name: typer carries its own copy of click, whose ParameterSource is another enum
    given = [f"--{name.replace('_', '-')}" for name in _PO_OPTIONS
             if getattr(ctx.get_parameter_source(name), "name", None) == "COMMANDLINE"]
    if given:
        raise RaysimError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to --po only")


@app.command("paper")
def paper_command(
    ctx: typer.Context,
    scale: float = typer.Option(1.0, help="Scale of the paper's Eq. 8 deformation (1: 1.2 mm peak "
                                          "to peak), 0 to 50."),
    grid: int = typer.Option(256, help="Aperture grid points across the diameter, 16 to 4096."),
    refine: int = typer.Option(3, help="GO refinement iterations of raysim's default row, 0 to 50."),
    device: str = typer.Option("cpu", help="Warp device: cpu or cuda."),
    po: bool = typer.Option(False, "--po", help="The PO & PTD frequency sweep (Table 3) instead of "
                                               "the GO case (Table 2). About 11 min on two cores, 7 of "
                                               "them the 3 GHz data."),
    frequencies: str = typer.Option("0.1e9,0.3e9,0.6e9,1e9,3e9", "--frequencies",
                                    help="--po: frequencies (Hz), comma-separated, 1e6 to 1e11."),
    coarse_3ghz: str | None = typer.Option(
        None, "--coarse-3ghz",
        help="--po: sphere grid (n_theta x n_phi) at frequencies of 2 GHz and above (the sweep's "
             "3 GHz row); 90x360 below. Default: 90x360 with --radiator fast (its cost barely "
             "depends on the points: 90x36 saves about 10 % at 3 GHz), 90x36 with direct."),
    fields: Path | None = typer.Option(None, "--fields",
                                       help="--po: folder to keep each FieldMap in and reuse it from."),
    wave_max_ghz: float | None = typer.Option(
        None, "--wave-max-ghz",
        help="--po: highest frequency (GHz) of the PO + PTD model refinement row (default 1 with "
             "--radiator fast, about a minute a row there; 0.3 with direct, whose 1 GHz row "
             "takes 35 min)."),
    radiator: str = typer.Option(
        "fast", "--radiator",
        help="--po: the PO + PTD sums of the data and the wave refinement: fast (the multilevel "
             "sum where cheaper) or direct (the reference sum)."),
    radiator_tol: float | None = typer.Option(
        None, "--radiator-tol",
        help=f"--po: relative RMS accuracy of the fast radiator, in [1e-12, 1) (default "
             f"{DEFAULT_TOL:g})."),
    json_path: str | None = json_option(),
) -> None:
    """The paper's tables beside raysim's: the GO case (Table 2), or with --po the PO & PTD
    frequency sweep (Table 3)."""
    from dataclasses import asdict

    from raysim.pipeline import paper
    from solver.options import check_options

    check_json_path(json_path)
    check_options(radiator=radiator, radiator_tol=radiator_tol)
    if not po:  # the GO case sums no fields and sweeps no frequencies: say so, not ignore them
        _only_with_po(ctx)
    radiator_tol = DEFAULT_TOL if radiator_tol is None else radiator_tol
    if po:
        options = paper.sweep_options(frequencies, coarse_3ghz, N=grid, refine=refine,
                                      wave_max_ghz=wave_max_ghz, radiator=radiator,
                                      radiator_tol=radiator_tol)
        rows = paper.po_sweep(**options, device=device, fields_dir=fields,
                              log=lambda line: note(f"paper: {line}"), radiator=radiator,
                              radiator_tol=radiator_tol)
        lines = paper.sweep_lines(rows, N=grid, refine=refine,
                                  wave_max_ghz=options["wave_max_hz"] / 1e9)
    else:
        rows = paper.compare(scale=scale, N=grid, refine=refine, device=device)
        lines = paper.compare_lines(rows, scale=scale, N=grid)
    write_json(json_path, "paper --po" if po else "paper", lines[0], [asdict(row) for row in rows],
               lines=lines, grid=grid, refine=refine)
    if json_to_stdout(json_path):
        return
    for line in lines:
        say(line)
