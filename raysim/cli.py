"""The ``raysim`` command: a thin typer layer over the Python API.

Units at this edge: lengths in metres, frequencies in Hz, angles in degrees where an option
name ends in ``-deg``. Errors a user can cause end with one line on stderr and exit status 2.
"""

from __future__ import annotations

import sys
import tempfile
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
    """Check an output file can be written before any work goes into it; return it."""
    path = path.expanduser()
    if path.is_dir():
        raise RaysimError(f"{path}: is a folder, give a file name")
    parent = path.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise RaysimError(f"{path}: cannot create its folder ({exc.strerror})") from exc
    try:  # a real probe: permissions alone do not tell (root, read-only mounts, /proc)
        with tempfile.NamedTemporaryFile(dir=parent, prefix=".raysim-probe-"):
            pass
    except OSError as exc:
        raise RaysimError(f"{path}: cannot write in {parent} ({exc.strerror})") from exc
    return path


# --- simulate (raysim.go, raysim.po, raysim.ptd) ------------------------------------------
@app.command()
def simulate(
    scene: Path = typer.Argument(..., help="Scene TOML file (see scenes/)."),
    output: Path = typer.Option(..., "-o", "--output", help="FieldMap NetCDF file to write."),
    method: str | None = typer.Option(None, "--method",
                                      help="go (geometric optics), po, or po+ptd (default: the "
                                           "scene's method key, else go)."),
    frequency: float | None = typer.Option(None, "--frequency", help="Override the scene's frequency (Hz)."),
    n_theta: int | None = typer.Option(None, "--n-theta", help="Cells in theta (polar angle from -z)."),
    n_phi: int | None = typer.Option(None, "--n-phi", help="Cells in phi (azimuth)."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    total: bool = typer.Option(False, "--total", help="PO: intensity of scattered plus incident field."),
    save_field: bool = typer.Option(False, "--save-field",
                                    help="PO: also store the complex field components E_re, E_im."),
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

    from raysim.field import save
    from raysim.scene import load_scene
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



# --- invert, paper (solver) ------------------------------------------------------------


@app.command("invert")
def invert_command(
    field: Path = typer.Argument(..., help="FieldMap NetCDF (simulated or measured scan)."),
    output: Path = typer.Option(..., "-o", "--output", help="SurfaceMap NetCDF to write."),
    solver: str = typer.Option("multigrid", help="direct, multigrid, gauss-seidel, sor or fft."),
    grid: int = typer.Option(256, help="Aperture grid points across the diameter (>= 16)."),
    rim: Path | None = typer.Option(None, help="Rim targets, CSV with header x,y,dz (m)."),
    remove: str = typer.Option("", help="Terms to remove, e.g. piston,tilt,focus."),
    refine: int = typer.Option(3, help="Model refinement iterations (0: the paper's linear answer)."),
    model: str | None = typer.Option(
        None, help="Forward model of the refinement: go, po or po+ptd (default: the one that made "
                   "the data, its FieldMap method; go for a measured scan). PO costs about 45 s "
                   "per iteration at 0.3 GHz on two cores, growing with f^2."),
    panels_csv: Path | None = typer.Option(None, help="Write the per-panel adjustment table."),
    gain: str = typer.Option("power", help="power (estimate the scan's scale) or none."),
    iterations: int | None = typer.Option(None, help="Fixed sweeps for gauss-seidel / sor."),
    device: str = typer.Option("cpu", help="Warp device of the refinement's model: cpu or cuda."),
) -> None:
    """Recover the surface deformation from an intensity scan (FieldMap -> SurfaceMap)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from solver.run import run_invert, summary

    # the bar appears with the refinement's first report: a user error before it stays one line
    bar = Progress(TextColumn("{task.description}"), BarColumn(), TimeElapsedColumn(),
                   console=console, transient=True)
    task = bar.add_task("invert", total=1.0)

    def report(stage: str, fraction: float) -> None:
        if not bar.live.is_started:
            bar.start()
        bar.update(task, completed=fraction, description=f"refine: {stage}")

    try:
        result = run_invert(field, output_path(output), solver=solver, N=grid, rim_csv=rim,
                            remove=remove, refine=refine, gain=gain, iterations=iterations,
                            device=device, panels_csv=panels_csv, model=model, progress=report)
    finally:
        if bar.live.is_started:
            bar.stop()
    for line in summary(result):
        out.print(line, highlight=False, soft_wrap=True)
    out.print(f"wrote {output}", highlight=False, soft_wrap=True)


@app.command("paper")
def paper_command(
    scale: float = typer.Option(1.0, help="Scale of the paper's Eq. 8 deformation (1: 1.2 mm)."),
    grid: int = typer.Option(256, help="Aperture grid points across the diameter."),
    refine: int = typer.Option(3, help="GO refinement iterations of raysim's default row."),
    device: str = typer.Option("cpu", help="Warp device: cpu or cuda."),
    po: bool = typer.Option(False, "--po", help="The PO & PTD frequency sweep (Table 3) instead of "
                                               "the GO case (Table 2). Slow on a CPU: about an hour."),
    frequencies: str = typer.Option("0.1e9,0.3e9,0.6e9,1e9,3e9", "--frequencies",
                                    help="--po: frequencies (Hz), comma-separated."),
    coarse_3ghz: str = typer.Option("90x36", "--coarse-3ghz",
                                    help="--po: sphere grid (n_theta x n_phi) at 2 GHz and above "
                                         "(90x360 below); 90x360 for the full grid."),
    fields: Path | None = typer.Option(None, "--fields",
                                       help="--po: folder to keep each FieldMap in and reuse it from."),
    wave_max_ghz: float = typer.Option(0.3, "--wave-max-ghz",
                                       help="--po: highest frequency (GHz) of the PO + PTD model "
                                            "refinement row (about 5 min at 0.3 GHz, grows as f^2)."),
) -> None:
    """The paper's tables beside raysim's: the GO case (Table 2), or with --po the PO & PTD
    frequency sweep (Table 3)."""
    if po:
        _paper_po(grid, refine, device, frequencies, coarse_3ghz, fields, wave_max_ghz)
        return
    from solver.paper import compare

    rows = compare(scale=scale, N=grid, refine=refine, device=device)
    out.print(f"paper GO case, Eq. 8 x {scale:g}, N = {grid}, 90 x 360 cells", highlight=False)
    out.print(f"{'method':44s} {'paper RRMS':>10s} {'paper s':>9s} {'RRMS':>9s} {'RMS um':>8s} "
              f"{'time s':>7s}", highlight=False, soft_wrap=True)
    for row in rows:
        paper = f"{row.paper_rrms * 100:.2f} %" if row.paper_rrms is not None else "-"
        out.print(f"{row.method:44s} {paper:>10s} {row.paper_seconds:>9s} "
                  f"{row.rrms * 100:7.3f} % {row.rms_m * 1e6:8.2f} {row.seconds:7.2f}",
                  highlight=False, soft_wrap=True)


def _paper_po(grid: int, refine: int, device: str, frequencies: str, coarse: str,
              fields: Path | None, wave_max_ghz: float) -> None:
    """``raysim paper --po``: Table 3 with the project's PO + PTD data, the paper beside it."""
    from solver.invert import DEFAULT_SOLVER
    from solver.paper import po_sweep

    try:
        freqs = [float(f) for f in frequencies.split(",") if f.strip()]
        n_theta, n_phi = (int(n) for n in coarse.lower().split("x"))
    except ValueError as exc:
        raise RaysimError(f"--frequencies takes Hz separated by commas and --coarse-3ghz a grid "
                          f"such as 90x36 ({exc})") from exc
    if not freqs or min(freqs) <= 0 or n_theta < 1 or n_phi < 1:
        raise RaysimError("--frequencies must be positive (Hz) and --coarse-3ghz at least 1x1")
    rows = po_sweep(freqs, N=grid, coarse=(n_theta, n_phi), refine=refine, device=device,
                    fields_dir=fields, log=lambda line: console.print(f"paper: {line}", highlight=False),
                    wave_max_hz=wave_max_ghz * 1e9)
    out.print(f"paper Table 3: PO & PTD (rim) data, Eq. 8 (1.2 mm), R = 10 m, N = {grid}", highlight=False)
    out.print(f"paper setting: FDM + Gauss-Seidel, 1000 iterations, linear; GO: {DEFAULT_SOLVER} "
              f"with {refine} GO refinements; wave: {DEFAULT_SOLVER} with {refine} PO + PTD "
              f"refinements (the default for PO + PTD data; up to {wave_max_ghz:g} GHz here)",
              highlight=False, soft_wrap=True)
    out.print(f"{'f GHz':>6s} {'sphere grid':>11s} {'paper RMS um':>12s} {'paper RRMS':>10s} "
              f"{'RMS um':>8s} {'RRMS':>8s} {'GO RMS um':>10s} {'GO RRMS':>9s} "
              f"{'wave RMS um':>11s} {'wave RRMS':>9s} {'sim s':>7s}", highlight=False, soft_wrap=True)
    for r in rows:
        paper_rms = f"{r.paper_rms_m * 1e6:.2f}" if r.paper_rms_m is not None else "-"
        paper_rrms = f"{r.paper_rrms * 100:.2f} %" if r.paper_rrms is not None else "-"
        wave_rms = f"{r.wave_rms_m * 1e6:.2f}" if r.wave_rms_m is not None else "-"
        wave_rrms = f"{r.wave_rrms * 100:.2f} %" if r.wave_rrms is not None else "-"
        out.print(f"{r.frequency_hz / 1e9:6g} {f'{r.n_theta} x {r.n_phi}':>11s} {paper_rms:>12s} "
                  f"{paper_rrms:>10s} {r.rms_m * 1e6:8.2f} {r.rrms * 100:6.2f} % "
                  f"{r.default_rms_m * 1e6:10.2f} {r.default_rrms * 100:7.2f} % {wave_rms:>11s} "
                  f"{wave_rrms:>9s} {r.seconds_simulate:7.0f}", highlight=False, soft_wrap=True)
    if any(r.n_phi != 360 for r in rows):
        out.print("coarse grids (fewer phi cells) keep the CPU time in check; the Eq. 8 "
                  "deformation is axially symmetric, so they lose nothing it can show",
                  highlight=False, soft_wrap=True)



# --- render, report (raysim.render) ----------------------------------------------------
@app.command()
def render(
    file: Path = typer.Argument(..., help="FieldMap or SurfaceMap NetCDF file."),
    output: Path = typer.Option(..., "-o", "--output", help="PNG file to write."),
    kind: str | None = typer.Option(
        None, "--kind", help="3d, map or cut (default: 3d for a FieldMap, map for a SurfaceMap)."),
    size: str | None = typer.Option(None, "--size", help="Width x height in pixels, e.g. 1600x1200."),
    quantity: str = typer.Option("fa", "--quantity",
                                 help="FieldMap colour: fa (I_ideal/I_def - 1), intensity, or normalized "
                                      "(intensity over the ideal GO law)."),
) -> None:
    """Draw a FieldMap (hemisphere over the dish) or a SurfaceMap (deformation in um) as PNG.

    Works with no display (EGL off-screen rendering).
    """
    from raysim.render import render as run

    written = run(file, output_path(output), kind=kind, size=size, quantity=quantity)
    out.print(f"{written}", highlight=False)


@app.command()
def report(
    source: Path = typer.Argument(..., help="Scene TOML file, or a FieldMap (.nc) simulated or measured."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder for report.html, its figures and data."),
    method: str | None = typer.Option(None, "--method",
                                      help="Simulation method: go, po or po+ptd (default: the "
                                           "scene's method key, else go)."),
    device: str = typer.Option("cpu", "--device", help="Warp device: cpu or cuda."),
    solver: str | None = typer.Option(None, "--solver", help="Poisson solver (default: the solver's)."),
    grid: int | None = typer.Option(None, "--grid",
                                    help="Aperture grid points across D (default: the solver's)."),
    refine: int | None = typer.Option(None, "--refine",
                                      help="GO refinement iterations (0: the paper's linear answer)."),
    invert: bool = typer.Option(True, "--invert/--no-invert",
                                help="--no-invert leaves the inversion out: the field's figures only."),
) -> None:
    """Simulate, invert and draw a scene: an HTML report mirroring the paper's Figs. 8-10.

    The page embeds its figures; the PNGs, field.nc and surface.nc are written beside it.
    Given a FieldMap instead of a scene, the simulation is skipped.
    """
    from raysim.render.report import report as run

    page = run(source, output, method=method, device=device, solver=solver, grid=grid, refine=refine,
               invert=invert,
               progress=lambda line: console.print(f"report: {line}", highlight=False))
    out.print(f"{page}", highlight=False)



# --- scan, rig (hardware) --------------------------------------------------------------

rig_app = typer.Typer(help="The scanning rig (track, slider, rotation, power meter).",
                      no_args_is_help=True)
app.add_typer(rig_app, name="rig")


def _vector3(text: str | None, option: str) -> tuple[float, float, float] | None:
    """'X,Y,Z' (m) to a tuple, or None."""
    if text is None:
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3:
        raise RaysimError(f"{option} '{text}': give three numbers X,Y,Z in metres")
    return values  # type: ignore[return-value]


@app.command()
def scan(
    plan: Path = typer.Argument(..., help="Scan plan (TOML), e.g. scenes/scan_demo.toml."),
    output: Path = typer.Option(..., "-o", "--output", help="Measured FieldMap to write (.nc)."),
    resource: list[str] | None = typer.Option(
        None, "--resource", help="Instrument address ROLE=VISA, ROLE meter or motion (twice)."),
    simulate: Path | None = typer.Option(
        None, "--simulate", help="Scan this FieldMap with a simulated rig on loopback sockets."),
    resume: bool = typer.Option(False, "--resume", help="Continue the journal of a stopped scan."),
    rig: Path | None = typer.Option(None, "--rig", help="Rig file (TOML) over the plan's."),
    journal: Path | None = typer.Option(None, "--journal", help="Journal file [OUTPUT.journal]."),
    from_journal: bool = typer.Option(
        False, "--from-journal", help="Write the FieldMap from the journal alone (no rig)."),
    seed: int | None = typer.Option(None, "--seed", help="Simulator: noise and drift seed."),
    noise_db: float | None = typer.Option(None, "--noise-db", help="Simulator: noise (dB rms)."),
    drift_db: float | None = typer.Option(None, "--drift-db",
                                          help="Simulator: drift amplitude (dB)."),
    centre_offset: str | None = typer.Option(
        None, "--centre-offset", help="Simulator: true track-centre offset X,Y,Z from the "
        "focus (m)."),
    time_scale: float | None = typer.Option(
        None, "--time-scale", help="Simulator: move-time factor (0 instant, 1 real time)."),
) -> None:
    """Scan the hemisphere with the rig (or a simulated one) into a measured FieldMap.

    Every completed sample is journaled to disk first; after a stop (Ctrl-C, kill, an
    instrument fault) the same command with --resume continues where it stopped.
    """
    import dataclasses
    import signal

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from hardware.plan import load_plan
    from hardware.session import fieldmap_from_journal, journal_path, parse_resources
    from hardware.session import scan as run_scan
    from raysim.field import save

    scan_plan = load_plan(plan, rig=rig)
    output = output_path(output)
    if from_journal:
        ds = fieldmap_from_journal(scan_plan, journal or journal_path(output))
        save(ds, output)
        out.print(f"wrote {output} from the journal: {ds.attrs['samples_measured']} of "
                  f"{ds.attrs['samples_expected']} samples")
        return
    overrides = {"seed": seed, "noise_db": noise_db, "drift_db": drift_db,
                 "centre_offset": _vector3(centre_offset, "--centre-offset"),
                 "time_scale": time_scale}
    for name in ("noise_db", "drift_db", "time_scale"):
        if overrides[name] is not None and not 0.0 <= overrides[name] < 1e3:
            raise RaysimError(f"--{name.replace('_', '-')} must be >= 0")
    sim = dataclasses.replace(scan_plan.simulator,
                              **{k: v for k, v in overrides.items() if v is not None})
    done = [0, 0]

    def on_signal(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, on_signal)
    columns = (TextColumn("scan"), BarColumn(), MofNCompleteColumn(), TextColumn("elapsed"),
               TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn())
    try:
        with Progress(*columns, console=console, disable=not console.is_terminal) as bar:
            task = bar.add_task("scan", total=None)

            def progress(steps_done: int, steps_total: int) -> None:
                if done[1] == 0:
                    bar.reset(task, total=steps_total, completed=steps_done)
                bar.update(task, completed=steps_done)
                done[:] = [steps_done, steps_total]

            result = run_scan(scan_plan, output, resources=parse_resources(resource),
                              simulate=simulate, sim=sim, resume=resume, journal=journal,
                              progress=progress)
    except KeyboardInterrupt:
        where = journal or journal_path(output)
        console.print(f"[bold red]interrupted:[/] {done[0]} of {done[1]} steps are in {where}; "
                      "run the same command with --resume to continue", highlight=False)
        raise typer.Exit(code=130) from None
    finally:
        signal.signal(signal.SIGTERM, previous)
    ds = result.fieldmap
    out.print(f"wrote {result.output}: {ds.attrs['samples_measured']} samples, "
              f"{result.steps_taken} of {result.steps_total} steps taken now "
              f"(journal {result.journal})")


@rig_app.command("park")
def rig_park(
    rig: Path = typer.Argument(..., help="Rig file (TOML), e.g. scenes/rig.toml."),
    resource: list[str] | None = typer.Option(
        None, "--resource", help="Motion controller address motion=VISA."),
    simulate: bool = typer.Option(False, "--simulate", help="Park a simulated rig."),
) -> None:
    """Move the probe to the park position that clears the optical path."""
    import math

    from hardware.rig import load_rig
    from hardware.session import park, parse_resources

    rig_obj, _ = load_rig(rig)
    slider, rotation = park(rig_obj, resources=parse_resources(resource), simulate=simulate)
    out.print(f"parked: slider {math.degrees(slider):.4f} deg, rotation "
              f"{math.degrees(rotation):.4f} deg")



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
