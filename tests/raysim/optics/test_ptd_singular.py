"""The fringe currents in every direction: finite, and smooth where the classical forms blow up.

Keller's diffraction coefficients and PO's edge term are both infinite at the shadow and
reflection boundaries; their difference, the fringe coefficient, is finite there (its value
on the boundary is the limit from either side). Michaeli's ray-coordinate form keeps it finite
off the Keller cone as well, grazing directions included; the one case it leaves singular
(grazing incidence observed along the grazing ray) is capped. One edge element is radiated to
a far sphere of directions.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.optics import po, ptd
from raysim.surface.edges import Edges

LAMBDA = 1.0
FAR = 1.0e4  # m: the field times distance is the far-field pattern to 1e-4
X, Y, T = np.eye(3)  # edge frame: plate along +x, lit normal +y, edge along t = x cross y


def element_field(directions, beta_i, phi_i, polarisation_deg=30.0):
    """R E (V) in ``directions`` (n, 3) of a unit-length edge element at the origin."""
    k_hat = -(np.sin(beta_i) * np.cos(phi_i) * X + np.sin(beta_i) * np.sin(phi_i) * Y) + np.cos(beta_i) * T
    a = np.cross(k_hat, T)
    a = a / np.linalg.norm(a) if np.linalg.norm(a) > 1e-12 else X
    b = np.cross(k_hat, a)
    chi = np.radians(polarisation_deg)
    wave = po.Illumination.plane_wave(po.C0 / LAMBDA, k_hat, np.cos(chi) * a + np.sin(chi) * b)
    one = np.zeros((1, 3))
    edge = Edges(one, T[None], Y[None], X[None], np.ones(1), one, np.zeros(1, dtype=np.int64),
                 np.zeros(1, dtype=bool))
    radiator = po.Radiator(FAR * np.asarray(directions), wave.k)
    radiator.add_packed(ptd.fringe_elements(edge, wave), "fringe")
    return radiator.field() * FAR


def keller(beta, phi):
    """Directions on the Keller cone at angle beta to the edge, azimuth phi from the plate."""
    phi = np.atleast_1d(phi)
    return (np.sin(beta) * (np.cos(phi)[:, None] * X + np.sin(phi)[:, None] * Y)
            + np.cos(beta) * T)


def fibonacci(n: int) -> np.ndarray:
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    phi = np.pi * (1.0 + 5**0.5) * i
    return np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])


@pytest.mark.parametrize("beta_i", np.radians([90.0, 50.0, 10.0]))
@pytest.mark.parametrize("phi_i", np.radians([0.5, 30.0, 90.0, 150.0, 179.5]))
def test_finite_and_bounded_in_every_direction(beta_i, phi_i):
    directions = np.vstack([fibonacci(4000), T, -T, X, -X, Y, -Y,
                            keller(beta_i, [0.0, np.pi - phi_i, np.pi + phi_i, np.pi])])
    RE = element_field(directions, beta_i, phi_i)
    assert np.all(np.isfinite(RE))
    # the pattern of a unit edge stays below about 1 / (4 pi) times 2 / (s + c), s + c >= c
    assert np.abs(RE).max() < 0.6 / np.cos(phi_i / 2), np.abs(RE).max()


@pytest.mark.parametrize("beta_i", np.radians([90.0, 50.0]))
@pytest.mark.parametrize("phi_i", np.radians([20.0, 60.0, 120.0]))
def test_continuous_across_shadow_and_reflection_boundaries(beta_i, phi_i):
    """On the Keller cone and off it (beta = b' +- 5 deg), across p = pi -+ p'."""
    eps = 1e-6
    for beta in (beta_i, beta_i - np.radians(5.0), beta_i + np.radians(5.0)):
        for boundary in (np.pi - phi_i, np.pi + phi_i):
            RE = element_field(keller(beta, [boundary - eps, boundary, boundary + eps]), beta_i, phi_i)
            scale = np.abs(RE).max()
            assert scale > 1e-3
            assert np.abs(RE[2] - RE[0]).max() < 1e-4 * scale
            assert np.abs(RE[1] - 0.5 * (RE[0] + RE[2])).max() < 1e-4 * scale


def test_smooth_around_the_cone():
    """Random directions nudged by 1e-6 rad change the pattern by about that fraction, except
    within 1e-3 rad of the grazing ray along the plate (a bounded, direction-dependent limit)."""
    rng = np.random.default_rng(7)
    d = fibonacci(600)
    nudge = d + 1e-6 * np.cross(d, rng.standard_normal(d.shape))
    nudge /= np.linalg.norm(nudge, axis=1, keepdims=True)
    beta_i, phi_i = np.radians(60.0), np.radians(70.0)
    s_g = np.sin(beta_i) * X + np.cos(beta_i) * T
    keep = np.arccos(np.clip(d @ s_g, -1, 1)) > 1e-3
    a, b = element_field(d, beta_i, phi_i), element_field(nudge, beta_i, phi_i)
    scale = np.abs(a).max()
    assert np.abs(a - b)[keep].max() < 1e-3 * scale


def test_ufimtsev_singularity_is_capped():
    """Grazing incidence from outside the plate (p' = pi) observed along the grazing ray: the
    fringe form itself is infinite there; the kernel returns a finite value."""
    beta_i = np.radians(70.0)
    s_g = np.sin(beta_i) * X + np.cos(beta_i) * T
    RE = element_field(np.vstack([s_g, keller(beta_i, [0.3, 1.0])]), beta_i, np.pi)
    assert np.all(np.isfinite(RE))
