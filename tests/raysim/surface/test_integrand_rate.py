"""PO's quadrature spaced by the integrand's own rate (raysim.surface.quadrature.plan with
targets): the rate bound against finite differences of the phase on the smooth surface, the
field against a finer uniform quadrature, and the same samples for a deformed twin."""

from __future__ import annotations

import numpy as np
import pytest

from raysim.optics import po
from raysim.optics.radiator import Radiator
from raysim.surface.deformation import GaussianBumps, PaperDeformation
from raysim.surface.mesh import paraboloid
from raysim.surface.quadrature import (
    FaceQuadrature,
    Targets,
    gauss_reach,
    integrand_orders,
    integrand_rate,
    plan,
    targets_around,
)

D, F, FACE = 20.0, 8.0, 2.5


def sphere_points(centre, radius: float, n: int, rng) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    return np.asarray(centre) + radius * v / np.linalg.norm(v, axis=1, keepdims=True)


def surface_phase_rate(x, y, P, k_hat, h=1e-5):
    """|surface gradient| of psi(s) = k_i . s + |P - s| on z = (x^2 + y^2) / 4F, by central
    differences in (x, y) and the graph's metric (g = I + grad z grad z^T)."""
    def psi(x, y):
        s = np.stack([x, y, (x * x + y * y) / (4 * F)], axis=-1)
        return s @ k_hat + np.linalg.norm(P - s, axis=-1)

    px = (psi(x + h, y) - psi(x - h, y)) / (2 * h)
    py = (psi(x, y + h) - psi(x, y - h)) / (2 * h)
    zx, zy = x / (2 * F), y / (2 * F)
    det = 1 + zx**2 + zy**2  # inverse metric: (I (1 + |grad z|^2) - grad z grad z^T) / det
    gxx, gyy, gxy = (1 + zy**2) / det, (1 + zx**2) / det, -zx * zy / det
    return np.sqrt(gxx * px**2 + 2 * gxy * px * py + gyy * py**2)


@pytest.mark.parametrize("tilt_deg", [0.0, 8.0])
def test_the_rate_bounds_the_phase_gradient_on_the_surface(tilt_deg):
    rng = np.random.default_rng(3)
    dish = paraboloid(D, F, FACE)
    t = np.radians(tilt_deg)
    k_hat = np.array([np.sin(t), 0.0, -np.cos(t)])
    targets = Targets((0.0, 0.0, F), 2.0, tuple(k_hat))
    bound = integrand_rate(dish, targets)
    P = np.concatenate([sphere_points((0, 0, F), 2.0, 300, rng),
                        sphere_points((0, 0, F), 1.0, 100, rng)])  # on the sphere and inside it
    faces = rng.choice(len(dish.faces), 40, replace=False)
    worst = 0.0
    for f in faces:
        corners = dish.vertices[dish.faces[f], :2]
        for b in rng.dirichlet(np.ones(3), 5):  # points inside the face
            x, y = b @ corners
            rate = surface_phase_rate(np.full(len(P), x), np.full(len(P), y), P, k_hat).max()
            assert rate <= bound[f] * (1 + 1e-6)
            worst = max(worst, rate / bound[f])
    assert worst > 0.5  # a bound, not a guess far above the rate
    # tilting the wave off the axis defocuses it: the integrand oscillates faster
    if tilt_deg:
        axial = integrand_rate(dish, Targets((0.0, 0.0, F), 2.0, (0.0, 0.0, -1.0)))
        assert np.median(bound) > 1.5 * np.median(axial)


def field(dish, wave, quadrature, points):
    radiator = Radiator(points, wave.k)
    for chunk in po.po_elements(dish, wave, quadrature):
        radiator.add_packed(chunk.numpy(), "electric")
    return radiator.field()


