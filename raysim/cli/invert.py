"""``raysim invert`` (solver) and ``raysim paper`` (raysim.pipeline.paper)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, console, out, output_path
from raysim.errors import RaysimError


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
    refine_method: str = typer.Option(
        "defect", "--refine-method",
        help="defect (defect correction, the default), gauss-newton (then Gauss-Newton with the "
             "wave model's exact Jacobian; po or po+ptd models; two PO radiations per LSQR "
             "iteration) or auto (gauss-newton for a wave model where a PO radiation is at most "
             "1e9 element-point pairs, about 0.1 GHz on the paper's grid)."),
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
                            device=device, panels_csv=panels_csv, model=model, progress=report,
                            refine_method=refine_method,
                            log=lambda line: console.print(line, highlight=False))
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
    from raysim.pipeline.paper import compare

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
    from raysim.pipeline.paper import po_sweep
    from solver.invert import DEFAULT_SOLVER

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
