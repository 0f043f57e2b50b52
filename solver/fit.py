"""Best-fit removal of piston, tilt and focus, and per-panel adjustments from a surface map.

Frame (docs/physics.md): aperture plane x, y (m), delta along z (m). The terms, fitted by least
squares over the grid points inside the aperture:

- ``piston``: a constant (m);
- ``tilt``: x and y slopes (rad, small angles: dz/dx, dz/dy);
- ``focus``: r^2 (1/m), the change of a paraboloid refocused from F to F + dF:
  r^2 / (4 (F + dF)) - r^2 / (4F) ~ -dF r^2 / (4 F^2), so dF = -4 F^2 c.

Per panel (when the reflector has panels): piston at the panel's centroid and two tilts,
fitted over the grid points on that panel, written as a table a surface crew can act on (the
actuator correction is the negative of each value). The map is the smooth surface whose
Laplacian the intensity fixes, so the table tells each panel how to follow the measured
large-scale shape (gravity, heat). Errors of single panels are another matter: a panel's own
piston and tilt are harmonic inside the panel, so GO intensity sees them only through the
images of its edges, which the gaps darken; independent panel pistons are unobservable and
independent tilts only partly observable (about 0.7 correlation on scenes/panels_go.toml).
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from raysim.files import write_text
from solver.aperture import ApertureGrid
from solver.errors import SolverError

TERMS = ("piston", "tilt", "focus")


def parse_terms(spec: str | Iterable[str] | None) -> tuple[str, ...]:
    """Terms to remove from ``"piston,tilt,focus"``-style text or a sequence; '' or None is none."""
    if spec is None:
        return ()
    items = spec.split(",") if isinstance(spec, str) else list(spec)
    names = [s.strip().lower() for s in items if s and s.strip() and s.strip().lower() != "none"]
    for name in names:
        if name not in TERMS:
            raise SolverError(f"unknown term {name!r} to remove: choose from {', '.join(TERMS)}")
    return tuple(t for t in TERMS if t in names)


def _design(x, y, terms: Sequence[str]) -> tuple[NDArray[np.float64], list[str]]:
    cols, names = [], []
    if "piston" in terms:
        cols.append(np.ones_like(x))
        names.append("piston_m")
    if "tilt" in terms:
        cols += [x, y]
        names += ["tilt_x_rad", "tilt_y_rad"]
    if "focus" in terms:
        cols.append(x * x + y * y)
        names.append("focus_per_m")
    return np.stack(cols, axis=-1), names


def fit_terms(grid: ApertureGrid, delta: NDArray[np.float64],
              terms: Sequence[str]) -> tuple[NDArray[np.float64], dict[str, float]]:
    """Least-squares fit of ``terms`` to ``delta`` (m, (N, N)) over the aperture's finite points.

    Returns the fitted surface (N, N; NaN outside the aperture) and the coefficients by name.
    """
    fitted = np.zeros((grid.N, grid.N))
    if not terms:
        return grid.masked(fitted), {}
    use = grid.mask & np.isfinite(delta)
    X, Y = grid.XY
    design, names = _design(X[use], Y[use], terms)
    coef, *_ = np.linalg.lstsq(design, delta[use], rcond=None)
    full, _ = _design(X, Y, terms)
    fitted = full @ coef
    return grid.masked(fitted), dict(zip(names, (float(c) for c in coef), strict=True))


def remove_terms(grid: ApertureGrid, delta: NDArray[np.float64], terms: Sequence[str],
                 F: float | None = None) -> tuple[NDArray[np.float64], dict[str, float]]:
    """``delta`` minus its best-fit ``terms``; coefficients recorded (and dF in m if F given)."""
    fitted, coef = fit_terms(grid, delta, terms)
    if "focus_per_m" in coef and F is not None:
        coef["focus_shift_m"] = -4.0 * F * F * coef["focus_per_m"]
    return delta - fitted, coef


def panel_adjustments(grid: ApertureGrid, delta: NDArray[np.float64], layout) -> list[dict]:
    """Per-panel rigid fit (piston at the centroid, tilts) of ``delta`` (m) on the grid.

    ``layout`` is a :class:`raysim.surface.panels.PanelLayout` (``panel_at``, ``centres``, ``ring``,
    ``n_panels``). Panels with fewer than three grid points get NaN values.
    """
    X, Y = grid.XY
    ids = np.where(grid.mask & np.isfinite(delta), layout.panel_at(X, Y), -1)
    centres = layout.centres()
    rows = []
    for panel in range(layout.n_panels):
        on = ids == panel
        cx, cy = centres[panel]
        piston = tx = ty = np.nan
        if np.count_nonzero(on) >= 3:
            design = np.stack([np.ones(on.sum()), X[on] - cx, Y[on] - cy], axis=-1)
            (piston, tx, ty), *_ = np.linalg.lstsq(design, delta[on], rcond=None)
        rows.append({"panel_id": panel, "ring": int(layout.ring(panel)),
                     "centre_x_m": float(cx), "centre_y_m": float(cy),
                     "piston_um": float(piston) * 1e6, "tilt_x_urad": float(tx) * 1e6,
                     "tilt_y_urad": float(ty) * 1e6, "n_points": int(on.sum())})
    return rows


# The CSV leaves the panel pistons out: a panel's own piston is harmonic inside the panel and
# unobservable from the intensity (correlation 0.02 with the truth on scenes/panels_go.toml);
# the tilts are partly observable (about 0.7) through the images of the panel edges.
PANEL_COLUMNS = ("panel_id", "ring", "centre_x_m", "centre_y_m", "tilt_x_urad", "tilt_y_urad",
                 "n_points")


def write_panel_csv(rows: list[dict], path: str | os.PathLike[str]) -> Path:
    """Write the adjustment table (tilts urad = dz/dx, dz/dy; pistons left out, unobservable)."""
    text = io.StringIO(newline="")
    writer = csv.DictWriter(text, fieldnames=PANEL_COLUMNS, extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: f"{v:.3f}" if isinstance(v, float) else v for k, v in row.items()})
    return write_text(path, text.getvalue())
