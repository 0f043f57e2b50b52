"""Deformations: the paper's numbers, slopes against finite differences, normalisations."""

from __future__ import annotations

import math
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from raysim.errors import SceneError
from raysim.surface.deformation import (
    MAX_ZERNIKE_ORDER,
    GaussianBumps,
    PanelRigid,
    PaperDeformation,
    Zernike,
    paper_peak_to_peak,
    zernike_radial,
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


def exact_radial(n: int, m: int, rho: Fraction) -> tuple[Fraction, Fraction, Fraction]:
    """R_n^m(rho), dR/drho and R/rho (m >= 1; else 0) by the explicit factorial sum, in exact
    rational arithmetic (no cancellation, whatever the order)."""
    value, slope, over = Fraction(0), Fraction(0), Fraction(0)
    for s in range((n - m) // 2 + 1):
        c = Fraction((-1) ** s * math.factorial(n - s),
                     math.factorial(s) * math.factorial((n + m) // 2 - s)
                     * math.factorial((n - m) // 2 - s))
        p = n - 2 * s
        value += c * rho**p
        if p:
            slope += c * p * rho ** (p - 1)
            over += c * rho ** (p - 1) if m else 0
    return value, slope, over


def test_zernike_radial_matches_exact_rational_sums_at_low_order():
    rhos = [Fraction(k, 16) for k in range(17)] + [Fraction(9, 7)]  # the disk and beyond its rim
    x = np.array([float(r) for r in rhos])
    for n in range(13):
        for m in range(n % 2, n + 1, 2):
            R, dR, R_over = zernike_radial(n, m, x, gradient=True)
            exact = [exact_radial(n, m, r) for r in rhos]
            want, want_slope, want_over = (np.array([float(e[i]) for e in exact]) for i in range(3))
            assert np.allclose(R, want, rtol=1e-12, atol=1e-12), (n, m)
            assert np.allclose(dR, want_slope, rtol=1e-12, atol=1e-12), (n, m)
            # R / rho, finite at the centre for m >= 1 (and 0 for m = 0, where nothing uses it)
            assert np.allclose(R_over, want_over, rtol=1e-12, atol=1e-12), (n, m)


@pytest.mark.parametrize(("n", "m"), [(44, 0), (60, 0), (61, 3), (80, 20), (100, 0), (100, 98)])
def test_zernike_radial_stays_accurate_at_high_order(n, m):
    # the explicit sum in floating point loses every digit here; exact fractions do not
    rhos = [Fraction(k, 40) for k in range(41)]
    R, dR, _ = zernike_radial(n, m, np.array([float(r) for r in rhos]), gradient=True)
    exact = [exact_radial(n, m, r) for r in rhos]
    assert np.allclose(R, [float(e[0]) for e in exact], rtol=0, atol=1e-11)
    assert np.allclose(dR, [float(e[1]) for e in exact], rtol=0, atol=1e-11 * n * n)


def test_zernike_radial_is_one_on_the_rim_and_bounded_inside():
    rho = np.linspace(0.0, 1.0, 2001)
    for n in range(MAX_ZERNIKE_ORDER + 1):
        for m in range(n % 2, n + 1, 2):
            R = zernike_radial(n, m, rho)[0]
            assert R[-1] == pytest.approx(1.0, abs=1e-12), (n, m)
            assert np.abs(R).max() <= 1.0 + 1e-12, (n, m)  # |R_n^m| <= 1 on the unit disk


@pytest.mark.parametrize("m", [0, 1, 7, 20])
def test_zernike_radial_polynomials_are_orthogonal_at_high_order(m):
    # int_0^1 R_n^m R_k^m rho drho = delta_nk / (2 (n + 1)), Gauss-Legendre exact to degree 319
    t, w = np.polynomial.legendre.leggauss(160)
    rho, w = 0.5 * (t + 1.0), 0.5 * w
    orders = [n for n in range(m, MAX_ZERNIKE_ORDER + 1, 2) if n >= 60]
    table = np.array([zernike_radial(n, m, rho)[0] for n in orders])
    gram = (table * (w * rho)) @ table.T
    want = np.diag([1.0 / (2 * (n + 1)) for n in orders])
    assert np.abs(gram - want).max() < 1e-13


def test_high_order_zernike_term_keeps_its_size_and_slopes():
    # the QA case: 1 um of Z(60, 0) peaks at sqrt(61) um (Noll norm, |R| <= 1), not metres
    z = Zernike(((60, 0, 1e-6),), 55.0)
    x, y = aperture_grid()
    assert np.abs(z(x, y)).max() <= math.sqrt(61) * 1e-6 * (1 + 1e-12)
    assert z(np.array([55.0]), np.array([0.0]))[0] == pytest.approx(math.sqrt(61) * 1e-6, rel=1e-12)
    # slopes of high-order terms against central differences, inside the disk
    z = Zernike(((60, 4, 1e-6), (61, -3, 2e-6), (100, 0, 1e-7)), 55.0)
    rng = np.random.default_rng(4)
    r, phi = 55.0 * np.sqrt(rng.uniform(0, 0.99, 500)), rng.uniform(0, 2 * np.pi, 500)
    x, y = r * np.cos(phi), r * np.sin(phi)
    gx, gy = z.gradient(x, y)
    fx, fy = central_difference(z, x, y, h=1e-4)
    scale = max(np.abs(fx).max(), np.abs(fy).max())
    assert np.abs(gx - fx).max() < 1e-6 * scale and np.abs(gy - fy).max() < 1e-6 * scale


def test_zernike_order_beyond_the_bound_is_refused():
    Zernike(((MAX_ZERNIKE_ORDER, 0, 1e-6),), 55.0)
    with pytest.raises(SceneError, match=rf"radial order n is over {MAX_ZERNIKE_ORDER}") as info:
        Zernike(((MAX_ZERNIKE_ORDER + 2, 0, 1e-6),), 55.0)
    assert "\n" not in str(info.value)


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
