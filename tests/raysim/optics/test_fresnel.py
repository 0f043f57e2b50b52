"""The geometric wave's Fresnel-zone correction (raysim.optics.fresnel).

References: PO + PTD (raysim.optics.po, raysim.optics.ptd) on a finer quadrature than the
engines' defaults, a separately written method; the geometric wave's own first-order answer
(a ray trace of the ideal surface plus a scaled-down deformation) where the deformation is
smooth on the Fresnel scale, so the window sums must give what the rays give.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid
from raysim.optics import fresnel, goedge, po, ptd
from raysim.surface.deformation import GaussianBumps
from raysim.surface.mesh import paraboloid

# a 10 m dish with the paper's F / D and R / F
D, F, R = 10.0, 3.0, 1.0
GRID = SphereGrid(R, 30, 24)


def intensity(E):
    return np.sum(np.abs(E) ** 2, axis=-1)


def fa_error(fa, fa_ref):
    """RMS of fa - fa_ref over FA's RMS, theta up to the rim's image minus 2 deg."""
    theta = np.degrees(GRID.theta)
    use = theta <= np.degrees(2.0 * np.arctan(D / (4.0 * F))) - 2.0
    return float(np.sqrt(np.mean((fa - fa_ref)[use] ** 2) / np.mean(fa_ref[use] ** 2)))


@pytest.mark.slow
def test_bumps_finer_than_the_fresnel_zone_follow_po_with_the_correction():
    # 7.5 GHz: u_F = 0.49 m at the vertex; bumps of sigma 0.3 m, which GO answers to with
    # the wrong sign and size
    wave = po.Illumination.plane_wave(7.5e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    dish = paraboloid(D, F, 0.5)
    bumps = GaussianBumps(((1.0, 0.5, 2e-4, 0.3), (-2.5, 1.0, -1.5e-4, 0.3),
                           (0.5, -3.0, 1e-4, 0.3)))
    deformed = dish.deformed(bumps)
    ref = [intensity(po.sphere_field(r, GRID, wave, 2.0).E
                     + ptd.sphere_edge_field(r, GRID, wave, "rim", 6.0).E) for r in (dish, deformed)]
    fa_ref = ref[0] / ref[1] - 1.0
    ideal, bent = goedge.sphere_field(dish, GRID, wave), goedge.sphere_field(deformed, GRID, wave)
    fix = fresnel.correction(dish, deformed, GRID, wave, ideal.E_geo, bent.subdivisions)
    I0 = intensity(ideal.E)
    plain = fa_error(I0 / intensity(bent.E) - 1.0, fa_ref)
    corrected = fa_error(I0 / intensity(bent.E + fix.dE) - 1.0, fa_ref)
    assert plain > 0.15                  # the geometric wave alone misses the smoothing
    assert corrected < 0.05 and corrected < 0.2 * plain   # measured: 24 % -> 2.6 %


def test_the_window_gives_the_rays_answer_for_a_deformation_smooth_on_the_fresnel_scale():
    # 30 GHz: u_F = 0.24 m at the vertex, a bump of sigma 2.5 m: geometrical optics holds, and
    # the window sums (specular points, path derivative q, stationary-phase weight) must give
    # the ray trace's first-order answer, phase and amplitude
    wave = po.Illumination.plane_wave(30e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    grid = SphereGrid(R, 12, 8, theta_max=np.radians(60.0))
    dish = paraboloid(D, F, 0.5)
    bump = GaussianBumps(((0.8, -0.4, 5e-6, 2.5),))
    deformed = dish.deformed(bump)
    ideal = goedge.sphere_field(dish, grid, wave)
    rho_go = fresnel.linear_response(dish, bump, grid, wave, ideal.E_geo, ideal.subdivisions)
    rho_wave, _ = fresnel.window_response(deformed, grid.points(F).reshape(-1, 3), grid.radius, wave)
    rho_wave = rho_wave.reshape(rho_go.shape)
    scale = np.sqrt(np.mean(np.abs(rho_go) ** 2))
    assert np.sqrt(np.mean(np.abs(rho_wave - rho_go) ** 2)) < 0.01 * scale
    # the amplitude part (the curvature term), far smaller than the phase, agrees too
    amp_scale = np.sqrt(np.mean(rho_go.real ** 2))
    assert np.sqrt(np.mean((rho_wave.real - rho_go.real) ** 2)) < 0.1 * amp_scale


def test_the_correction_says_where_it_does_not_apply():
    dish = paraboloid(D, F, 1.0)
    on_axis = po.Illumination.plane_wave(3e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    tilt = 0.01
    oblique = po.Illumination.plane_wave(3e9, (np.sin(tilt), 0.0, -np.cos(tilt)),
                                         (np.cos(tilt), 0.0, np.sin(tilt)))
    bumps = GaussianBumps(((1.0, 0.5, 2e-4, 0.3),))
    assert "not deformed" in fresnel.applies(dish, on_axis)
    assert "not on the axis" in fresnel.applies(dish.deformed(bumps), oblique)
    assert fresnel.applies(dish.deformed(bumps), on_axis) is None
    assert fresnel.correction(dish, dish, GRID, on_axis, np.ones((30, 24, 3)), 1) is None
