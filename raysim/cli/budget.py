"""``raysim budget``: a scan plan's predicted deformation RMS and scan time (raysim.pipeline.budget)."""

from __future__ import annotations

from pathlib import Path

import typer

from raysim.cli.common import app, say
from raysim.cli.tables import check_json_path, json_option, json_to_stdout, print_table, write_json


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
    remove: str = typer.Option("", help="Terms the inversion removes from the map (as invert "
                                        "--remove), e.g. tilt or piston,tilt,focus: the noise's "
                                        "share along them goes with them."),
    target_um: float | None = typer.Option(None, "--target-um",
                                           help="An RMS to reach (um): the readings per point "
                                                "and the scan time it needs."),
    json_path: str | None = json_option(),
) -> None:
    """Predict the deformation RMS a scan plan leaves, by mode, from the inversion's linear
    operator (no Monte Carlo), and the readings per point a target RMS needs."""
    from hardware.plan import load_plan
    from raysim.pipeline.budget import LINEAR_NOISE_DB, budget_rows, mode_lines, parse_levels, table_rows
    from solver.errors import SolverError

    if gain not in ("estimated", "known"):
        raise SolverError(f"unknown gain {gain!r}: choose estimated or known")
    if not 0 <= refine <= 50:
        raise SolverError(f"--refine must be an integer in 0..50, got {refine}")
    check_json_path(json_path, [("plan", plan)])
    scan_plan = load_plan(plan)
    check_json_path(json_path, scan_plan.inputs())  # the rig and mesh files the plan names too
    rows = budget_rows(scan_plan, parse_levels(noise_db), readings, rim, rim_std_um * 1e-6,
                       gain == "known", refine > 0,
                       None if target_um is None else target_um * 1e-6, remove)
    lines = table_rows(rows)
    title = f"error budget of {plan}"
    write_json(json_path, "budget", title, [_record(row) for row in rows], lines)
    if json_to_stdout(json_path):
        return
    print_table(title, lines)
    for line in mode_lines(rows):
        say(line)
    if rows and rows[0].blocked_cells:
        say(f"{rows[0].blocked_cells} cells inside the rim image are hidden by the plan's "
            "obstacles and counted as carrying no data")
    say("predicted from the inversion's linear operator (solver.budget); delta_c is the shape an "
        "unknown gain makes, removed when the gain is estimated")
    if any(row.budget.harmonic is None for row in rows):
        # a planner compared 5.62 um without targets against 6.23 um with 64 and took the first
        say("WARNING: without rim targets the RMS leaves out the harmonic part (tilt, astigmatism, "
            "any r^n cos n phi), which the scan cannot see at all: the map's error is unbounded "
            "there, so the RMS is not comparable with a plan that has targets; add --rim N")
    if rows and rows[0].budget.removed:
        say(f"removed after the solve (as invert --remove): {', '.join(rows[0].budget.removed)}; "
            "every part has lost its share along them")
    if any(row.budget.reference for row in rows):
        say("references: the drift references' own noise, carried into every line they correct "
            "(more reference_samples shrink it; more readings per point do not)")
        if scan_plan.drift_correction in ("auto", "smooth"):
            say(f"references: counted for a linear drift correction, an upper bound: drift_correction "
                f"= {scan_plan.drift_correction} corrects with line fits over several references, or "
                "not at all when the scan shows no drift (then this part is 0)")
    if any(row.noise_db > LINEAR_NOISE_DB for row in rows):
        say(f"WARNING: above {LINEAR_NOISE_DB:g} dB per reading the budget's linear noise model "
            "underestimates the scatter (by about 20 % at 3 dB and 70 times at 10 dB against a "
            "Monte Carlo): the map's error is no longer linear in the noise")


def _record(row) -> dict:
    """One noise level's numbers for ``--json``: lengths in m, times in hours."""
    b = row.budget
    return {"noise_db": row.noise_db, "readings": row.readings, "rms_m": b.total, "noise_m": b.noise,
            "delta_c_m": b.delta_c, "delta_c_removed": b.delta_c_removed,
            "removed_terms": list(b.removed),
            "references_m": b.reference if b.reference else None, "rim_targets_m": b.harmonic,
            "scan_hours": row.hours, "target_m": row.target, "readings_needed": row.readings_needed,
            "hours_needed": row.hours_needed, "blocked_cells": row.blocked_cells,
            "modes": [{"label": m.label, "m": m.m, "n": m.n, "rms_m": m.rms} for m in b.modes]}
