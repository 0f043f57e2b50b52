"""Piston, tilt and focus removal, and the per-panel adjustment table."""

import csv

import numpy as np
import pytest

from raysim.surface.deformation import PanelRigid
from raysim.surface.panels import PanelLayout
from solver.aperture import ApertureGrid
from solver.errors import SolverError
from solver.fit import panel_adjustments, parse_terms, remove_terms, write_panel_csv

F, D = 33.0, 110.0


def test_parse_terms():
    assert parse_terms("focus, piston") == ("piston", "focus")
    assert parse_terms("") == () and parse_terms(None) == () and parse_terms("none") == ()
    assert parse_terms(["tilt"]) == ("tilt",)
    with pytest.raises(SolverError, match="coma"):
        parse_terms("piston,coma")


def test_removed_coefficients_are_the_ones_put_in():
    grid = ApertureGrid(D, 96)
    X, Y = grid.XY
    rest = 1e-5 * (X**2 - Y**2) / 55**2     # orthogonal to the terms on the symmetric grid
    dF = 2e-3
    refocus = (X**2 + Y**2) / (4 * (F + dF)) - (X**2 + Y**2) / (4 * F)
    delta = grid.masked(4e-5 + 2e-6 * X - 3e-6 * Y + refocus + rest)
    cleaned, coef = remove_terms(grid, delta, ("piston", "tilt", "focus"), F)
    np.testing.assert_allclose(cleaned[grid.mask], rest[grid.mask], atol=1e-10)
    assert np.isclose(coef["piston_m"], 4e-5, atol=1e-10)
    assert np.isclose(coef["tilt_x_rad"], 2e-6) and np.isclose(coef["tilt_y_rad"], -3e-6)
    assert np.isclose(coef["focus_shift_m"], dF, rtol=2 * dF / F)
    assert np.all(np.isnan(cleaned[~grid.mask]))


def test_panel_table_recovers_rigid_panel_errors(tmp_path):
    layout = PanelLayout((0.0, 20.0, 40.0, 55.0), (4, 8, 12), gap=0.05)
    rigid = PanelRigid.random(layout, rms=50e-6, seed=4)
    grid = ApertureGrid(D, 256)
    X, Y = grid.XY
    delta = grid.masked(rigid(X, Y))
    rows = panel_adjustments(grid, delta, layout)
    assert len(rows) == layout.n_panels
    for row in rows:
        p = row["panel_id"]
        assert abs(row["piston_um"] - rigid.piston[p] * 1e6) < 1e-6
        assert abs(row["tilt_x_urad"] - rigid.tilt_x[p] * 1e6) < 1e-6
        assert abs(row["tilt_y_urad"] - rigid.tilt_y[p] * 1e6) < 1e-6
        assert row["ring"] == int(layout.ring(p)) and row["n_points"] > 50
    path = write_panel_csv(rows, tmp_path / "panels.csv")
    with open(path) as fh:
        table = list(csv.DictReader(fh))
    assert list(table[0]) == ["panel_id", "ring", "centre_x_m", "centre_y_m", "tilt_x_urad",
                              "tilt_y_urad", "n_points"]         # pistons unobservable: left out
    assert len(table) == layout.n_panels
