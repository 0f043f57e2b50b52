"""PO and PO + PTD of a large flat plate's straight edge against Sommerfeld's exact half-plane.

Reference: the exact solution of a perfectly conducting half-plane under a plane wave
(Sommerfeld; Balanis, *Advanced Engineering Electromagnetics*, 2nd ed., ch. 13), in the
exp(+j w t) convention: with the edge along t, the plate along +x and y its normal on the lit
side, the field components along the edge are

    E_t = E_t^i(edge) [U(rho, p - p') - U(rho, p + p')] exp(-j k_z z),
    H_t = H_t^i(edge) [U(rho, p - p') + U(rho, p + p')] exp(-j k_z z),
    U(rho, psi) = exp(j pi/4) / sqrt(pi) exp(j k_t rho cos psi) Int_{-inf}^{a} exp(-j t^2) dt,
    a = sqrt(2 k_t rho) cos(psi / 2),  k_t = k sin b',  k_z = k cos b',

(the integral is a Fresnel integral, scipy.special.fresnel) and the transverse components
follow from Maxwell's equations, E_T = -(j / k_t^2) (k_z grad E_t - k eta t x grad H_t).

The plate here is 60 to 130 wavelengths across with its current (PO and fringe) tapered
smoothly to zero far from the edge under test, so that no other edge diffracts. PO alone
misses the edge wave by O((k rho)^-1/2) of the incident field; PTD's fringe currents capture
its leading term, leaving O((k rho)^-3/2) (one power of k rho better) away from grazing.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import fresnel

from raysim.optics import po, ptd
from raysim.surface.mesh import Reflector
from raysim.surface.quadrature import FaceQuadrature
from tests.flat import FlatSurface

LAMBDA = 1.0  # m
RHO = np.array([2.0, 4.0, 8.0, 16.0])  # distances from the edge (m): k rho = 12.6 .. 100.5
PHI = np.radians([20, 45, 70, 90, 110, 135, 160, 200, 225, 250, 270, 290, 315, 340])
AWAY = (PHI >= np.radians(45)) & (PHI <= np.radians(315))  # not near the plate's faces
EDGE = np.array([0.31, 0.17, 0.0])  # a point on the edge under test (m)


# --- the exact solution -------------------------------------------------------------------
def _fresnel_tail(a):
    """Int_{-inf}^{a} exp(-j t^2) dt."""
    S, C = fresnel(a * np.sqrt(2.0 / np.pi))
    return np.sqrt(np.pi / 2.0) * ((0.5 + C) - 1j * (0.5 + S))


def _U(rho, psi, kt):
    """U(rho, psi) and its derivatives in rho and in the angle."""
    pref = np.exp(1j * np.pi / 4.0) / np.sqrt(np.pi)
    a = np.sqrt(2.0 * kt * rho) * np.cos(0.5 * psi)
    wave = pref * np.exp(1j * kt * rho * np.cos(psi))
    U = wave * _fresnel_tail(a)
    edge = wave * np.exp(-1j * a * a)
    d_rho = 1j * kt * np.cos(psi) * U + edge * a / (2.0 * rho)
    d_phi = -1j * kt * rho * np.sin(psi) * U - edge * 0.5 * np.sqrt(2.0 * kt * rho) * np.sin(0.5 * psi)
    return U, d_rho, d_phi


def exact_total(P, r0, x, y, t, k, k_hat, e_hat):
    """Total E (n, 3) of the half-plane with edge through r0 along t, plate along +x."""
    d = P - r0
    X, Y, Z = d @ x, d @ y, d @ t
    rho = np.hypot(X, Y)
    phi = np.mod(np.arctan2(Y, X), 2.0 * np.pi)
    cos_b = k_hat @ t
    sin_b = np.sqrt(1.0 - cos_b**2)
    phi_i = np.arctan2(-(k_hat @ y), -(k_hat @ x))
    kt, kz = k * sin_b, k * cos_b
    at_edge = np.exp(-1j * k * (r0 @ k_hat))
    Et0 = (e_hat @ t) * at_edge
    Ht0 = (np.cross(k_hat, e_hat) @ t) / po.ETA0 * at_edge
    U1, r1, p1 = _U(rho, phi - phi_i, kt)
    U2, r2, p2 = _U(rho, phi + phi_i, kt)
    along = np.exp(-1j * kz * Z)

    def grad(d_rho, d_phi):
        return (np.cos(phi) * d_rho - np.sin(phi) / rho * d_phi,
                np.sin(phi) * d_rho + np.cos(phi) / rho * d_phi)

    ex, ey = grad(r1 - r2, p1 - p2)
    hx, hy = grad(r1 + r2, p1 + p2)
    ex, ey, hx, hy = (Et0 * ex * along, Et0 * ey * along, Ht0 * hx * along, Ht0 * hy * along)
    EX = -(1j / kt**2) * (kz * ex + k * po.ETA0 * hy)
    EY = -(1j / kt**2) * (kz * ey - k * po.ETA0 * hx)
    Et = Et0 * (U1 - U2) * along
    return EX[:, None] * x + EY[:, None] * y + Et[:, None] * t


# --- the plate --------------------------------------------------------------------------


def plate(core: float, ramp: float, h: float = 2.5):
    """Rectangle in z = 0, edge under test at x = EDGE[0], plate towards +x; and its taper:
    1 within ``core`` (m) of the edge point, smoothly 0 over the next ``ramp`` (m)."""
    x0, yc, size = EDGE[0], EDGE[1], core + ramp
    nx, ny = int(np.ceil(size / h)) + 1, int(np.ceil(2 * size / h)) + 1
    X, Y = np.meshgrid(np.linspace(x0, x0 + size, nx), np.linspace(yc - size, yc + size, ny), indexing="ij")
    vertices = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    i = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = i[:-1, :-1].ravel(), i[1:, :-1].ravel(), i[1:, 1:].ravel(), i[:-1, 1:].ravel()
    faces = np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
    normals = np.zeros_like(vertices)
    normals[:, 2] = 1.0
    refl = Reflector(vertices, faces, np.zeros(len(faces), dtype=np.int64), normals, 1.0, 2.0 * size,
                     FlatSurface(), None)

    def bump(u):
        u = np.clip(u, 0.0, 1.0)
        f = np.where(u > 0, np.exp(-1.0 / np.maximum(u, 1e-300)), 0.0)
        g = np.where(u < 1, np.exp(-1.0 / np.maximum(1.0 - u, 1e-300)), 0.0)
        return f / (f + g)

    def taper(x, y):
        return bump((x0 + size - x) / ramp) * bump((size - np.abs(y - yc)) / ramp)

    return refl, taper


def errors(refl, taper, k_hat, e_hat):
    """Max over directions of |E - E_exact| (scattered field, V/m per V/m incident) at each
    distance, for PO and for PO + PTD, and the points' edge-frame field components."""
    wave = po.Illumination.plane_wave(po.C0 / LAMBDA, k_hat, e_hat)
    x = np.array([1.0, 0.0, 0.0])
    y = np.array([0.0, 0.0, 1.0]) * (-np.sign(wave.k_hat[2]))
    t = np.cross(x, y)
    cot_b = (wave.k_hat @ t) / np.sqrt(1.0 - (wave.k_hat @ t) ** 2)
    R, P_ = np.meshgrid(RHO, PHI, indexing="ij")
    # on the Keller cone of the edge point EDGE: the stationary point stays there
    P = EDGE + R.reshape(-1, 1) * (np.cos(P_).reshape(-1, 1) * x + np.sin(P_).reshape(-1, 1) * y + cot_b * t)
    radiator = po.Radiator(P, wave.k)
    for src in po.po_elements(refl, wave, FaceQuadrature(refl, LAMBDA / 4.0, curve_rim=False), taper=taper):
        radiator.add_packed(src)
    E_po = radiator.field()
    E_edge = ptd.edge_field(refl, P, wave, "all", taper=taper, curve=False).E
    exact = exact_total(P, EDGE, x, y, t, wave.k, wave.k_hat, wave.e_hat) - po.incident_field(
        P, wave.k, wave.k_hat, wave.e_hat)
    e_po = np.linalg.norm(E_po - exact, axis=1).reshape(R.shape)
    e_ptd = np.linalg.norm(E_po + E_edge - exact, axis=1).reshape(R.shape)
    return e_po, e_ptd, (E_po @ t).reshape(R.shape), ((E_po + E_edge) @ t).reshape(R.shape)


