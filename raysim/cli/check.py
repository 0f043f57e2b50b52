"""``raysim check``: GO against a wave engine on a dish, per frequency (raysim.pipeline.check)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, note, progress_bar, say
from raysim.cli.tables import check_json_path, json_option, json_to_stdout, print_table, write_json
from raysim.errors import RaysimError
from raysim.optics.fast import DEFAULT_TOL


@app.command()
def check(
    source: Path = typer.Argument(..., help="Scene TOML file (or a shipped example's name), or a mesh "
                                            "file of the dish (STL, PLY, OBJ, GLB), fitted to its "
                                            "paraboloid."),
    output: Path = typer.Option(..., "-o", "--output",
                                help="Folder for check.html, check.nc and figures/ (a new folder, or "
                                     "an earlier check's, replaced once the new one is complete)."),
    frequency: list[float] | None = typer.Option(None, "--frequency",
                                                 help="Frequency in Hz; repeat for several (default: "
                                                      "the scene's; a mesh needs one)."),
    deformation: str = typer.Option("auto", "--deformation",
                                    help="auto (the scene's, else the mix), scene, or mix (gravity-like "
                                         "astigmatism plus actuator bumps)."),
    rms_um: float = typer.Option(100.0, "--rms-um", help="RMS of the mix over the aperture (um)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the mix's shape."),
    gap_m: float | None = typer.Option(None, "--gap-m",
                                       help="Panel gap (m) of a generated dish: its panel layout, or "
                                            "8 rings of 6 to 48 panels."),
    wave: str = typer.Option("auto", "--wave",
                             help="Wave engine: auto (PO + PTD wherever its samples fit the memory, "
                                  "else go+edge; the expected time is printed first), po, po+ptd "
                                  "or go+edge (its data take seconds at any frequency)."),
    sphere: str | None = typer.Option(None, "--sphere",
                                      help="Probe-sphere cells NTHETAxNPHI, e.g. 90x360 (default: "
                                           "the scene's)."),
    grid: int = typer.Option(256, "--grid", help="Aperture grid points across D of the inversions."),
    refine: int = typer.Option(3, "--refine", help="Refinement iterations of every inversion."),
    refine_model: str = typer.Option("auto", "--refine-model",
                                     help="Model of the wave-aware refinement: auto (the data's own), "
                                          "go+edge, po, po+ptd, none."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    radiator: str = typer.Option(
        "fast", "--radiator",
        help="PO + PTD's sums (wave engine, wave models, and the engine rule's cost): fast (the "
             "multilevel sum where cheaper) or direct (the reference sum)."),
    radiator_tol: float = typer.Option(DEFAULT_TOL, "--radiator-tol",
                                       help="Relative RMS accuracy of the fast radiator, in [1e-12, 1)."),
    sphere_radius: float | None = typer.Option(None, "--sphere-radius",
                                               help="Mesh only: probe-sphere radius R (m), default 0.3 F."),
    focal_length: float | None = typer.Option(None, "--focal-length",
                                              help="Mesh only: F (m) instead of the fitted one."),
    mesh_unit: float | None = typer.Option(None, "--mesh-unit",
                                           help="Mesh only: metres per file unit (0.001 for a file "
                                                "in millimetres; default 1)."),
    resolution: float | None = typer.Option(None, "--resolution",
                                            help="GO triangle edge (m) of a generated dish; on a mesh "
                                                 "file, the GO rays' spacing on its faces (default "
                                                 "0.15)."),
    json_path: str | None = json_option(),
) -> None:
    """Does GO hold for this dish at these frequencies? GO against PO + PTD or go+edge.

    Per frequency: the ideal intensity's and FA's differences (maps and theta bands), the
    surface error the GO assumption costs (the wave data inverted with GO, and with the
    wave-aware refinement), and the panel gaps' signature. Prints the verdict and a table.
    """
    from raysim.pipeline.check import source_inputs, summary_rows, verdict_lines, write_check
    from raysim.pipeline.check_inputs import parse_grid

    if json_path not in (None, "-") and Path(json_path).resolve().is_relative_to(Path(output).resolve()):
        # the check replaces its folder whole: the JSON there overwrote check.nc, or made the
        # next run refuse the folder as holding a file that is not the check's
        raise RaysimError(f"--json {json_path}: lies in the check's output folder {output}, which "
                          "each run replaces whole; write it beside the folder")
    check_json_path(json_path, [("source", source)])
    if json_path not in (None, "-"):  # and the files a scene names (read only for a --json file)
        check_json_path(json_path, source_inputs(source))
    with progress_bar() as bar:
        task = bar.add_task("check", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"check: {stage}")

        page, ds = write_check(source, output, frequencies=frequency, deformation=deformation,
                               rms=rms_um * 1e-6, seed=seed, gap_m=gap_m, wave=wave,
                               grid=parse_grid(sphere), N=grid, refine=refine,
                               refine_model=refine_model, device=device, sphere_radius=sphere_radius,
                               focal_length=focal_length, resolution=resolution, progress=report,
                               mesh_unit=mesh_unit, notice=note,
                               radiator=radiator, radiator_tol=radiator_tol)
    rows, title = summary_rows(ds), "GO against the wave engine"
    write_json(json_path, "check", title, _records(ds), rows, verdict=verdict_lines(ds),
               page=str(page))
    if json_to_stdout(json_path):
        return
    print_table(title, rows)
    for line in verdict_lines(ds):
        say(line)
    say(f"{page}")


def _records(ds) -> list[dict]:
    """Per frequency, every per-frequency number of check.nc (SI units: m, s, fractions)."""
    names = [k for k in ds.data_vars if ds[k].dims == ("frequency",)]
    return [{"frequency_hz": float(f), **{k: ds[k].values[i].item() for k in names}}
            for i, f in enumerate(ds["frequency"].values)]
