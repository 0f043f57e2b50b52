"""PO under an obstacle's shadow: the lit part of the faces the shadow's edge crosses.

The reference is written here a second way, without meshes or rays: on axis the shadow of a
disk at any height is its outline projected along z, the 128-gon circumscribed about the disk
(raysim's disk obstacle), so the lit reflector is the dish less that polygon. Its PO current
J = 2 n x H_inc is integrated exactly over it in polar coordinates (Gauss in phi on each of the
polygon's sectors, Gauss in r from the polygon's side out to the rim) and radiated by the
closed-form field of electric dipoles (Balanis 4-10, tests/raysim/optics/test_po_kernels.py).
Keeping or dropping whole samples at the shadow's edge erred by 0.85 % in intensity here at 4
samples per wavelength (1 % at the default 1.5), converging only as the samples' spacing.
"""

from __future__ import annotations

import math
from itertools import pairwise

import numpy as np
import pytest

from raysim.optics import po
from raysim.optics.bvh import ReflectorBVH
from raysim.optics.illumination import Illumination
from raysim.optics.shadow_edge import lit_samples
from raysim.scene.scene import parse_scene
from raysim.surface.mesh import reflectors_for
from raysim.surface.obstacles import DISK_SEGMENTS
from raysim.surface.quadrature import plan
from tests.raysim.optics.test_po_kernels import electric_dipole_exact

D, F, R, HZ = 10.0, 5.0, 2.0, 0.5e9
CABIN, CABIN_Z = 1.0, 4.0
SCENE = f"""
name = "shadowed"
method = "po"
[dish]
diameter_m = {D}
focal_length_m = {F}
resolution_m = 1.0
[[obstacle]]
type = "disk"
radius_m = {CABIN}
z_m = {CABIN_Z}
[source]
frequency_hz = {HZ}
[sphere]
radius_m = {R}
n_theta = 6
n_phi = 8
"""


@pytest.fixture(scope="module")
def shadowed():
    reflector, _ = reflectors_for(parse_scene(SCENE))
    wave = Illumination.plane_wave(HZ, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    return reflector, wave


def polygon_area() -> float:
    """The disk's shadow: the 128-gon whose inscribed circle is the disk (m^2)."""
    n = DISK_SEGMENTS
    return n * CABIN**2 * math.tan(math.pi / n)


@pytest.mark.parametrize(("samples_per_wavelength", "bound"), [(1.5, 1e-3), (4.0, 1e-4)])
def test_the_lit_area_is_the_dish_less_the_shadow_polygon(shadowed, samples_per_wavelength, bound):
    reflector, wave = shadowed
    quadrature = plan(reflector, wave.wavelength, samples_per_wavelength)
    bvh = ReflectorBVH.build(reflector, "cpu")
    projected = sum(lit_samples(quadrature, chunk, bvh, wave.k_hat)[0].area[:, 2].sum()
                    for chunk in quadrature.chunks())
    exact = math.pi * (D / 2) ** 2 - polygon_area()
    # whole samples kept or dropped: 0.026 and 0.022 m^2 off (0.8 and 0.7 % of the shadow); cut
    # along the edge, the chords' error falls with the square of the pieces (a quarter of the
    # samples' spacing at the most here)
    assert abs(projected - exact) < bound * polygon_area()


LEGS = """
name = "legs"
method = "po"
[dish]
diameter_m = 15.0
focal_length_m = 6.0
resolution_m = 1.0
[[obstacle]]
type = "disk"
radius_m = 0.8
z_m = 6.0
[[obstacle]]
type = "legs"
count = 4
width_m = 0.2
foot_radius_m = 5.0
apex_z_m = 6.0
apex_radius_m = 0.8
rotation_deg = 45.0
[source]
frequency_hz = 0.5e9
[sphere]
radius_m = 2.0
n_theta = 4
n_phi = 8
"""


def test_a_leg_shadow_narrower_than_the_samples_spacing_is_cut_not_skipped():
    """0.2 m legs (up to a 0.8 m cabin) on 1 m faces at 0.5 GHz: the default's samples lie
    0.33 m apart, and each leg's shadow passed between a face's samples and corners, kept
    whole (0.018 m^2 a face). The lit area converges: the default against 12 samples per
    wavelength. (A leg's end inside a face, with no cabin over it, is still kept or dropped
    at the finest pieces' samples: 0.0024 m^2 a face at the default.)"""
    reflector, _ = reflectors_for(parse_scene(LEGS))
    wave = Illumination.plane_wave(0.5e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))
    bvh = ReflectorBVH.build(reflector, "cpu")

    def lit_area(samples_per_wavelength):
        quadrature = plan(reflector, wave.wavelength, samples_per_wavelength)
        return sum(lit_samples(quadrature, chunk, bvh, wave.k_hat)[0].area[:, 2].sum()
                   for chunk in quadrature.chunks())

    shadow = math.pi * 7.5**2 - lit_area(12.0)          # cabin and legs, about 5.5 m^2
    assert 4.0 < shadow < 7.0
    # samples and corners only: 0.073 m^2 (2 % of the shadow); whole samples: 0.81 m^2
    assert abs(lit_area(1.5) - lit_area(12.0)) < 2e-3 * shadow


