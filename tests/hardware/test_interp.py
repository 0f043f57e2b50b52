"""FieldSampler: stored values at the centres, bilinear between, periodic, through the pole."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hardware.interp import FieldSampler, SphereField
from raysim.maps.fieldmap import fieldmap
from raysim.maps.sphere import SphereGrid, ideal_go_intensity, theta_rim

GRID = SphereGrid(10.0, 18, 36)          # 5 deg x 10 deg cells over the hemisphere


def test_cell_centres_return_stored_values() -> None:
    rng = np.random.default_rng(1)
    values = rng.uniform(0.5, 2.0, (18, 36))
    sampler = FieldSampler(values, GRID)
    t, p = np.meshgrid(GRID.theta, GRID.phi, indexing="ij")
    assert np.array_equal(sampler(t, p), values)


def test_bilinear_function_is_reproduced_inside_cells() -> None:
    """a + b theta + c phi + d theta phi is bilinear: exact between the centres."""
    t, p = np.meshgrid(GRID.theta, GRID.phi, indexing="ij")

    def f(theta, phi):
        return 1.0 + 0.3 * theta - 0.05 * phi + 0.02 * theta * phi

    sampler = FieldSampler(f(t, p), GRID)
    rng = np.random.default_rng(2)
    theta = rng.uniform(GRID.theta[0], GRID.theta[-1], 500)
    phi = rng.uniform(GRID.phi[0], GRID.phi[-1], 500)
    assert np.allclose(sampler(theta, phi), f(theta, phi), rtol=0, atol=1e-13)


def test_known_value_between_four_centres() -> None:
    values = np.zeros((18, 36))
    values[3, 4], values[3, 5], values[4, 4], values[4, 5] = 1.0, 2.0, 3.0, 4.0
    sampler = FieldSampler(values, GRID)
    # a quarter of the way from centre (3, 4) towards (4, 5) in both directions
    theta = math.radians(17.5 + 1.25)
    phi = math.radians(45.0 + 2.5)
    expected = 0.75 * (0.75 * 1.0 + 0.25 * 2.0) + 0.25 * (0.75 * 3.0 + 0.25 * 4.0)
    assert float(sampler(theta, phi)) == pytest.approx(expected, abs=1e-14)


def test_periodic_in_phi() -> None:
    values = np.zeros((18, 36))
    values[:, 0], values[:, 35] = 1.0, 3.0           # centres at 5 deg and 355 deg
    sampler = FieldSampler(values, GRID)
    theta = GRID.theta[7]
    # 0 deg lies halfway between the centres at 355 deg and 5 deg
    assert float(sampler(theta, 0.0)) == pytest.approx(2.0, abs=1e-14)
    assert float(sampler(theta, 2 * math.pi)) == pytest.approx(2.0, abs=1e-14)
    assert float(sampler(theta, math.radians(-2.5))) == pytest.approx(2.5, abs=1e-14)
    assert float(sampler(theta, math.radians(722.5))) == pytest.approx(1.5, abs=1e-14)


def test_through_the_pole() -> None:
    """Below the first row the row mirrored through theta = 0 (seen from phi + 180) holds."""
    values = np.ones((18, 36))
    values[0, 3] = 5.0      # theta 2.5 deg, phi 35 deg
    values[0, 21] = 9.0     # theta 2.5 deg, phi 215 deg
    sampler = FieldSampler(values, GRID)
    phi = math.radians(35.0)
    # at the pole: halfway between the two rows -> mean of the values 180 deg apart
    assert float(sampler(0.0, phi)) == pytest.approx(0.5 * (5.0 + 9.0), abs=1e-14)
    assert float(sampler(math.radians(1.25), phi)) == pytest.approx(0.25 * 9 + 0.75 * 5,
                                                                     abs=1e-14)


def test_edges_hold_outside_a_partial_grid() -> None:
    grid = SphereGrid(10.0, 4, 3, theta_min=math.radians(10), theta_max=math.radians(50),
                      phi_min=0.0, phi_max=math.radians(90))
    values = np.arange(12.0).reshape(4, 3)
    sampler = FieldSampler(values, grid)
    assert float(sampler(math.radians(5), math.radians(15))) == 0.0
    assert float(sampler(math.radians(80), math.radians(75))) == 11.0
    assert float(sampler(math.radians(15), math.radians(100))) == 2.0


def test_missing_sample_spreads_only_to_neighbours() -> None:
    values = np.ones((18, 36))
    values[9, 9] = np.nan
    sampler = FieldSampler(values, GRID)
    assert math.isnan(float(sampler(GRID.theta[9] + 0.01, GRID.phi[9] + 0.01)))
    assert float(sampler(GRID.theta[9], GRID.phi[10])) == 1.0
    assert float(sampler(GRID.theta[11], GRID.phi[9] + 0.05)) == 1.0


def test_sphere_field_is_ratio_times_exact_ideal() -> None:
    """A map 2 % above the ideal reads 1.02 (rho/R)^2 anywhere inside the rim image, 0
    beyond it, and (R / r)^2 times that off the sphere; GO cell means (whose ideal is the
    cell mean too) give the same point values."""
    F, D = 33.0, 110.0
    grid = SphereGrid(10.0, 90, 360)
    lo, hi = grid.theta_edges[:-1], grid.theta_edges[1:]
    from raysim.maps.sphere import ideal_go_cell_mean
    ideal = np.repeat(ideal_go_cell_mean(lo, hi, F, 10.0, D)[:, None], 360, axis=1)
    ds = fieldmap(grid, 1.02 * ideal, ideal, focal_length=F, diameter=D, frequency_hz=3e8,
                  method="go", sampling="cell_mean")
    field = SphereField.from_fieldmap(ds)
    rim = theta_rim(D, F)
    for theta in (0.0, 0.3, 1.0, rim - 1e-3):
        point = 1.02 * (2 * F / (1 + math.cos(theta)) / 10.0) ** 2
        assert field(theta, 0.7, 10.0) == pytest.approx(point, rel=1e-12)
        assert field(theta, 0.7, 10.004) == pytest.approx(point * (10.0 / 10.004) ** 2,
                                                          rel=1e-12)
    assert field(rim + 1e-3, 0.7, 10.0) == 0.0
    assert float(ideal_go_intensity(rim + 1e-3, F, 10.0, D)) == 0.0
