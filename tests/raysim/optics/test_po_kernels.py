"""The PO radiation kernels against the exact fields of Hertzian dipoles (near and far).

Reference: Balanis, *Antenna Theory* (4th ed.), sec. 4.2 (infinitesimal electric dipole) and,
by duality, the infinitesimal magnetic dipole; time factor exp(+j w t). The references are
written in the dipole's own spherical frame (r, theta, phi), independently of the kernels'
Cartesian dyadic form.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from raysim.errors import RaysimError
from raysim.optics import po
from raysim.optics import runtime as warp_runtime
from raysim.optics.kernels import radiation

K = 2.0 * np.pi / 0.7  # rad/m: lambda = 0.7 m


def electric_dipole_exact(points, origin, axis, moment, k):
    """E of an electric dipole I l = ``moment`` (A m) along ``axis`` at ``origin`` (Balanis 4-10)."""
    w = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    d = points - origin
    r = np.linalg.norm(d, axis=1)
    r_hat = d / r[:, None]
    cos_t = r_hat @ w
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    # theta_hat = (cos t) (rho_hat) - (sin t) w, rho_hat the unit radial direction off the axis
    rho = r_hat - cos_t[:, None] * w
    rho_len = np.linalg.norm(rho, axis=1)
    rho_hat = rho / rho_len[:, None]
    theta_hat = cos_t[:, None] * rho_hat - sin_t[:, None] * w
    kr = k * r
    eta = po.ETA0
    phase = np.exp(-1j * kr)
    E_r = eta * moment * cos_t / (2 * np.pi * r**2) * (1 + 1 / (1j * kr)) * phase
    E_t = 1j * eta * k * moment * sin_t / (4 * np.pi * r) * (1 + 1 / (1j * kr) - 1 / kr**2) * phase
    return E_r[:, None] * r_hat + E_t[:, None] * theta_hat


def magnetic_dipole_exact(points, origin, axis, moment, k):
    """E of a magnetic dipole I_m l = ``moment`` (V m) along ``axis`` (duality of Balanis 4-10)."""
    w = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    d = points - origin
    r = np.linalg.norm(d, axis=1)
    r_hat = d / r[:, None]
    cos_t = r_hat @ w
    sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t**2))
    phi_hat = np.cross(w, r_hat)
    phi_hat /= np.linalg.norm(phi_hat, axis=1, keepdims=True)
    kr = k * r
    E_p = -1j * k * moment * sin_t / (4 * np.pi * r) * (1 + 1 / (1j * kr)) * np.exp(-1j * kr)
    return E_p[:, None] * phi_hat


def _field_points(origin, rng):
    """Points at kr from 0.05 (reactive near field) to 2000 (far field), many directions."""
    kr = np.geomspace(0.05, 2000.0, 41)
    dirs = rng.normal(size=(len(kr), 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    return origin + (kr / K)[:, None] * dirs


def _rel_error(got, ref):
    return np.linalg.norm(got - ref, axis=1) / np.linalg.norm(ref, axis=1)


@pytest.mark.parametrize("tile", [1, 4])
def test_electric_dipole_near_and_far(tile):
    rng = np.random.default_rng(5)
    origin = np.array([3.0, -2.0, 20.0])
    axis = np.array([0.3, -0.5, 0.8])
    moment = 1.7 - 0.4j
    points = _field_points(origin, rng)
    radiator = po.Radiator(points, K, "cpu", tile=tile)
    w = axis / np.linalg.norm(axis)
    radiator.add(po.CurrentElements(origin[None, :], (moment * w)[None, :]))
    err = _rel_error(radiator.field(), electric_dipole_exact(points, origin, axis, moment, K))
    assert err.max() < 1e-12, err.max()


@pytest.mark.parametrize("tile", [1, 4])
def test_magnetic_dipole_near_and_far(tile):
    rng = np.random.default_rng(6)
    origin = np.array([-1.0, 4.0, 7.5])
    axis = np.array([1.0, 1.0, 0.2])
    moment = 0.3 + 2.2j
    points = _field_points(origin, rng)
    radiator = po.Radiator(points, K, "cpu", tile=tile)
    w = axis / np.linalg.norm(axis)
    radiator.add(po.CurrentElements(origin[None, :], (moment * w)[None, :], magnetic=True))
    err = _rel_error(radiator.field(), magnetic_dipole_exact(points, origin, axis, moment, K))
    assert err.max() < 1e-12, err.max()


@pytest.mark.parametrize("magnetic", [False, True])
def test_many_elements_add_up_across_blocks_and_threads(magnetic):
    """Superposition: many dipoles in small blocks, on both kernels (one point a thread, and
    four points in vector lanes), match the exact sum."""
    rng = np.random.default_rng(7)
    n = 37
    origins = rng.uniform(-3, 3, size=(n, 3))
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    moments = rng.normal(size=n) + 1j * rng.normal(size=n)
    points = np.array([0.0, 0.0, 30.0]) + rng.normal(size=(203, 3))
    dipole = magnetic_dipole_exact if magnetic else electric_dipole_exact
    exact = sum(dipole(points, o, a, m, K) for o, a, m in zip(origins, axes, moments, strict=True))
    for tile in (1, 4):
        radiator = po.Radiator(points, K, "cpu", block=5, tile=tile)
        radiator.add(po.CurrentElements(origins, moments[:, None] * axes, magnetic=magnetic))
        assert radiator.pairs == n * len(points)
        err = np.linalg.norm(radiator.field() - exact) / np.linalg.norm(exact)
        assert err < 1e-12, (tile, err)


def test_phase_beyond_the_kernel_range_is_refused():
    radiator = po.Radiator(np.array([[0.0, 0.0, 1e5]]), 2.0 * np.pi / 0.01, "cpu")
    with pytest.raises(RaysimError, match="phase range"):
        radiator.add(po.CurrentElements(np.zeros((1, 3)), np.ones((1, 3), dtype=complex)))


def test_incident_field_convention():
    """E_inc = e_hat exp(-j k k_hat . r): on axis (k_hat = -z) x_hat exp(+j k z)."""
    z = np.array([0.0, 1.3, 7.9])
    points = np.column_stack([0 * z, 0 * z, z])
    E = po.incident_field(points, K, (0, 0, -1), (1, 0, 0))
    np.testing.assert_allclose(E[:, 0], np.exp(1j * K * z), rtol=0, atol=1e-15)
    assert np.all(E[:, 1:] == 0)


@wp.kernel(enable_backward=False)
def _cis_kernel(x: wp.array(dtype=wp.float64), table: wp.array(dtype=wp.vec2d),
                out: wp.array(dtype=wp.vec2d)):
    i = wp.tid()
    out[i] = radiation.cis(x[i], table)


def test_cis_against_long_double():
    """The kernels' exp(-j k R): cos and sin to 1e-15 (a few ulp) up to the phase limit."""
    warp_runtime.init()
    rng = np.random.default_rng(8)
    x = np.concatenate([np.linspace(0.0, 20.0, 20001), rng.uniform(0, 1e4, 50000),
                        rng.uniform(0, 0.99 * radiation.MAX_PHASE, 50000)])
    out = wp.zeros(len(x), dtype=wp.vec2d, device="cpu")
    wp.launch(_cis_kernel, dim=len(x), device="cpu",
              inputs=[wp.array(x, dtype=wp.float64, device="cpu"),
                      wp.array(radiation.cis_table(), dtype=wp.vec2d, device="cpu"), out])
    got = out.numpy()
    xl = x.astype(np.longdouble)
    assert np.finfo(np.longdouble).eps < 1e-18, "needs 80-bit long double for the reference"
    err_c = np.abs(got[:, 0] - np.cos(xl)).max()
    err_s = np.abs(got[:, 1] - np.sin(xl)).max()
    assert max(err_c, err_s) < 1e-15, (err_c, err_s)
