"""The independent GO reference (tests/reference_go.py) against closed forms."""

import numpy as np

from raysim.maps.sphere import SphereGrid, ideal_go_cell_mean
from tests.reference_go import cell_mean_intensity, intensity_at, paper_delta, preimage, sphere_hit

F, D, R = 33.0, 110.0, 10.0


def test_ideal_point_intensity_is_rho_over_R_squared():
    theta = np.radians(np.linspace(0.01, 89.5, 60))[:, None]
    phi = np.linspace(0.0, 2 * np.pi, 37)[None, :]
    value = intensity_at(theta, phi, F, R)
    rho = 2 * F / (1 + np.cos(theta))
    np.testing.assert_allclose(value, np.broadcast_to((rho / R) ** 2, value.shape), rtol=2e-9)


def test_ideal_cell_means_match_the_closed_form_inside_the_rim():
    grid = SphereGrid(R)
    value = cell_mean_intensity(grid, F, D)
    exact = ideal_go_cell_mean(grid.theta_edges[:-1], grid.theta_edges[1:], F, R, D)
    inside = grid.theta_edges[1:] <= 2 * np.arctan(D / (4 * F))
    np.testing.assert_allclose(value[inside], np.broadcast_to(exact[inside, None],
                                                                value[inside].shape), rtol=2e-9)
    assert np.all(value[grid.theta > np.radians(80.0)] == 0.0)
    # the cell the rim image cuts holds exactly the power of its lit part
    cut = np.flatnonzero(~inside)[0]
    np.testing.assert_allclose(value[cut], exact[cut], rtol=2e-9)


def test_preimage_round_trip_lands_on_the_target_sphere_point():
    theta = np.radians(np.linspace(1.0, 78.0, 30))[:, None]
    phi = np.linspace(0.1, 6.2, 25)[None, :]
    x, y = preimage(theta, phi, F, R, paper_delta)
    S = sphere_hit(x, y, F, R, paper_delta) - np.array([0.0, 0.0, F])
    np.testing.assert_allclose(np.linalg.norm(S, axis=-1), R, rtol=1e-12)
    got_theta = np.arccos(-S[..., 2] / R)
    got_phi = np.mod(np.arctan2(S[..., 1], S[..., 0]), 2 * np.pi)
    np.testing.assert_allclose(got_theta, np.broadcast_to(theta, got_theta.shape), atol=1e-11)
    np.testing.assert_allclose(got_phi, np.broadcast_to(phi, got_phi.shape), atol=1e-10)
    # the deformation moves the preimage off the ideal mapping by about slope * distance
    r_ideal = 2 * F * np.tan(theta / 2)
    assert 1e-4 < np.max(np.abs(np.hypot(x, y) - r_ideal)) < 1e-1


def test_small_deformation_follows_the_linear_deformation_intensity_equation():
    """FA = G Laplacian(delta) (paper Eq. 28) to about 1 %, with the sign and scale right."""
    theta = np.radians(np.arange(0.5, 79.0, 1.0))[:, None]
    phi = np.radians(np.arange(0.5, 360.0, 7.0))[None, :]
    theta, phi = np.broadcast_arrays(theta, phi)

    def delta(x, y):
        return paper_delta(x, y, scale=0.01)

    fa = intensity_at(theta, phi, F, R, None, D) / intensity_at(theta, phi, F, R, delta, D) - 1
    r = 2 * F * np.tan(theta / 2)
    x, y = r * np.cos(phi), r * np.sin(phi)
    e = 1e-2
    lap = (delta(x + e, y) + delta(x - e, y) + delta(x, y + e) + delta(x, y - e)
           - 4 * delta(x, y)) / e**2
    G = -2 * F * (F + r**2 / (4 * F) - R) / R
    linear = G * lap
    mismatch = np.sqrt(np.mean((fa - linear) ** 2) / np.mean(linear**2))
    assert mismatch < 0.03
