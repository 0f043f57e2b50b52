"""Deformations: the paper's numbers, slopes against finite differences, normalisations."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from raysim.errors import SceneError
from raysim.surface.deformation import (
    GaussianBumps,
    PanelRigid,
    PaperDeformation,
    Zernike,
    paper_peak_to_peak,
)
from raysim.surface.gridded import GriddedMap
from raysim.surface.mapfile import read_map
from raysim.surface.panels import PanelLayout
from tests.surfaces import disk_rms

D, F = 110.0, 33.0
LAYOUT = PanelLayout((0.0, 20.0, 55.0), (6, 12), 0.01)


def aperture_grid(n: int = 256):
    """The paper's N x N cell-centred grid over the diameter, points inside the aperture."""
    g = -D / 2 + (np.arange(n) + 0.5) * D / n
    x, y = np.meshgrid(g, g)
    inside = np.hypot(x, y) < D / 2
    return x[inside], y[inside]


def test_paper_deformation_matches_the_papers_magnitudes():
    # docs/physics.md: peak-to-peak M = 1.2 mm, RMS 327.65 um over the aperture
    assert paper_peak_to_peak(D, F) == pytest.approx(1.2e-3, rel=0.02)
    x, y = aperture_grid()
    rms = np.sqrt(np.mean(PaperDeformation(D, F)(x, y) ** 2))
    assert rms == pytest.approx(327.65e-6, rel=1e-3)
    assert np.sqrt(np.mean(PaperDeformation(D, F, 1 / 3)(x, y) ** 2)) == pytest.approx(109.22e-6, rel=1e-3)


def test_paper_deformation_written_out_by_hand():
    x, y = np.array([0.0, 12.0, -30.0]), np.array([0.0, 5.0, 40.0])
    r = np.hypot(x, y)
    by_hand = np.sin(F / D * np.sqrt(x**2 + y**2 + F / 2)) / (50 * F) / (1 + np.exp(-0.6 * (0.4 * D - r)))
    assert np.allclose(PaperDeformation(D, F)(x, y), by_hand, rtol=1e-14, atol=0)


def central_difference(defo, x, y, panel=None, h=1e-5):
    gx = (defo(x + h, y, panel) - defo(x - h, y, panel)) / (2 * h)
    gy = (defo(x, y + h, panel) - defo(x, y - h, panel)) / (2 * h)
    return gx, gy


@pytest.mark.parametrize(
    "defo",
    [
        PaperDeformation(D, F, 0.7),
        Zernike(((2, 2, 200e-6), (3, -1, 40e-6), (4, 0, -30e-6), (5, 3, 10e-6)), 55.0),
        GaussianBumps(((10.0, -4.0, 30e-6, 2.5), (-20.0, 15.0, -12e-6, 6.0))),
    ],
    ids=["paper", "zernike", "bumps"],
)
def test_slopes_agree_with_finite_differences(defo):
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-50, 50, 2000), rng.uniform(-50, 50, 2000)
    gx, gy = defo.gradient(x, y)
    fx, fy = central_difference(defo, x, y)
    scale = max(np.abs(fx).max(), np.abs(fy).max())
    assert np.abs(gx - fx).max() < 1e-6 * scale
    assert np.abs(gy - fy).max() < 1e-6 * scale


def test_zernike_slopes_are_finite_at_the_centre():
    z = Zernike(((1, 1, 1e-4), (3, 1, 1e-4), (2, -2, 1e-4)), 55.0)
    gx, gy = z.gradient(np.array([0.0]), np.array([0.0]))
    fx, fy = central_difference(z, np.array([0.0]), np.array([0.0]), h=1e-4)
    assert np.allclose([gx[0], gy[0]], [fx[0], fy[0]], rtol=1e-6)


@pytest.mark.parametrize(("n", "m"), [(1, 1), (2, 0), (2, -2), (3, 1), (4, 4), (6, -2)])
def test_zernike_terms_are_noll_normalised_and_orthogonal(n, m):
    # RMS over the disk equals the coefficient (polar Gauss quadrature, independent of the code)
    rq, rw = np.polynomial.legendre.leggauss(40)
    r = 0.5 * (rq + 1)
    phi = np.linspace(0, 2 * np.pi, 128, endpoint=False)
    R, P = np.meshgrid(r, phi, indexing="ij")
    w = (0.5 * rw * r)[:, None] * (2 * np.pi / 128) / np.pi
    a = Zernike(((n, m, 1.0),), 1.0)(R * np.cos(P), R * np.sin(P))
    b = Zernike(((2, 2, 1.0),), 1.0)(R * np.cos(P), R * np.sin(P))
    assert np.sum(w * a * a) == pytest.approx(1.0, rel=1e-10)
    if (n, m) != (2, 2):
        assert abs(np.sum(w * a * b)) < 1e-10


