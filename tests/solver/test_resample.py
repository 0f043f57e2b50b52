"""Sphere -> aperture resampling through the ideal mapping r = 2F tan(theta/2)."""

import numpy as np
import pytest

from raysim.errors import FieldMapError
from raysim.maps.sphere import SphereGrid
from solver.aperture import ApertureGrid
from solver.linear import Scan
from solver.resample import fill_missing, sphere_to_aperture, unmeasured_ring, usable_rows

F, D, R = 33.0, 110.0, 10.0


def smooth(x, y):
    """A smooth aperture field with no symmetry (so pole and seam errors would show)."""
    return np.sin(0.09 * x + 0.05 * y + 0.4) + 0.3 * np.cos(0.13 * y - 0.02 * x * y / 10)


def sampled(sphere):
    t, p = np.meshgrid(sphere.theta, sphere.phi, indexing="ij")
    r = 2 * F * np.tan(t / 2)
    return smooth(r * np.cos(p), r * np.sin(p))


def test_resampled_values_match_the_field_at_the_aperture_points():
    sphere = SphereGrid(R, 90, 360)
    grid = ApertureGrid(D, 128)
    got, coverage = sphere_to_aperture(sampled(sphere), sphere, grid, F, D)
    X, Y = grid.XY
    expected = smooth(X, Y)
    r_last = 2 * F * np.tan(coverage.theta_last / 2)
    inner = grid.mask & (grid.r <= r_last)
    assert np.max(np.abs(got - expected)[inner]) < 5e-5
    band = grid.mask & (grid.r > r_last)
    assert band.any() and np.max(np.abs(got - expected)[band]) < 2e-3
    assert np.all(np.isnan(got[~grid.mask]))
    assert coverage.n_rows == 79 and coverage.n_filled == 0


def test_holes_are_filled_and_counted():
    sphere = SphereGrid(R, 90, 360)
    grid = ApertureGrid(D, 128)
    values = sampled(sphere)
    clean, _ = sphere_to_aperture(values, sphere, grid, F, D)
    rng = np.random.default_rng(1)
    holes = rng.random(values.shape) < 0.03
    holes[0, :10] = True                     # next to the pole
    holes[40, 355:] = True                   # across the phi seam
    values[holes] = np.nan
    got, coverage = sphere_to_aperture(values, sphere, grid, F, D)
    assert coverage.n_filled == int(holes[: coverage.n_rows].sum())
    error = np.abs(got - clean)
    assert np.max(error[grid.mask & (grid.r < 50.0)]) < 1e-4
    assert np.nanmax(error) < 3e-2          # one-sided near the last usable row


def test_fill_missing_is_exact_for_discrete_harmonic_fields():
    kappa = np.arccosh(2 - np.cos(2 * np.pi / 12))        # cosh(k t) cos(2 pi p / 12) is
    t, p = np.meshgrid(np.arange(8.0), np.arange(12.0), indexing="ij")   # discrete-harmonic
    values = 0.3 * t + np.cosh(kappa * t) * np.cos(2 * np.pi * p / 12) + 2.0
    holes = np.zeros(values.shape, bool)
    holes[2, 3] = holes[3, 3] = holes[3, 4] = holes[4, 11] = holes[3, 0] = True
    truth = values.copy()
    values[holes] = np.nan
    filled, count = fill_missing(values, 8)
    assert count == 5
    np.testing.assert_allclose(filled, truth, atol=1e-9)


def test_partial_scans_are_refused():
    with pytest.raises(FieldMapError, match="full circle"):
        sphere = SphereGrid(R, 90, 180, phi_max=np.pi)
        sphere_to_aperture(np.ones((90, 180)), sphere, ApertureGrid(D, 32), F, D)
    with pytest.raises(FieldMapError, match="short of the rim"):
        usable_rows(SphereGrid(R, 60, 360, theta_max=np.radians(60.0)), F, D)


def test_coarse_rows_that_leave_the_outer_ring_unmeasured_say_so():
    """Coarse rows may stop up to three cells short of the rim image: on the paper's dish (rim
    image at 79.6 deg) 9 deg rows to 72 deg end their last centre at 67.5 deg, r = 44.1 m of
    55: 20 % of the radius was the spline's extrapolation, without a word. The ring (r from
    2 F tan(theta / 2)) is measured, and the SurfaceMap warns above 15 % of the radius; 5 deg
    rows to 75 deg (12 %) and 1 deg rows to 79 deg do not."""
    from raysim.maps.fieldmap import fieldmap
    from raysim.maps.sphere import ideal_go_intensity
    from solver.record import ring_attrs

    grid = SphereGrid(R, 8, 72, theta_max=np.radians(72.0))
    share, reached = unmeasured_ring(grid, F, D)
    assert reached == pytest.approx(2 * F * np.tan(np.radians(67.5) / 2), rel=1e-12)
    assert share == pytest.approx(1 - reached / 55.0, rel=1e-12)
    assert unmeasured_ring(SphereGrid(R, 15, 72, theta_max=np.radians(75.0)), F, D)[0] < 0.15
    assert unmeasured_ring(SphereGrid(R, 79, 360, theta_max=np.radians(79.0)), F, D)[0] < 0.03
    t, _ = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    ideal = ideal_go_intensity(t, F, R, D)
    coarse = fieldmap(grid, ideal, ideal, focal_length=F, diameter=D, frequency_hz=3e8,
                      method="go", sampling="cell_mean")
    attrs = ring_attrs(Scan.from_fieldmap(coarse))
    assert "r = 44.1 m of 55 m: the ring beyond (20 % of the radius) is extrapolated" in attrs["ring_warning"]



@pytest.mark.parametrize(("theta_min_deg", "cap_limit"),
                         [(4.0, 1e-3), (10.0, 2e-2), (4.5, 1e-3), (7.9, 1e-2), (2.7, 1e-3)])
def test_a_scan_that_starts_short_of_the_pole_has_its_cap_filled_and_counted(theta_min_deg, cap_limit):
    # rows of the scan's own step (about 1 deg) fill the cap as missing samples; 4.5, 7.9 and
    # 2.7 deg start part of a step from the pole (their step is not 1 deg either), so the
    # rows are first moved onto ones half a step from it. A cap held at its first row's
    # values erred by 0.2 to 0.6 in the cap; one left part of a step off the pole, by 0.026
    sphere = SphereGrid(R, 90 - int(theta_min_deg), 360, np.radians(theta_min_deg), np.pi / 2)
    grid = ApertureGrid(D, 128)
    got, coverage = sphere_to_aperture(sampled(sphere), sphere, grid, F, D)
    assert coverage.n_filled == int(theta_min_deg) * 360
    assert coverage.n_rows == usable_rows(sphere, F, D)
    error = np.abs(got - smooth(*grid.XY))
    r_cap = 2 * F * np.tan(np.radians(theta_min_deg) / 2)
    cap = grid.mask & (grid.r < r_cap)
    assert cap.sum() > 8 and np.max(error[cap]) < cap_limit
    assert np.max(error[grid.mask & (grid.r > r_cap + 1.0) & (grid.r < 45.0)]) < 1e-4
