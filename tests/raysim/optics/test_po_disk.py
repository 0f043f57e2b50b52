"""PO of a flat circular disk at normal incidence against its closed form on the axis.

With J = 2 n x H_inc uniform on the disk (radius a, in z = 0, wave along -z polarised along x),
the scattered field on the axis at height z is, exactly for PO,
E_x(z) = -exp(-jkz) + exp(-jk Ra) [(1 + cos^2 alpha)/2 + j sin^2 alpha / (2 k Ra)],
Ra = sqrt(z^2 + a^2), cos alpha = z / Ra, sin alpha = a / Ra (issue 5). Every rim point is at
the same distance from an axis point, so the rim's edge wave adds coherently there: the
hardest case for a polygonal rim, which the quadrature replaces by the true circle.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from raysim.optics import po
from raysim.surface.quadrature import FaceQuadrature
from tests.flat import flat_disk

A = 5.0  # disk radius (m)
Z = np.linspace(2.0, 50.0, 25)  # axis points (m)


def closed_form(z, a, k):
    Ra = np.sqrt(z * z + a * a)
    cos_a, sin_a = z / Ra, a / Ra
    return -np.exp(-1j * k * z) + np.exp(-1j * k * Ra) * ((1 + cos_a**2) / 2
                                                         + 1j * sin_a**2 / (2 * k * Ra))


def axis_field(reflector, wave, spacing: float, curve_rim: bool = True) -> np.ndarray:
    """PO field (n, 3) on the axis points through the library's own pieces."""
    points = np.column_stack([0 * Z, 0 * Z, Z])
    quadrature = FaceQuadrature(reflector, spacing, curve_rim=curve_rim)
    radiator = po.Radiator(points, wave.k, "cpu")
    for src in po.po_elements(reflector, wave, quadrature):
        radiator.add_packed(src)
    return radiator.field()


@pytest.fixture(scope="module")
def disk():
    return flat_disk(A, 1.0)


@pytest.mark.parametrize("frequency_hz", [0.3e9, 1e9])
def test_disk_on_axis_matches_closed_form(disk, frequency_hz):
    wave = po.Illumination.plane_wave(frequency_hz, (0, 0, -1), (1, 0, 0))
    E = axis_field(disk, wave, wave.wavelength / 4.0)
    exact = closed_form(Z, A, wave.k)
    rel = np.abs(E[:, 0] - exact) / np.abs(exact)
    assert rel.max() < 1e-4, rel.max()
    # by symmetry the cross-polar and axial components vanish on the axis
    assert np.abs(E[:, 1:]).max() < 1e-4 * np.abs(exact).min()


def test_disk_converges_in_samples_per_wavelength(disk):
    """Errors fall by more than 10x per step of samples per wavelength (Gauss order grows)."""
    wave = po.Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    exact = closed_form(Z, A, wave.k)
    errors = []
    for spw in (1.5, 2.0, 3.0, 4.0):
        E = axis_field(disk, wave, wave.wavelength / spw)
        errors.append(np.max(np.abs(E[:, 0] - exact) / np.abs(exact)))
    assert errors[0] > 1e-2  # the coarse end really is coarse
    for coarse, fine in itertools.pairwise(errors):
        assert fine < coarse / 10, errors
    assert errors[-1] < 1e-4, errors


def test_polygonal_rim_is_what_the_arcs_fix(disk):
    """The same faces with the chords as rim err by far more: the edge wave moves with it."""
    wave = po.Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    exact = closed_form(Z, A, wave.k)
    spacing = wave.wavelength / 4.0
    curved = np.abs(axis_field(disk, wave, spacing)[:, 0] - exact) / np.abs(exact)
    chords = np.abs(axis_field(disk, wave, spacing, curve_rim=False)[:, 0] - exact) / np.abs(exact)
    assert chords.max() > 1e-3
    assert chords.max() > 100 * curved.max()