def test_panel_rigid_is_a_plane_per_panel_and_zero_in_gaps():
    rng = np.random.default_rng(3)
    n = LAYOUT.n_panels
    defo = PanelRigid(LAYOUT, rng.normal(0, 1e-4, n), rng.normal(0, 1e-5, n), rng.normal(0, 1e-5, n))
    centres = LAYOUT.centres()
    x, y = rng.uniform(-55, 55, 5000), rng.uniform(-55, 55, 5000)
    ids = LAYOUT.panel_at(x, y)
    values = defo(x, y)
    on = ids >= 0
    k = ids[on]
    expected = defo.piston[k] + defo.tilt_x[k] * (x[on] - centres[k, 0]) + defo.tilt_y[k] * (y[on] - centres[k, 1])
    assert np.allclose(values[on], expected, rtol=0, atol=1e-18)
    assert np.all(values[~on] == 0.0)
    gx, gy = defo.gradient(x, y)
    assert np.allclose(gx[on], defo.tilt_x[k]) and np.all(gx[~on] == 0)
    assert np.allclose(gy[on], defo.tilt_y[k]) and np.all(gy[~on] == 0)


def test_random_panel_errors_hit_their_rms_and_repeat():
    a = PanelRigid.random(LAYOUT, 50e-6, seed=9)
    b = PanelRigid.random(LAYOUT, 50e-6, seed=9)
    c = PanelRigid.random(LAYOUT, 50e-6, seed=10)
    assert np.array_equal(a.piston, b.piston) and not np.array_equal(a.piston, c.piston)
    # the RMS over the panel footprints by an independent polar quadrature
    for errors in (a, c):
        assert disk_rms(errors, 55.0, LAYOUT, panels_only=True) == pytest.approx(50e-6, rel=2e-3)


def smooth_field(x, y, panel=None):
    return 1e-4 * np.sin(0.1 * x) * np.cos(0.07 * y) + 2e-6 * x


def test_gridded_map_interpolates_values_and_slopes():
    g = np.linspace(-60, 60, 241)
    X, Y = np.meshgrid(g, g)
    m = GriddedMap(g, g, smooth_field(X, Y))
    rng = np.random.default_rng(2)
    x, y = rng.uniform(-55, 55, 500), rng.uniform(-55, 55, 500)
    assert np.abs(m(x, y) - smooth_field(x, y)).max() < 1e-9
    gx, gy = m.gradient(x, y)
    fx, fy = central_difference(smooth_field, x, y)
    assert np.abs(gx - fx).max() < 1e-8 and np.abs(gy - fy).max() < 1e-8


def test_gridded_map_fills_nan_outside_the_aperture_smoothly():
    g = np.linspace(-60, 60, 121)
    X, Y = np.meshgrid(g, g)
    values = np.where(np.hypot(X, Y) < 55, 1e-4 + 0 * X, np.nan)
    m = GriddedMap(g, g, values)
    # a constant inside extends as that constant (the harmonic extension of a constant)
    assert np.allclose(m(np.array([0.0, 57.0, -59.0]), np.array([0.0, 0.0, 10.0])), 1e-4, atol=1e-12)


def test_gridded_map_files_round_trip(tmp_path: Path):
    g = np.linspace(-60, 60, 61)
    X, Y = np.meshgrid(g, g)
    dz = smooth_field(X, Y)
    nc = tmp_path / "map.nc"
    xr.Dataset({"deformation": (("y", "x"), dz, {"units": "m"})}, coords={"x": g, "y": g}).to_netcdf(nc)
    csv = tmp_path / "map.csv"
    order = np.random.default_rng(0).permutation(dz.size)  # rows in any order
    rows = np.column_stack([X.ravel(), Y.ravel(), dz.ravel()])[order]
    np.savetxt(csv, rows, delimiter=",", header="x,y,dz", comments="")
    pts = (np.array([3.3, -40.1]), np.array([17.0, 2.5]))
    assert np.allclose(read_map(nc)(*pts), read_map(csv)(*pts), rtol=0, atol=1e-15)
    bad = tmp_path / "bad.nc"
    xr.Dataset({"deformation": (("y", "x"), dz * 1e6, {"units": "um"})}, coords={"x": g, "y": g}).to_netcdf(bad)
    with pytest.raises(SceneError, match="must be in m, got 'um'"):
        read_map(bad)
    ragged = tmp_path / "ragged.csv"
    ragged.write_text("x,y,dz\n0,0,1\n1,0,1\n0,1,1\n")
    with pytest.raises(SceneError, match="do not fill a regular x-y grid"):
        read_map(ragged)


def test_deformations_add():
    a = GaussianBumps(((0.0, 0.0, 1e-5, 3.0),))
    b = Zernike(((2, 2, 2e-5),), 55.0)
    x, y = np.array([1.0, 20.0]), np.array([2.0, -3.0])
    assert np.allclose((a + b)(x, y), a(x, y) + b(x, y))
    assert np.allclose((a + b).gradient(x, y)[0], a.gradient(x, y)[0] + b.gradient(x, y)[0])