def slope(err):
    """Log-log slope of an error against k rho (least squares over the distances)."""
    return np.polyfit(np.log(RHO), np.log(err), 1)[0]


SKEW = np.radians(50.0), np.radians(60.0)  # b', p' of the oblique cases


def oblique(hard: bool):
    b, p = SKEW
    # edge frame of the plate: x = +x, y = +z (lit side), t = x cross y = -y
    k_hat = -(np.sin(b) * np.cos(p) * np.array([1, 0, 0]) + np.sin(b) * np.sin(p) * np.array([0, 0, 1])) \
        + np.cos(b) * np.array([0.0, -1.0, 0.0])
    soft_e = np.cross(np.cross(k_hat, [0.0, 1.0, 0.0]), k_hat)  # E in the plane of k and the edge
    e_hat = np.cross(k_hat, soft_e) if hard else soft_e
    return k_hat, e_hat / np.linalg.norm(e_hat)


@pytest.fixture(scope="module")
def normal_plate():
    return plate(22.0, 16.0)


@pytest.fixture(scope="module")
def large_plate():
    return plate(40.0, 25.0)


# --- the reference itself ------------------------------------------------------------------
def test_exact_solution_vanishes_on_the_plate():
    """Tangential E is zero on both faces of the half-plane, for either polarisation."""
    x, y, t = np.eye(3)
    for k_hat, e_hat in (oblique(False), oblique(True)):
        X = np.linspace(0.3, 9.0, 7)
        for side in (1e-12, -1e-12):  # just above and just below the plate
            P = np.column_stack([X, side * np.ones_like(X), 0.2 * X])
            E = exact_total(P, np.zeros(3), x, y, t, 2 * np.pi, k_hat, e_hat)
            assert np.abs(E @ x).max() < 1e-9 and np.abs(E @ t).max() < 1e-9


