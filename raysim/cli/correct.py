"""``raysim correct``: actuator commands from a SurfaceMap, the residual they leave, the gain they
buy (solver.correction_io)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, say


def _screws(text: str) -> tuple[tuple[float, float], ...]:
    from solver.errors import SolverError

    try:
        pairs = tuple(tuple(float(v) for v in item.split(",")) for item in text.split(";") if item.strip())
    except ValueError as exc:
        raise SolverError(f"--screws {text!r}: give u,v pairs separated by ';' ({exc})") from exc
    if not pairs or any(len(p) != 2 for p in pairs):
        raise SolverError(f"--screws {text!r}: give u,v pairs separated by ';', e.g. 0.2,0.2;0.2,0.8;0.8,0.5")
    return pairs  # type: ignore[return-value]


@app.command("correct")
def correct_command(
    surface_map: Path = typer.Argument(..., help="SurfaceMap NetCDF (raysim invert's output)."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder to write the commands, the "
                                                             "predicted residual and the summary in."),
    scene: Path | None = typer.Option(None, help="Scene TOML whose \\[panels] give the panel layout "
                                                 "(default: the scene the map's source FieldMap records)."),
    actuators: Path | None = typer.Option(None, help="Actuator file: CSV with columns id,x_m,y_m,panels"
                                                     "\\[,min_m,max_m] or TOML \\[\\[actuator]] tables."),
    layout: str = typer.Option("corners", help="Without --actuators: corners (one actuator per panel "
                                               "corner, shared by the panels meeting there) or screws."),
    screws: str = typer.Option("0.2,0.2;0.2,0.8;0.8,0.5",
                               help="--layout screws: screw positions u,v on each panel (u across the "
                                    "ring, v along it, 0..1), ';' between screws."),
    remove: str = typer.Option("piston,tilt", help="Terms left to pointing and focus, removed before "
                                                   "fitting: any of piston,tilt,focus, or none."),
    unit: str = typer.Option("um", help="Unit of the commands: um, mm or mil."),
    stroke: float | None = typer.Option(None, help="Actuator range +- this many UNIT (generated "
                                                   "layouts; a file gives min_m/max_m per actuator)."),
    frequency: list[float] = typer.Option([], "--frequency", help="Observing frequency (Hz) for the "
                                                                  "Ruze efficiency; repeat for more."),
    zernike_order: int = typer.Option(4, "--zernike-order", help="Highest radial order of the Noll "
                                                                 "terms fitted to map and residual."),
) -> None:
    """Least-squares actuator commands for a measured surface; a positive command moves the
    surface along +z (toward the focus) by that many UNIT. Writes commands.csv, commands.toml,
    residual.nc (predicted surface after the correction), zernike.csv and summary.txt."""
    from raysim.errors import RaysimError
    from solver.correction_io import UNITS, run_correct, summary_lines

    if output.exists() and not output.is_dir():
        raise RaysimError(f"{output}: is a file, give a folder")
    if actuators is not None and layout != "corners":
        raise RaysimError("give --actuators or --layout, not both")
    if unit not in UNITS:
        raise RaysimError(f"unknown --unit {unit!r}: choose {', '.join(UNITS)}")
    run = run_correct(surface_map, output, scene=scene, actuators=actuators,
                      layout_kind=None if actuators is not None else layout, remove=remove,
                      unit=unit, frequencies=frequency, zernike_order=zernike_order,
                      screws=_screws(screws), stroke=None if stroke is None else stroke * UNITS[unit])
    for line in summary_lines(run):
        say(line)
    say(f"wrote {', '.join(str(p) for p in run.files)}")
