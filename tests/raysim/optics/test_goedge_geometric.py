"""The geometric wave of the go+edge engine (raysim.optics.geowave) against independent references.

- the ideal paraboloid: the analytic GO field on the sphere, |E| = rho / R (docs/physics.md), the
  polarisation mirrored in the normal, the phase -k (F - R) (every ray's path), times the
  Green's function's near-field factor a(k s), s = rho - R;
- a deformed dish: the intensity against the GO engine's own cell means (raysim.optics.go,
  power deposited by overlap area: a second method written separately), and the phase change
  against the first-order path change, k (1 + cos theta) delta at the ray's aperture radius;
- the tie rule of the point-in-tube test and the caustic count, on hand-made tubes.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.maps.sphere import SphereGrid, aperture_radius
from raysim.optics import runtime
from raysim.optics.geowave import trace_wave
from raysim.optics.illumination import Illumination
from raysim.surface.deformation import PaperDeformation
from raysim.surface.mesh import paraboloid

D, F, R = 10.0, 3.0, 0.9
GRID = SphereGrid(R, 30, 12, 0.0, np.radians(75.0), 0.0, np.pi)
WAVE = Illumination.plane_wave(3e9, (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))


def analytic_go(grid: SphereGrid, k: float) -> np.ndarray:
    """The ideal paraboloid's reflected field at the cell centres (n_theta, n_phi, 3)."""
    theta, phi = np.meshgrid(grid.theta, grid.phi, indexing="ij")
    r = aperture_radius(theta, F)
    n = np.stack([-r * np.cos(phi) / (2 * F), -r * np.sin(phi) / (2 * F), np.ones_like(r)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    e = np.array([1.0, 0.0, 0.0])
    polar = -e + 2.0 * (n @ e)[..., None] * n
    rho = F + r * r / (4 * F)
    u = 1.0 / (k * (rho - R))
    a = 1.0 - 1j * u - u * u
    return ((rho / R) * a * np.exp(-1j * k * (F - R)))[..., None] * polar


@pytest.fixture(scope="module")
def dish():
    return paraboloid(D, F, 0.5)


def test_ideal_paraboloid_matches_the_analytic_field(dish):
    wave = trace_wave(dish, (0, 0, F), R, WAVE, subdivisions=10)
    E = wave.field(GRID.points(F).reshape(-1, 3)).reshape(GRID.n_theta, GRID.n_phi, 3)
    exact = analytic_go(GRID, WAVE.k)
    # the near-field longitudinal part (order 1 / (k s)) aside, the transverse field agrees
    d = -GRID.directions()
    transverse = E - np.sum(E * d, axis=-1, keepdims=True) * d
    err = np.linalg.norm(transverse - exact, axis=-1) / np.linalg.norm(exact, axis=-1)
    # the ray amplitudes are 1-ring means of the tubes' divergence: first order at irregular rings
    assert np.sqrt(np.mean(err**2)) < 5e-4 and err.max() < 3e-3, (np.sqrt(np.mean(err**2)), err.max())
    phase = np.angle(np.sum(np.conj(exact) * transverse, axis=-1))
    assert np.abs(phase).max() < 1e-5  # the path: exact on every ray, F - R
    assert np.abs(np.sum(E * d, axis=-1)).max() < 3.0 / (WAVE.k * (F - R)) * np.abs(exact).max()


def test_deformed_intensity_matches_the_go_engine(dish):
    """|E|^2 against the GO engine's cell means on the same mesh: FA = I0 / I - 1 to 3 % of FA."""
    from raysim.optics import go

    delta = PaperDeformation(D, F, 0.1)
    deformed = dish.deformed(delta)
    grid = SphereGrid(R, 75, 6, 0.0, np.radians(75.0), 0.0, np.pi)  # 1 deg: mean ~ centre
    points = grid.points(F).reshape(-1, 3)
    I = {}
    for name, refl in (("ideal", dish), ("deformed", deformed)):
        E = trace_wave(refl, (0, 0, F), R, WAVE, subdivisions=12).field(points)
        I[name] = np.sum(np.abs(E) ** 2, axis=-1).reshape(grid.n_theta, grid.n_phi)
    I_go = {name: go.trace(refl, grid, subdivisions=24).intensity
            for name, refl in (("ideal", dish), ("deformed", deformed))}
    # off the pole, where both engines' tubes come from the mesh's central fan (a few cm across)
    away = grid.theta >= np.radians(2.0)
    fa = (I["ideal"] / I["deformed"] - 1)[away]
    fa_go = (I_go["ideal"] / I_go["deformed"] - 1)[away]
    rms = np.sqrt(np.mean(fa_go**2))
    assert rms > 1e-3  # the deformation is really seen
    assert np.sqrt(np.mean((fa - fa_go) ** 2)) < 0.03 * rms


def test_deformed_phase_is_the_path_change(dish):
    """A small delta shifts the phase by k (1 + cos theta) delta(r) (first order)."""
    delta = PaperDeformation(D, F, 0.1)  # 0.7 mm: second order far below
    points = GRID.points(F).reshape(-1, 3)
    E0 = trace_wave(dish, (0, 0, F), R, WAVE, subdivisions=10).field(points)[:, 0]
    E1 = trace_wave(dish.deformed(delta), (0, 0, F), R, WAVE, subdivisions=10).field(points)[:, 0]
    theta, phi = np.meshgrid(GRID.theta, GRID.phi, indexing="ij")
    r = aperture_radius(theta, F).ravel()
    expected = WAVE.k * (1.0 + np.cos(theta.ravel())) * delta(r * np.cos(phi.ravel()), r * np.sin(phi.ravel()))
    shift = np.angle(E1 / E0)
    assert np.abs(expected).max() > 0.02  # rad: a real signal
    assert np.abs(shift - expected).max() < 0.01 * np.abs(expected).max()


def test_blocks_give_the_same_bits(dish):
    wave = trace_wave(dish, (0, 0, F), R, WAVE, subdivisions=6)
    points = GRID.points(F).reshape(-1, 3)
    whole = wave.field(points)
    pick = np.random.default_rng(3).permutation(len(points))[:57]
    assert np.array_equal(wave.field(points[pick]), whole[pick])


# --- hand-made tubes: the kernel's tie rule and caustic count --------------------------------
def _gather(chart, tubes, queries):
    """Run the gather kernel on rays at ``chart`` (unit amplitude along x, zero path)."""
    from raysim.optics.geowave import bucket_tubes
    from raysim.optics.kernels import geowave as K
    from raysim.optics.kernels.radiation import cis_table

    wp = runtime.init()
    n = len(chart)
    tubes = np.asarray(tubes, dtype=np.int32)
    b = bucket_tubes(chart, tubes, np.ones(len(tubes), dtype=bool))
    zeros3 = wp.zeros(n, dtype=wp.vec3d)
    amp = np.zeros((n, 3))
    amp[:, 0] = 1.0
    E = wp.zeros((6, len(queries)), dtype=wp.float64)
    runtime.launch(K.geometric_field, len(queries), [
        wp.array(queries, dtype=wp.vec2d), wp.array(chart, dtype=wp.vec2d), wp.zeros(n, dtype=wp.float64), wp.array(np.full(n, 1e6), dtype=wp.float64),
        wp.array(amp, dtype=wp.vec3d), zeros3, wp.array(tubes, dtype=wp.vec3i),
        wp.zeros(len(tubes), dtype=wp.int32), wp.array(b.start, dtype=wp.int32),
        wp.array(b.tubes, dtype=wp.int32), wp.vec2d(*b.origin), float(b.inv_size), b.nx, b.ny, 1.0,
        wp.array(cis_table(), dtype=wp.vec2d), E], "cpu")
    return E.numpy()[0]


def test_points_on_shared_edges_and_vertices_count_once():
    """A fan of six tubes round a vertex and a square cut in two: on every shared edge and at
    every shared vertex exactly one tube holds the point (the field is 1, never 0 or 2)."""
    ang = np.arange(6) * np.pi / 3
    fan = np.vstack([[0.0, 0.0], np.column_stack([np.cos(ang), np.sin(ang)])])
    fan_tubes = [(0, 1 + i, 1 + (i + 1) % 6) for i in range(6)]
    q = [[0.0, 0.0]] + [[0.5 * np.cos(a), 0.5 * np.sin(a)] for a in ang]  # centre, spokes
    assert np.allclose(_gather(fan, fan_tubes, np.array(q)), 1.0, atol=1e-14)
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    q = np.array([[0.5, 0.5], [0.25, 0.25], [0.75, 0.75], [0.3, 0.6]])
    out = _gather(square, [(0, 1, 2), (0, 2, 3)], q)
    assert np.allclose(out, 1.0, atol=1e-14)
    # a fold: the second sheet lies over the first, and both add
    fold = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    assert np.allclose(_gather(fold, [(0, 1, 2), (1, 3, 2), (0, 2, 1)], np.array([[0.2, 0.3]])), 2.0)


@pytest.mark.parametrize(("focal", "expected"), [((1.0, 1.0), 2), ((1.0, 1e9), 1), ((5.0, 5.0), 0)])
def test_caustics_before_the_sphere(focal, expected):
    """Rays converging to focal lines at distances f1, f2 (m), sphere at 2 m: j per caustic."""
    from raysim.optics.kernels import geowave as K

    wp = runtime.init()
    h = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.1, 0.0]])
    f1, f2 = focal
    d = np.column_stack([-h[:, 0] / f1, -h[:, 1] / f2, np.ones(3)])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    q = h + 2.0 * d
    out = {name: wp.zeros(1, dtype=t) for name, t in (("p", wp.float64), ("a", wp.float64),
                                                     ("turns", wp.int32), ("valid", wp.int32))}
    runtime.launch(K.tube_geometry, 1, [
        wp.array(h, dtype=wp.vec3d), wp.array(q, dtype=wp.vec3d), wp.array(d, dtype=wp.vec3d),
        wp.array(np.full(3, 2.0), dtype=wp.float64), wp.array(np.ones(3, dtype=np.int32), dtype=wp.int32),
        wp.array(np.array([[0, 1, 2]], dtype=np.int32), dtype=wp.vec3i), wp.vec3d(0.0, 0.0, 1.0),
        out["p"], out["a"], out["turns"], out["valid"]], "cpu")
    assert int(out["turns"].numpy()[0]) == expected
    assert out["p"].numpy()[0] == pytest.approx(0.005)