def test_the_field_matches_a_finer_uniform_quadrature_with_fewer_samples():
    rng = np.random.default_rng(5)
    dish = paraboloid(D, F, FACE)
    wave = po.Illumination.plane_wave(3e9, (0, 0, -1), (1, 0, 0))
    points = sphere_points((0, 0, F), 2.0, 150, rng)
    points = points[points[:, 2] < F + 1.0]  # the hemisphere facing the dish and a band above
    targets = targets_around(points, (0.0, 0.0, F), wave.k_hat)
    rate_plan = plan(dish, wave.wavelength, 1.5, targets)
    uniform = plan(dish, wave.wavelength, 1.5)
    fine = plan(dish, wave.wavelength, 3.0)
    assert rate_plan.n_samples < 0.75 * uniform.n_samples
    assert np.all(rate_plan.spacings >= uniform.spacing)  # never closer than asked
    E_ref = field(dish, wave, fine, points)
    err = np.sqrt(np.mean(np.abs(field(dish, wave, rate_plan, points) - E_ref) ** 2) / np.mean(np.abs(E_ref) ** 2))
    assert err < 1e-6
    # the rule asked for 1e-4 per face is visibly worse (the tolerance is not idle)
    omega = np.pi * rate_plan.edge_length * integrand_rate(dish, targets) / wave.wavelength
    coarse = FaceQuadrature(dish, uniform.spacing, face_orders=integrand_orders(omega, tol=1e-4))
    err_coarse = np.sqrt(np.mean(np.abs(field(dish, wave, coarse, points) - E_ref) ** 2) / np.mean(np.abs(E_ref) ** 2))
    assert err_coarse > 30 * err


@pytest.mark.parametrize("n", [6, 10, 17, 24, 64, 128])
def test_gauss_reach_is_where_the_rule_stops_integrating_a_phase_ramp(n):
    """Against the integral of exp(j omega x) over [-1, 1], 2 sin(omega) / omega: within the
    tolerance up to the reach, beyond it within half a radian; the reach approaches 2n from below."""
    x, w = np.polynomial.legendre.leggauss(n)

    def error(omega):
        return abs(np.exp(1j * omega * x) @ w - 2 * np.sin(omega) / omega) / 2

    tol = 1e-9
    reach = gauss_reach(n, tol)
    assert max(error(o) for o in np.linspace(0.05, reach, 400)) <= tol
    assert max(error(o) for o in np.linspace(reach + 0.02, reach + 0.5, 50)) > tol
    assert reach < 2 * n  # the degree-(2n - 1) exactness bounds it
    assert reach > (0.8 * n if n >= 16 else 0.25 * n)  # and high orders come close to it


def test_a_face_gets_points_that_follow_its_phase_and_high_orders_where_it_turns_fast():
    omega = np.array([0.5, 5.0, 40.0, 400.0])
    m, n = integrand_orders(omega, tol=1e-9, n_max=24, floor=6)
    assert np.all(n >= 6) and np.all(n <= 24)
    for o, mi, ni in zip(omega, m, n, strict=True):  # each sub-triangle's Gauss rule, on its ramp
        x, w = np.polynomial.legendre.leggauss(int(ni))
        sub = o / mi
        assert abs(np.exp(1j * sub * x) @ w - 2 * np.sin(sub) / sub) / 2 <= 1e-9
    # many periods on a face: the highest orders, about three points a period where
    # ten-point rules need five
    periods = omega[-1] / np.pi
    assert n[-1] >= 20 and 2.5 < (m * n)[-1] / periods < 4.0


def test_faces_many_periods_long_take_orders_past_24_and_keep_the_field():
    """At 12 GHz a 2.5 m face is a hundred wavelengths: the rule's highest orders follow the
    integrand with about two points a period, and the field is that of a rule held to 1e-13 per
    face on orders up to 24 (a different set of points), with two fifths fewer samples."""
    rng = np.random.default_rng(11)
    dish = paraboloid(D, F, FACE)
    wave = po.Illumination.plane_wave(12e9, (0, 0, -1), (1, 0, 0))
    points = sphere_points((0, 0, F), 2.0, 60, rng)
    points = points[points[:, 2] < F + 1.0]
    targets = targets_around(points, (0.0, 0.0, F), wave.k_hat)
    rule = plan(dish, wave.wavelength, 1.5, targets)
    assert rule.orders[1].max() > 24
    omega = np.pi * rule.edge_length * integrand_rate(dish, targets) / wave.wavelength
    tight = FaceQuadrature(dish, rule.spacing, face_orders=integrand_orders(omega, tol=1e-13, n_max=24))
    assert rule.n_samples < 0.7 * tight.n_samples
    many = omega > 100.0  # faces of more than sixty periods: at most 2.5 points a period
    assert np.any(many) and np.all((rule.orders[0] * rule.orders[1])[many] < 2.5 * omega[many] / np.pi)
    reference = field(dish, wave, tight, points)
    assert relative_error(dish, wave, rule, points, reference) < 1e-9


