"""A campaign's error budget: a scan plan, noise levels, rim targets -> predicted RMS and scan time.

Units: lengths in m (the table's figures in um), noise in dB per reading, times in s. The
prediction is :func:`solver.budget.noise_budget` (the linear operator, no Monte Carlo) on the
plan's sphere grid and dish, with the drift references' noise when the plan corrects for drift
(``drift_correction`` other than ``none``; ``smooth`` counted as ``linear``, an upper bound);
the scan time is :meth:`hardware.plan.ScanPlan.duration` at the readings per point asked for.
A plan with obstacles passes the cells they leave (:attr:`hardware.plan.ScanPlan.blocked_share`
at the FieldMap's threshold): blocked cells carry no data. ``raysim budget`` prints
:func:`budget_rows`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from hardware.plan import ScanPlan, load_plan
from raysim.optics.blockage import BLOCKED_SHARE
from solver.budget import Budget, noise_response
from solver.errors import SolverError
from solver.fit import parse_terms

MAX_READINGS = 100_000
#: dB per reading above which the linear noise model (sigma = ln 10 / 10 s) is off by more than
#: a few per cent (the log-normal reading's own spread: 4 % at 1 dB, 40 % at 3 dB)
LINEAR_NOISE_DB = 1.0


@dataclass(frozen=True)
class BudgetRow:
    """The budget of one noise level: at the plan's readings, and what a target RMS needs."""

    noise_db: float
    readings: int
    budget: Budget
    hours: float
    target: float | None            # m
    readings_needed: int | None     # None: the target is out of reach (rim targets' part)
    hours_needed: float | None
    blocked_cells: int = 0          # usable cells the plan's obstacles hide (no data)


def parse_levels(text: str) -> list[float]:
    """Noise levels (dB per reading) from ``"0.001,0.01,0.05"``, each in (0, 10]."""
    try:
        levels = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise SolverError(f"--noise-db must be numbers separated by commas, got {text!r}") from None
    check_levels(levels, repr(text))
    return levels


def check_levels(levels: Sequence[float], shown: str) -> None:
    """Refuse noise levels (dB per reading) that are not numbers in (0, 10]."""
    if (isinstance(levels, str | bytes) or len(levels) == 0
            or any(isinstance(v, bool) or not isinstance(v, numbers.Real)
                   or not (math.isfinite(v) and 0.0 < v <= 10.0) for v in levels)):
        raise SolverError(f"--noise-db values must lie in (0, 10] dB, got {shown}")


def budget_rows(plan: ScanPlan | str | Path, levels: list[float], readings: int | None = None,
                rim: int = 0, rim_std: float = 10e-6, gain_known: bool = False,
                refine: bool = True, target: float | None = None,
                remove: str | Sequence[str] = ()) -> list[BudgetRow]:
    """One :class:`BudgetRow` per noise level of ``plan`` (a ScanPlan or its file).

    ``readings``: readings per point (None: the plan's ``samples_per_point``); ``rim``: rim
    targets (0: none) of std ``rim_std`` (m); ``refine``: the map is model-refined (its
    delta_c is the refocus), else linear; ``target`` (m): the RMS to reach; ``remove``: the
    terms the inversion removes from the map (``invert --remove``: piston, tilt, focus).
    """
    check_levels(levels, repr(levels))  # -0.01 dB gave the budget of +0.01, nan a nan total
    terms = parse_terms(remove)
    plan = plan if isinstance(plan, ScanPlan) else load_plan(plan)
    k = plan.samples_per_point if readings is None else readings
    if isinstance(k, bool) or not isinstance(k, numbers.Integral) or not 1 <= k <= MAX_READINGS:
        raise SolverError(f"--readings must be an integer in 1..{MAX_READINGS}, got {k!r}")
    if isinstance(rim, bool) or not isinstance(rim, numbers.Integral) or (rim and not 8 <= rim):
        raise SolverError(f"--rim needs at least 8 targets (or 0 for none), got {rim!r}")
    if not 0.0 <= rim_std <= 1e-2:
        raise SolverError(f"--rim-std-um must lie in 0..10000 um, got {rim_std * 1e6:g}")
    if target is not None and not 0.0 < target <= 1e-2:
        raise SolverError(f"--target-um must lie in (0, 10000] um, got {target * 1e6:g}")
    corrected = plan.drift_correction != "none"
    response = noise_response(plan.grid, plan.focal_length, plan.diameter,
                              "refocus" if refine else "linear",
                              plan.reference_every if corrected else None, used_cells(plan),
                              terms)
    options = dict(gain_known=gain_known, rim_targets=rim, target_std=rim_std,
                   reference_samples=plan.reference_samples if corrected else 0)
    rows = []
    for level in levels:
        budget = response.budget(level, k, **options)
        needed = None if target is None else response.readings_for(target, level, **options)
        rows.append(BudgetRow(level, k, budget, plan.duration(k) / 3600.0, target, needed,
                              None if needed is None or needed > MAX_READINGS
                              else plan.duration(needed) / 3600.0, response.unused_cells))
    return rows


def used_cells(plan: ScanPlan) -> NDArray[np.bool_] | None:
    """(n_theta, n_phi): the plan's cells that carry data, those its obstacles do not hide
    (the measured FieldMap's ``blocked`` rule); None without obstacles."""
    share = plan.blocked_share
    return None if share is None else ~(share > BLOCKED_SHARE)


def table_rows(rows: list[BudgetRow]) -> list[list[str]]:
    """The printed table: a header and one row per noise level (figures in um, hours)."""
    head = ["noise (dB)", "readings", "RMS (um)", "noise part", "delta_c", "references",
            "rim targets", "scan (h)"]
    if rows and rows[0].target is not None:
        head += [f"readings for {rows[0].target * 1e6:g} um", "scan (h)"]
    out = [head]
    for row in rows:
        b = row.budget
        line = [f"{row.noise_db:g}", str(row.readings), f"{b.total * 1e6:.2f}",
                f"{b.noise * 1e6:.2f}",
                f"{b.delta_c * 1e6:.2f} " + ("removed" if b.delta_c_removed else "kept"),
                f"{b.reference * 1e6:.2f}" if b.reference else "none",
                "unbounded (none)" if b.harmonic is None else f"{b.harmonic * 1e6:.2f}",
                f"{row.hours:.2f}"]
        if row.target is not None:
            line += ["out of reach" if row.readings_needed is None
                     else f"more than {MAX_READINGS}" if row.readings_needed > MAX_READINGS
                     else str(row.readings_needed),
                     "-" if row.hours_needed is None else f"{row.hours_needed:.1f}"]
        out.append(line)
    return out


def mode_lines(rows: list[BudgetRow]) -> list[str]:
    """The largest Dirichlet-mode shares of the readings' and the references' noise at each
    level (um), after delta_c's removal when the gain is estimated and the removed terms'."""
    return [f"{row.noise_db:g} dB: largest modes " + ", ".join(
        f"{m.label} {m.rms * 1e6:.2f}" for m in row.budget.modes) for row in rows]
