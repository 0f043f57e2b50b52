"""``raysim render`` (raysim.render) and ``raysim report`` (raysim.pipeline.report)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, note, output_path, say, scene_inputs


@app.command()
def render(
    file: Path = typer.Argument(..., help="FieldMap or SurfaceMap NetCDF file."),
    output: str = typer.Option(..., "-o", "--output", help="PNG file to write."),
    kind: str | None = typer.Option(
        None, "--kind", help="3d, map or cut (default: 3d for a FieldMap, map for a SurfaceMap)."),
    size: str | None = typer.Option(None, "--size", help="Width x height in pixels, e.g. 1600x1200."),
    quantity: str | None = typer.Option(
        None, "--quantity", help="FieldMap colour: fa (I_ideal/I_def - 1, the default), intensity, or "
                                 "normalized (intensity over the ideal GO law). Not for a SurfaceMap."),
) -> None:
    """Draw a FieldMap (hemisphere over the dish) or a SurfaceMap (deformation in um) as PNG.

    Works with no display (EGL off-screen rendering).
    """
    from raysim.maps.netcdf import check_file
    from raysim.render import render as run
    from raysim.render.api import check_output_name
    from raysim.render.backend import RenderError

    check_file(file, RenderError)  # before the output's folder is made for a missing input
    # an input named as the output first (the message says what would be lost), then the name
    # as typed (a Path drops the trailing slash of "x.png/")
    output_path(Path(output), [("file to draw", file), *scene_inputs(file)])
    written = run(file, check_output_name(output), kind=kind, size=size, quantity=quantity)
    say(f"{written}")


@app.command()
def report(
    source: Path = typer.Argument(..., help="Scene TOML file (or a shipped example's name), or a "
                                            "FieldMap (.nc) simulated or measured."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="Folder for report.html, its figures and data (a new folder, or "
                                     "an earlier report's, replaced once the new one is complete)."),
    method: str | None = typer.Option(None, "--method",
                                      help="Simulation method: go, po, po+ptd or go+edge (default: the "
                                           "scene's method key, else go)."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    solver: str | None = typer.Option(None, "--solver", help="Poisson solver (default: the solver's)."),
    grid: int | None = typer.Option(None, "--grid",
                                    help="Aperture grid points across D, 16 to 4096 (default 256)."),
    refine: int | None = typer.Option(None, "--refine",
                                      help="Model refinement iterations, 0 to 50 (0: the paper's "
                                           "linear answer; default 3)."),
    invert: bool = typer.Option(True, "--invert/--no-invert",
                                help="--no-invert leaves the inversion out: the field's figures only."),
) -> None:
    """Simulate, invert and draw a scene: an HTML report mirroring the paper's Figs. 8-10.

    The page embeds its figures; beside it are figures/ (the PNGs), field.nc (the simulated
    FieldMap) when the source is a scene, and surface.nc (the SurfaceMap) unless --no-invert.
    Given a FieldMap instead of a scene, the simulation is skipped and no field.nc is written.
    """
    from raysim.files import check_output_folder
    from raysim.pipeline.report import page_warnings
    from raysim.pipeline.report import report as run
    from raysim.render.backend import RenderError

    # a FieldMap's scene names files (its mesh, maps, tables) the report reads for the truth:
    # the folder it replaces must not hold them (a scene is checked with its files by the run)
    check_output_folder(output, scene_inputs(source), RenderError)
    page = run(source, output, method=method, device=device, solver=solver, grid=grid, refine=refine,
               invert=invert,
               progress=lambda stage, fraction: note(f"report: {stage}"))
    for line in page_warnings(page, source):  # what the page says first, said where the command ran
        say(f"WARNING: {line}")
    say(f"{page}")