def test_a_deformed_twin_gets_the_ideal_samples_and_a_big_tilt_more():
    """Eq. 8 (millimetres) keeps the ideal dish's samples, on the paper's dish and squeezed onto
    a 20 m one; half a metre of it tilts the surface by tenths and gets more."""
    paper = paraboloid(110.0, 33.0, 5.0)
    around = Targets((0.0, 0.0, 33.0), 10.0, (0.0, 0.0, -1.0))
    a, b = plan(paper, 0.1, 1.5, around), plan(paper.deformed(PaperDeformation(110.0, 33.0)), 0.1, 1.5, around)
    np.testing.assert_array_equal(a.orders, b.orders)
    dish = paraboloid(D, F, FACE)
    targets = Targets((0.0, 0.0, F), 2.0, (0.0, 0.0, -1.0))
    ideal = plan(dish, 0.1, 1.5, targets)
    np.testing.assert_array_equal(plan(dish.deformed(PaperDeformation(D, F)), 0.1, 1.5, targets).orders,
                                  ideal.orders)
    steep = dish.deformed(PaperDeformation(D, F, 200.0))  # half a metre: slopes of tenths
    assert plan(steep, 0.1, 1.5, targets).n_samples > ideal.n_samples


def test_narrow_bumps_of_a_tenth_of_a_millimetre_are_resolved():
    """Bumps 0.1 mm high and 0.1 m wide barely tilt the surface, but the rule must still
    resolve their width: a plan read on the ideal dish's orders alone left 4.5e-6 of the field
    (2.6 % of what the bumps change)."""
    rng = np.random.default_rng(7)
    dish = paraboloid(D, F, FACE)
    wave = po.Illumination.plane_wave(3e9, (0, 0, -1), (1, 0, 0))
    bumps = GaussianBumps(((3.1, -4.6, 1e-4, 0.1), (-5.0, 2.0, -1e-4, 0.1), (0.7, 0.3, 1e-4, 0.1)))
    bumped = dish.deformed(bumps)
    points = sphere_points((0, 0, F), 1.0, 80, rng)
    targets = targets_around(points, (0.0, 0.0, F), wave.k_hat)
    ideal, rule = plan(dish, wave.wavelength, 1.5, targets), plan(bumped, wave.wavelength, 1.5, targets)
    assert ideal.n_samples < rule.n_samples < 0.2 * plan(bumped, wave.wavelength, 1.5).n_samples
    reference = field(bumped, wave, plan(bumped, wave.wavelength, 3.0), points)
    change = reference - field(dish, wave, plan(dish, wave.wavelength, 3.0), points)
    E = field(bumped, wave, rule, points)
    assert relative_error(bumped, wave, rule, points, reference) < 1e-7
    assert np.sqrt(np.mean(np.abs(E - reference) ** 2) / np.mean(np.abs(change) ** 2)) < 1e-3
    on_ideal = FaceQuadrature(bumped, rule.spacing, face_orders=ideal.orders, face_spacing=ideal.spacings)
    assert relative_error(bumped, wave, on_ideal, points, reference) > 1e-6  # the bumps need it


def test_targets_reaching_the_dish_keep_the_uniform_rule():
    dish = paraboloid(D, F, FACE)
    wide = Targets((0.0, 0.0, F), 9.0, (0.0, 0.0, -1.0))  # the ball holds the vertex
    uniform = plan(dish, 0.1, 1.5)
    assert plan(dish, 0.1, 1.5, wide).n_samples >= uniform.n_samples * 0.99


def relative_error(dish, wave, quadrature, points, reference):
    E = field(dish, wave, quadrature, points)
    return np.sqrt(np.mean(np.abs(E - reference) ** 2) / np.mean(np.abs(reference) ** 2))


