"""``raysim simulate``: a scene -> a FieldMap (raysim.simulate over the optics engines)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, console, out, output_path


@app.command()
def simulate(
    scene: Path = typer.Argument(..., help="Scene TOML file (see scenes/)."),
    output: Path = typer.Option(..., "-o", "--output", help="FieldMap NetCDF file to write."),
    method: str | None = typer.Option(None, "--method",
                                      help="go (geometric optics), po, po+ptd, or go+edge (GO wave plus edge "
                                           "diffraction, for high frequencies) (default: the "
                                           "scene's method key, else go)."),
    frequency: float | None = typer.Option(None, "--frequency", help="Override the scene's frequency (Hz)."),
    n_theta: int | None = typer.Option(None, "--n-theta", help="Cells in theta (polar angle from -z)."),
    n_phi: int | None = typer.Option(None, "--n-phi", help="Cells in phi (azimuth)."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    total: bool = typer.Option(False, "--total",
                               help="Wave methods: intensity of scattered plus incident field."),
    save_field: bool = typer.Option(False, "--save-field",
                                    help="Wave methods: also store the complex field components E_re, E_im."),
    samples_per_wavelength: float | None = typer.Option(
        None, "--samples-per-wavelength",
        help="PO: Gauss points per wavelength along mesh face edges (default 1.5; 3-4 for "
             "field points near the surface, far from its focus)."),
    edges: str | None = typer.Option(
        None, "--edges",
        help="po+ptd: rim (the outer rim, default) or all (also every panel edge beside a gap)."),
) -> None:
    """Simulate a scene: intensity of the ideal and deformed reflector on the probe sphere.

    Writes a FieldMap (NetCDF): intensity relative to the incident plane wave on (theta, phi)
    cells, theta from -z at the focus and phi = atan2(y, x), both in radians in the file.
    """
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from raysim.maps.fieldmap import save
    from raysim.scene.scene import load_scene
    from raysim.simulate import simulate as run
    from raysim.simulate import summary

    loaded = load_scene(scene).with_overrides(frequency, n_theta, n_phi)
    method = method or loaded.method
    output_path(output)
    with Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                  console=console, transient=True) as bar:
        task = bar.add_task(f"{method} {loaded.name}", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"{method} {loaded.name}: {stage}")

        ds = run(loaded, method=method, device=device, progress=report, total=total,
                 save_field=save_field, samples_per_wavelength=samples_per_wavelength, edges=edges)
    save(ds, output)
    out.print(f"{output}: {summary(ds)}", highlight=False, soft_wrap=True)