def reference_field(points: np.ndarray, wave: Illumination) -> np.ndarray:
    """PO field (n, 3) of the dish less the polygon, by the module's quadrature."""
    n = DISK_SEGMENTS
    gp, gw = np.polynomial.legendre.leggauss(8)
    side = 2.0 * np.pi / n
    phi = (np.arange(n)[:, None] + 0.5 * (gp[None, :] + 1.0)) * side            # (n, 8)
    w_phi = np.broadcast_to(0.5 * gw * side, phi.shape)
    r_in = CABIN / np.cos(phi - (np.arange(n)[:, None] + 0.5) * side)           # the side's line
    edges = np.linspace(0.0, 1.0, 25)
    s = np.concatenate([0.5 * (a + b) + 0.5 * (b - a) * gp for a, b in pairwise(edges)])
    w_s = np.concatenate([0.5 * (b - a) * gw for a, b in pairwise(edges)])
    a = D / 2
    r = r_in[..., None] + s * (a - r_in)[..., None]                               # (n, 8, S)
    w = w_phi[..., None] * w_s * (a - r_in)[..., None] * r                        # r dr dphi
    phi3 = np.broadcast_to(phi[..., None], r.shape)
    x, y = (r * np.cos(phi3)).ravel(), (r * np.sin(phi3)).ravel()
    z = (x * x + y * y) / (4.0 * F)
    normal_area = np.column_stack([-x / (2 * F), -y / (2 * F), np.ones_like(x)]) * w.ravel()[:, None]
    source = np.column_stack([x, y, z])
    h_inc = np.cross(wave.k_hat, wave.e_hat) / po.ETA0 * np.exp(-1j * wave.k * (source @ wave.k_hat))[:, None]
    moment = 2.0 * np.cross(normal_area, h_inc)                                   # J dA (A m)
    field = np.zeros((len(points), 3), dtype=complex)
    for i, p in enumerate(points):
        for c, axis in enumerate(np.eye(3)):
            field[i] += electric_dipole_exact(p[None, :], source, axis, moment[:, c], wave.k).sum(axis=0)
    return field


def test_po_field_of_a_shadowed_dish_matches_an_exact_quadrature_of_its_lit_part(shadowed):
    reflector, wave = shadowed
    theta, phi = np.meshgrid(np.radians([10.0, 30.0, 50.0, 65.0]), np.radians(np.arange(0, 360, 45.0)))
    theta, phi = theta.ravel(), phi.ravel()
    points = np.column_stack([R * np.sin(theta) * np.cos(phi), R * np.sin(theta) * np.sin(phi),
                              F - R * np.cos(theta)])
    got = po.scatter(reflector, points, wave, samples_per_wavelength=4.0, radiator="direct").E
    want = reference_field(points, wave)
    intensity = np.sum(np.abs(got) ** 2, axis=1) / np.sum(np.abs(want) ** 2, axis=1) - 1.0
    # samples kept or dropped whole: 0.85 % (1e-8 without the obstacle at these settings)
    assert np.max(np.abs(intensity)) < 2e-4