def test_exact_solution_is_geometrical_optics_far_from_the_edge():
    """At k rho = 6000 in the lit region, away from the shadow and reflection boundaries,
    the total field is the incident plus the reflected plane wave to O((k rho)^-1/2)."""
    x, y, t = np.eye(3)
    k = 2 * np.pi
    k_hat = np.array([-np.cos(1.0), -np.sin(1.0), 0.0])  # p' = 1 rad, normal to the edge
    e_hat = np.array([0.0, 0.0, 1.0])
    phi = np.radians([30.0, 60.0, 150.0, 200.0])  # reflection region, then lit only
    P = 955.0 * np.column_stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)])
    E = exact_total(P, np.zeros(3), x, y, t, k, k_hat, e_hat)
    k_ref = k_hat * np.array([1.0, -1.0, 1.0])  # mirrored in the plate
    go = po.incident_field(P, k, k_hat, e_hat) - po.incident_field(P, k, k_ref, e_hat) * (phi < np.pi - 1.0)[:, None]
    assert np.abs(E - go).max() < 0.02


# --- PO and PO + PTD against it ----------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("polarisation", ["soft", "hard"])
def test_normal_incidence(normal_plate, polarisation):
    """E along the edge (soft) or across it (hard), wave normal to the plate."""
    e_hat = (0.0, 1.0, 0.0) if polarisation == "soft" else (1.0, 0.0, 0.0)
    e_po, e_ptd, _, _ = errors(*normal_plate, (0.0, 0.0, -1.0), e_hat)
    po_max, ptd_max, ptd_away = e_po.max(axis=1), e_ptd.max(axis=1), e_ptd[:, AWAY].max(axis=1)
    # PO misses the edge wave: a few per cent of the incident field, falling as (k rho)^-1/2
    assert po_max.min() > 0.02, po_max
    assert -0.6 < slope(po_max) < -0.4, slope(po_max)
    # PO + PTD: over an order of magnitude better from the start, one power of k rho faster
    assert np.all(ptd_max < po_max / 4), (ptd_max, po_max)
    assert ptd_max[-1] < po_max[-1] / 20, (ptd_max, po_max)
    assert slope(ptd_away) < -1.4, slope(ptd_away)
    assert slope(ptd_max) < -1.15, slope(ptd_max)


@pytest.mark.slow
@pytest.mark.parametrize("hard", [False, True], ids=["soft", "hard"])
def test_skew_incidence(large_plate, hard):
    """b' = 50 deg to the edge, p' = 60 deg from the plate: the Keller cone opens to 100 deg."""
    e_po, e_ptd, Et_po, Et_ptd = errors(*large_plate, *oblique(hard))
    po_max, ptd_max = e_po.max(axis=1), e_ptd.max(axis=1)
    assert po_max.min() > 0.02, po_max
    assert np.all(ptd_max < po_max / 4), (ptd_max, po_max)
    assert ptd_max[-1] < po_max[-1] / 10, (ptd_max, po_max)
    assert slope(ptd_max) < -1.1, slope(ptd_max)
    if hard:
        # no E along the edge exists for this polarisation; PO's current radiates some under
        # skew incidence, and the H_t term of the fringe current I removes it
        assert np.abs(Et_po).max() > 0.01
        assert np.abs(Et_ptd).max() < np.abs(Et_po).max() / 10
