"""``raysim campaign``: a simulated measurement campaign end to end (raysim.pipeline.campaign)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, progress_bar, say


@app.command("campaign")
def campaign_command(
    scene: Path = typer.Argument(..., help="Scene TOML: the telescope as it is (or a shipped name)."),
    plan: Path = typer.Argument(..., help="Scan plan TOML with a \\[simulator] table (noise, gain)."),
    output: Path = typer.Option(..., "-o", "--output", help="Folder for the campaign's files."),
    rim: int = typer.Option(64, help="Rim targets spread round the rim (0: none)."),
    rim_std_um: float = typer.Option(10.0, "--rim-std-um", help="Error of one rim target (um)."),
    target_um: float | None = typer.Option(None, "--target-um",
                                           help="RMS to plan for (um): the budget picks the "
                                                "readings per point."),
    readings: int | None = typer.Option(None, help="Readings per point (default: the plan's, or "
                                                   "the budget's for --target-um)."),
    grid: int = typer.Option(256, help="Aperture grid points across the diameter, 16 to 4096."),
    refine: int = typer.Option(3, help="GO refinement iterations of the inversion, 0 to 50."),
    seed: int = typer.Option(0, help="Seed of the rim targets' errors."),
) -> None:
    """Simulate a campaign: budget, GO field, scan through the simulated rig, rim targets,
    inversion of the measured scan, and the budget's prediction beside the RMS reached."""
    from raysim.pipeline.campaign import run_campaign
    from solver.options import check_options

    check_options(N=grid, refine=refine)
    with progress_bar() as bar:
        task = bar.add_task("campaign", total=1.0)

        def report(stage: str, fraction: float) -> None:
            bar.update(task, completed=fraction, description=f"campaign: {stage}")

        result = run_campaign(scene, plan, output, rim=rim, rim_std=rim_std_um * 1e-6,
                              target=None if target_um is None else target_um * 1e-6,
                              readings=readings, N=grid, refine=refine, seed=seed,
                              progress=report)
    for line in result.lines:
        say(line)
    say(f"wrote {result.folder}")