def test_a_small_target_ball_keeps_enough_points_on_each_face():
    """A ball of 0.3 m on 2.5 m faces: the rate is low, and the ramp's phase alone would leave
    three points a face (1e-5 of the field, from the amplitude's and the surface's own
    variation); the floor keeps the field within 1e-7 of a finer rule."""
    rng = np.random.default_rng(11)
    dish = paraboloid(D, F, FACE)
    wave = po.Illumination.plane_wave(1.5e9, (0, 0, -1), (1, 0, 0))
    points = sphere_points((0, 0, F), 0.3, 100, rng)
    thin = plan(dish, wave.wavelength, 1.5, targets_around(points, (0.0, 0.0, F), wave.k_hat))
    assert thin.n_samples < 0.2 * plan(dish, wave.wavelength, 1.5).n_samples
    reference = field(dish, wave, plan(dish, wave.wavelength, 3.0), points)
    assert relative_error(dish, wave, thin, points, reference) < 1e-7


def test_a_bump_between_the_corners_is_seen():
    """A 5 mm bump 0.15 m wide, a metre from any face corner or centroid: its slopes raise
    the tilt allowance, so the deformed dish is sampled closer than the ideal one, and its
    field stays within 1e-6 of a finer rule."""
    rng = np.random.default_rng(7)
    dish = paraboloid(D, F, FACE)
    wave = po.Illumination.plane_wave(1.5e9, (0, 0, -1), (1, 0, 0))
    bumped = dish.deformed(GaussianBumps(((3.10, -6.60, 5e-3, 0.15),)))
    corners = dish.vertices[:, :2]
    centroids = dish.vertices[dish.faces][..., :2].mean(axis=1)
    nearest = np.min(np.hypot(*(np.vstack([corners, centroids]) - (3.10, -6.60)).T))
    assert nearest > 0.9  # the bump lies between the points the rate itself is read at
    points = sphere_points((0, 0, F), 1.0, 100, rng)
    targets = targets_around(points, (0.0, 0.0, F), wave.k_hat)
    ideal, deformed = plan(dish, wave.wavelength, 1.5, targets), plan(bumped, wave.wavelength, 1.5, targets)
    assert deformed.n_samples > 1.3 * ideal.n_samples  # the rate about 1.2 times the ideal's
    reference = field(bumped, wave, plan(bumped, wave.wavelength, 3.0), points)
    assert relative_error(bumped, wave, deformed, points, reference) < 1e-6


def test_a_wave_far_off_the_axis_keeps_each_face_on_its_own_rule():
    """15 deg off the axis the integrand turns faster than the uniform rule follows on some
    faces; while the whole stays within the uniform rule's samples those faces keep their own
    rules, and the field is that of a rule held to 1e-13 per face (other points, 3.5e-12 apart),
    where the uniform rule on those eleven faces leaves 7.1e-7 of it."""
    rng = np.random.default_rng(13)
    dish = paraboloid(D, F, FACE)
    t = np.radians(15.0)
    wave = po.Illumination.plane_wave(1.5e9, (np.sin(t), 0.0, -np.cos(t)), (np.cos(t), 0.0, np.sin(t)))
    points = sphere_points((0, 0, F), 2.0, 80, rng)
    points = points[points[:, 2] < F + 1.0]
    targets = targets_around(points, (0.0, 0.0, F), wave.k_hat)
    rule, uniform = plan(dish, wave.wavelength, 1.5, targets), plan(dish, wave.wavelength, 1.5)
    assert rule.n_samples < uniform.n_samples
    (m, n), (m_u, n_u) = rule.orders, uniform.orders
    over = m * n > m_u * n_u
    assert np.any(over)
    capped = FaceQuadrature(dish, rule.spacing, face_orders=(np.where(over, m_u, m), np.where(over, n_u, n)))
    omega = np.pi * rule.edge_length * integrand_rate(dish, targets) / wave.wavelength
    tight = FaceQuadrature(dish, rule.spacing, face_orders=integrand_orders(omega, tol=1e-13, n_max=24))
    reference = field(dish, wave, tight, points)
    err = relative_error(dish, wave, rule, points, reference)
    assert err < 1e-9
    assert relative_error(dish, wave, capped, points, reference) > 1e-7  # measured 7.1e-7
