"""``raysim budget``: a scan plan's predicted deformation RMS and scan time (raysim.pipeline.budget)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, out, say


@app.command("budget")
def budget_command(
    plan: Path = typer.Argument(..., help="Scan plan TOML (or a shipped plan's name)."),
    noise_db: str = typer.Option("0.001,0.01,0.05", "--noise-db",
                                 help="Noise of one reading (dB rms), one or more, comma-separated."),
    readings: int | None = typer.Option(None, help="Readings averaged per point (default: the "
                                                   "plan's samples_per_point)."),
    rim: int = typer.Option(0, help="Rim targets spread round the rim (0: none, the harmonic part "
                                    "is then unbounded)."),
    rim_std_um: float = typer.Option(10.0, "--rim-std-um", help="Error of one rim target (um)."),
    gain: str = typer.Option("estimated", help="estimated (a measured scan: delta_c removed) or "
                                               "known."),
    refine: int = typer.Option(3, help="The inversion's refinement iterations (0: the linear "
                                       "answer, whose delta_c differs)."),
    target_um: float | None = typer.Option(None, "--target-um",
                                           help="An RMS to reach (um): the readings per point "
                                                "and the scan time it needs."),
) -> None:
    """Predict the deformation RMS a scan plan leaves, by mode, from the inversion's linear
    operator (no Monte Carlo), and the readings per point a target RMS needs."""
    from raysim.pipeline.budget import budget_rows, mode_lines, parse_levels, table_rows
    from solver.errors import SolverError

    if gain not in ("estimated", "known"):
        raise SolverError(f"unknown gain {gain!r}: choose estimated or known")
    if not 0 <= refine <= 50:
        raise SolverError(f"--refine must be an integer in 0..50, got {refine}")
    rows = budget_rows(plan, parse_levels(noise_db), readings, rim, rim_std_um * 1e-6,
                       gain == "known", refine > 0,
                       None if target_um is None else target_um * 1e-6)
    from rich.table import Table

    lines = table_rows(rows)
    table = Table(*lines[0], title=f"error budget of {plan}")
    for line in lines[1:]:
        table.add_row(*line)
    out.print(table)
    for line in mode_lines(rows):
        say(line)
    if rows and rows[0].blocked_cells:
        say(f"{rows[0].blocked_cells} cells inside the rim image are hidden by the plan's "
            "obstacles and counted as carrying no data")
    say("predicted from the inversion's linear operator (solver.budget); delta_c is the shape an "
        "unknown gain makes, removed when the gain is estimated")
    if any(row.budget.reference for row in rows):
        say("references: the drift references' own noise, carried into every line they correct "
            "(more reference_samples shrink it; more readings per point do not)")
