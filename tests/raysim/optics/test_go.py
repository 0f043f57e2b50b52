"""Geometric optics: analytic intensities, an independent trace, power balance, gaps, shadows."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

from raysim.errors import DeviceError
from raysim.maps.sphere import SphereGrid, ideal_go_cell_mean, theta_rim
from raysim.optics import go
from raysim.surface.deformation import Deformation
from raysim.surface.mesh import Reflector, panel_footprint, paraboloid
from raysim.surface.panels import PanelLayout
from tests.reference_go import cell_mean_intensity

D, F, R = 110.0, 33.0, 10.0


def ring_mean_from_preimage(grid: SphereGrid, r_of_theta, r_max: float) -> np.ndarray:
    """Exact cell means of an axisymmetric map aperture radius r -> sphere angle theta.

    Power through the band theta_a..theta_b is pi (r_b^2 - r_a^2) for a unit incident wave
    (aperture normal to the beam); the band's area is 2 pi R^2 (cos theta_a - cos theta_b).
    """
    e = grid.theta_edges
    r = np.array([min(r_of_theta(t), r_max) for t in e])
    return (r[1:] ** 2 - r[:-1] ** 2) / (2 * grid.radius**2 * (np.cos(e[:-1]) - np.cos(e[1:])))


def flat_plate(a: float, focus_height: float, h: float = 0.2) -> Reflector:
    """A horizontal disk of radius a at z = 0 (no smooth surface: hits on the facets)."""
    xy, faces = panel_footprint(PanelLayout((0.0, a), (1,), 0.0), 0, h)
    vertices = np.column_stack([xy, np.zeros(len(xy))])
    normals = np.tile([0.0, 0.0, 1.0], (len(xy), 1))
    return Reflector(vertices, faces, np.zeros(len(faces), dtype=np.int64), normals, focus_height, 2 * a)


def test_ideal_paraboloid_is_rho_over_R_squared():
    grid = SphereGrid(R, 90, 360)
    result = go.trace(paraboloid(D, F), grid)  # the default mesh resolution
    e = grid.theta_edges
    exact = ideal_go_cell_mean(e[:-1], e[1:], F, R, D)
    rows = e[1:] <= theta_rim(D, F) - np.radians(2.0)
    rel = result.intensity[rows] / exact[rows, None] - 1.0
    assert np.abs(rel).max() < 1e-3
    # beyond the rim image nothing arrives
    beyond = e[:-1] >= theta_rim(D, F)
    assert np.all(result.intensity[beyond] == 0.0)


def test_ideal_intensity_converges_with_mesh_refinement():
    grid = SphereGrid(R, 45, 90)
    e = grid.theta_edges
    exact = ideal_go_cell_mean(e[:-1], e[1:], F, R, D)
    rows = e[1:] <= theta_rim(D, F) - np.radians(2.0)
    errors = []
    for h in (1.2, 0.6, 0.3):
        I = go.trace(paraboloid(D, F, h), grid).intensity
        errors.append(np.sqrt(np.mean((I[rows] / exact[rows, None] - 1.0) ** 2)))
    # second order in the triangle size: halving h divides the error by about 4
    assert errors[0] / errors[1] > 3.0 and errors[1] / errors[2] > 3.0, errors


def test_flat_plate_on_axis_gives_cos_theta():
    # rays leave a horizontal plate straight up; on the sphere the flux density is cos(theta)
    # and the band theta_a..theta_b receives the rays from radii R sin(theta_a)..R sin(theta_b)
    grid = SphereGrid(R, 60, 72)
    a = 8.0
    # the plate's map is steep (d theta / dr = 1 / (R cos theta)), so its tubes must be small
    result = go.trace(flat_plate(a, focus_height=20.0, h=0.05), grid)
    exact = ring_mean_from_preimage(grid, lambda t: R * np.sin(t), a)
    inside = grid.theta_edges[1:] < np.arcsin(a / R) - 0.02
    assert np.abs(result.intensity[inside] / exact[inside, None] - 1).max() < 1e-3
    assert result.power_balance == pytest.approx(0.0, abs=1e-12)


class SphericalResidual(Deformation):
    """The sphere z = Rc - sqrt(Rc^2 - r^2) written as the paraboloid r^2/(4F) plus delta."""

    def __init__(self, Rc: float, F: float) -> None:
        self.Rc, self.F = Rc, F

    def __call__(self, x, y, panel=None):
        r2 = np.asarray(x) ** 2 + np.asarray(y) ** 2
        return self.Rc - np.sqrt(self.Rc**2 - r2) - r2 / (4 * self.F)

    def gradient(self, x, y, panel=None):
        x, y = np.asarray(x, float), np.asarray(y, float)
        g = 1 / np.sqrt(self.Rc**2 - x * x - y * y) - 1 / (2 * self.F)
        return g * x, g * y


def spherical_mirror_theta(r: float, Rc: float, F: float, R: float) -> float:
    """Where the ray reflected at aperture radius r by a spherical mirror (radius Rc, vertex at
    the origin) enters the sphere of radius R about (0, F): the polar angle from -z.

    In the meridional plane the normal at the hit is (-sin a, cos a), sin a = r / Rc, and the
    reflected direction is (-sin 2a, cos 2a).
    """
    alpha = np.arcsin(r / Rc)
    p = np.array([r, Rc - np.sqrt(Rc**2 - r**2) - F])
    d = np.array([-np.sin(2 * alpha), np.cos(2 * alpha)])
    b = p @ d
    s = -b - np.sqrt(b * b - (p @ p - R * R))
    q = p + s * d
    return float(np.arctan2(q[0], -q[1]))


def test_spherical_mirror_matches_its_exact_ray_map():
    Rc, a = 2 * F, 20.0
    grid = SphereGrid(R, 60, 36, theta_max=np.radians(60.0))
    mirror = paraboloid(2 * a, F, 0.2).deformed(SphericalResidual(Rc, F))
    result = go.trace(mirror, grid)
    t_max = spherical_mirror_theta(a, Rc, F, R)

    def r_of_theta(t: float) -> float:
        if t >= t_max:
            return a
        return brentq(lambda r: spherical_mirror_theta(r, Rc, F, R) - t, 0.0, a, xtol=1e-13)

    exact = ring_mean_from_preimage(grid, r_of_theta, a)
    inside = grid.theta_edges[1:] < t_max - 0.02
    assert inside.sum() > 20
    assert np.abs(result.intensity[inside] / exact[inside, None] - 1).max() < 1e-3


def test_flat_plate_off_axis_is_a_tilted_parallel_beam():
    # a wave arriving 20 deg off axis leaves the plate as a parallel beam along b, the incident
    # direction mirrored in the plate; it enters the sphere where u . b < 0 with flux |u . b|
    beta = np.radians(20.0)
    k_hat = np.array([-np.sin(beta), 0.0, -np.cos(beta)])
    b_hat = np.array([k_hat[0], k_hat[1], -k_hat[2]])
    a, H = 12.0, 20.0
    grid = SphereGrid(R, 40, 80)
    result = go.trace(flat_plate(a, focus_height=H, h=0.05), grid, direction=k_hat)
    # power intercepted: the plate's area projected on the wave front
    assert result.power_lit == pytest.approx(np.pi * a * a * np.cos(beta), rel=2e-4)
    # cell means of |u . b| by Gauss quadrature (sin(theta) area weight) over each cell
    x, w = np.polynomial.legendre.leggauss(4)
    te, pe = grid.theta_edges, grid.phi_edges
    t = 0.5 * (te[:-1] + te[1:])[:, None] + 0.5 * grid.dtheta * x[None, :]
    p = 0.5 * (pe[:-1] + pe[1:])[:, None] + 0.5 * grid.dphi * x[None, :]
    T, P = t[:, None, :, None], p[None, :, None, :]
    u = np.stack(np.broadcast_arrays(np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), -np.cos(T)), axis=-1)
    flux = u @ b_hat
    weight = w[:, None] * w[None, :] * np.sin(T)
    mean_flux = np.sum(np.abs(flux) * weight, axis=(2, 3)) / np.sum(weight, axis=(2, 3))
    # a cell counts where every quadrature point is entered by the beam and traces back to
    # the plate well inside its rim (away from the grazing line, where the map is singular)
    q = np.array([0.0, 0.0, H]) + R * u
    foot = q - (q[..., 2] / b_hat[2])[..., None] * b_hat
    lit = (np.hypot(foot[..., 0], foot[..., 1]) < a - 1.0) & (flux < -0.3)
    inside = lit.all(axis=(2, 3))
    assert inside.sum() > 1500
    assert np.abs(result.intensity[inside] / mean_flux[inside] - 1).max() < 1e-3


def test_tube_deposition_matches_exact_overlap_areas():
    # the kernel alone: random chart triangles (half of them covering the pole) spread over the
    # cells by their overlap areas, checked against shapely's polygon intersections
    import shapely

    from raysim.optics import runtime as warp_runtime
    from raysim.optics.kernels import go as K

    wp = warp_runtime.init()
    grid = SphereGrid(R, 20, 40)
    te, pe = grid.theta_edges, grid.phi_edges
    arc = np.linspace(0, 1, 400)

    def cell(i, j):
        ph = pe[j] + arc * grid.dphi
        ra, rb = 2 * np.sin(te[i] / 2), 2 * np.sin(te[i + 1] / 2)
        ring = [np.column_stack([rb * np.cos(ph), rb * np.sin(ph)]),
                np.column_stack([ra * np.cos(ph[::-1]), ra * np.sin(ph[::-1])])]
        return shapely.Polygon(np.vstack(ring))

    cells = [[cell(i, j) for j in range(grid.n_phi)] for i in range(grid.n_theta)]
    rng = np.random.default_rng(0)
    n = 40
    centres = np.where(np.arange(n)[:, None] % 2 == 0, rng.normal(0, 0.04, (n, 2)), rng.normal(0, 0.5, (n, 2)))
    tris = centres[:, None, :] + rng.normal(0, 0.06, (n, 3, 2))
    for tri in tris:
        power = deposit(wp, K, grid, tri, np.array([[0, 1, 2]], np.int32), np.ones(1))
        T = shapely.Polygon(tri)
        expected = np.array([[T.intersection(c).area for c in row] for row in cells]) / T.area
        # the cells' arcs are polygons of 400 chords: 3e-6 of a cell's radial extent
        assert np.abs(power - expected).max() < 1e-4


def deposit(wp, K, grid: SphereGrid, chart: np.ndarray, tubes: np.ndarray, power_t: np.ndarray,
            table: bool = True) -> np.ndarray:
    """``deposit_tubes`` alone (one thread): chart points (n, 2), tubes (m, 3), tube powers
    (m,); with ``table`` False its wedge table lies out of reach, so every wedge computes its
    own sides."""
    dev = "cpu"
    ch = wp.array(chart, dtype=wp.vec2d, device=dev)
    ok = wp.array(np.ones(len(chart), np.int32), dtype=wp.int32, device=dev)
    polar = wp.zeros(len(chart), dtype=wp.vec3d, device=dev)
    wp.launch(K.chart_polar, dim=len(chart), inputs=[ch, ok, polar, 0], device=dev)
    j_first, sides = go.wedge_table(grid, dev)
    if not table:
        j_first = 1 << 30
    power = wp.zeros((grid.n_theta, grid.n_phi), dtype=wp.float64, device=dev)
    wp.launch(K.deposit_tubes, dim=len(tubes), inputs=[
        ch, ok, wp.array(tubes, dtype=wp.vec3i, device=dev), wp.array(power_t, dtype=wp.float64, device=dev),
        polar, wp.array(2 * np.sin(grid.theta_edges / 2), dtype=wp.float64, device=dev), sides, j_first,
        grid.theta_min, grid.dtheta, grid.n_theta, grid.phi_min, grid.dphi, grid.n_phi,
        int(grid.full_circle), power, 0], device=dev)
    return power.numpy()


@pytest.mark.parametrize("grid", [SphereGrid(R, 30, 72), SphereGrid(R, 30, 72, phi_min=-np.pi, phi_max=np.pi),
                                  SphereGrid(R, 12, 16, phi_min=-0.4, phi_max=0.9)],
                         ids=["full circle", "full circle from -pi", "sector"])
def test_tube_deposition_is_the_same_with_and_without_the_wedge_table(grid):
    # the kernel takes the wedges' sides from a table made once per grid: the very numbers it
    # would compute itself, so the deposit is the same bit for bit (tubes across the pole,
    # across phi = +-pi and across many rings and wedges included)
    from raysim.optics import runtime as warp_runtime
    from raysim.optics.kernels import go as K

    wp = warp_runtime.init()
    rng = np.random.default_rng(3)
    n = 3000
    centres = rng.normal(0, 0.6, (n, 2))
    chart = (centres[:, None, :] + rng.normal(0, 0.05, (n, 3, 2)) * rng.uniform(0.1, 4, (n, 1, 1)))
    chart = chart.reshape(-1, 2)
    tubes = np.arange(3 * n, dtype=np.int32).reshape(n, 3)
    power_t = rng.uniform(0.5, 2.0, n)
    tabled = deposit(wp, K, grid, chart, tubes, power_t)
    assert tabled.sum() > 0.1 * power_t.sum()  # a fair share lands on the grid
    assert np.array_equal(tabled, deposit(wp, K, grid, chart, tubes, power_t, table=False))


def test_paper_case_ratio_matches_an_independent_trace(paper_scene, paper_reflectors):
    grid = paper_scene.sphere
    ideal, deformed = paper_reflectors
    I_ideal = go.trace(ideal, grid).intensity
    I_def = go.trace(deformed, grid).intensity
    ref_ideal = cell_mean_intensity(grid, F, D, None, order=2)
    ref_def = cell_mean_intensity(grid, F, D, paper_scene.deformation, order=2)
    rows = grid.theta_edges[1:] <= np.radians(78.0)
    FA = I_ideal[rows] / I_def[rows] - 1
    FA_ref = ref_ideal[rows] / ref_def[rows] - 1
    signal = np.sqrt(np.mean(FA_ref**2))
    assert 4e-3 < signal < 1e-2  # the paper's case: FA of a few 1e-3
    worst_per_theta = np.abs(FA - FA_ref).max(axis=1)
    assert worst_per_theta.max() < 0.02 * signal, worst_per_theta.max() / signal


def test_power_balance_ideal_and_with_gaps(panels_scene):
    grid = SphereGrid(R, 90, 360)
    layout = panels_scene.panels
    whole, panelled = (go.trace(paraboloid(D, F, 0.3, panels), grid) for panels in (None, layout))
    for result in (whole, panelled):
        # every lit tube's power reaches the sphere ...
        assert abs(result.power_balance) < 1e-6
        total = np.sum(result.intensity * grid.cell_area())
        assert total == pytest.approx(result.power_lit, rel=1e-6)
    # ... and the wave delivers the aperture's area, less the gaps' (up to the rim's chords)
    assert whole.power_lit == pytest.approx(np.pi * (D / 2) ** 2, rel=2e-5)
    assert panelled.power_lit == pytest.approx(np.pi * (D / 2) ** 2 - layout.gap_area(), rel=2e-5)


def predicted_gap_fraction(grid: SphereGrid, layout: PanelLayout) -> np.ndarray:
    """Fraction of each cell's aperture preimage in the gaps, from the gaps' geometry alone.

    The ideal mapping r = 2F tan(theta/2) takes a cell to the annular sector ra..rb,
    phi_a..phi_b. The ring gaps (width g about each inner ring edge) cover whole arcs of it;
    a radial gap about the cut at angle psi covers |phi - psi| < asin(g / 2r) at radius r,
    integrated over r by Gauss quadrature. (Where two gaps cross, g^2 is counted twice.)
    """
    g = layout.gap
    e, pe = grid.theta_edges, grid.phi_edges
    ra, rb = 2 * F * np.tan(e[:-1] / 2), 2 * F * np.tan(e[1:] / 2)
    gap = np.zeros((grid.n_theta, grid.n_phi))
    for i in range(grid.n_theta):
        for edge in layout.ring_edges[1:-1]:
            lo, hi = max(ra[i], edge - g / 2), min(rb[i], edge + g / 2)
            if hi > lo:
                gap[i] += 0.5 * grid.dphi * (hi * hi - lo * lo)
        for ring in range(layout.n_rings):
            n = layout.panels_per_ring[ring]
            lo, hi = max(ra[i], layout.ring_edges[ring]), min(rb[i], layout.ring_edges[ring + 1])
            if n == 1 or hi <= lo:
                continue
            x, w = np.polynomial.legendre.leggauss(64)
            r = 0.5 * (hi + lo) + 0.5 * (hi - lo) * x
            half = np.arcsin(np.minimum(g / (2 * r), 1.0))
            for psi in layout.phi0 + 2 * np.pi * np.arange(n) / n:
                # the cut's angle nearest to each cell, unwrapped; covered angle per radius
                c = pe[:-1] + np.mod(psi - pe[:-1] + np.pi, 2 * np.pi) - np.pi
                a0 = np.maximum(c[:, None] - half[None, :], pe[:-1, None])
                a1 = np.minimum(c[:, None] + half[None, :], pe[1:, None])
                covered = np.maximum(a1 - a0, 0.0)
                gap[i] += 0.5 * (hi - lo) * covered @ (w * r)
    sector = 0.5 * grid.dphi * (rb**2 - ra**2)
    return gap / sector[:, None]


def test_panel_gaps_are_dark_where_the_ideal_mapping_puts_them(panels_scene):
    layout = panels_scene.panels
    grid = SphereGrid(R, 45, 180)
    whole = go.trace(paraboloid(D, F, 0.3), grid).intensity
    panelled = go.trace(paraboloid(D, F, 0.3, layout), grid).intensity
    rows = grid.theta_edges[1:] <= theta_rim(D, F) - np.radians(1.0)
    dark = 1 - panelled[rows] / whole[rows]
    expected = predicted_gap_fraction(grid, layout)[rows]
    # the dark lines are where the gaps' images fall, cell by cell ...
    crossed = expected > 0
    assert crossed.mean() > 0.2 and np.all(np.abs(dark[~crossed]) < 1e-3)
    assert np.abs(dark - expected).max() < 0.1 * expected.max()
    # ... and over the whole sphere the power missing is the gaps' share of the aperture
    area = grid.cell_area()
    missing = np.sum((whole - panelled) * area) / np.sum(whole * area)
    assert missing == pytest.approx(layout.gap_area() / (np.pi * (D / 2) ** 2), rel=2e-3)


def test_panels_scene_ratio_is_finite_where_both_are_lit(panels_scene):
    from dataclasses import replace

    from raysim.surface.mesh import reflectors_for

    small = panels_scene.with_overrides(n_theta=45, n_phi=180)
    small = replace(small, dish=replace(small.dish, resolution=0.3))
    ideal, deformed = reflectors_for(small)
    I0 = go.trace(ideal, small.sphere).intensity
    I1 = go.trace(deformed, small.sphere).intensity
    both = (I0 > 0) & (I1 > 0)
    ratio = I0[both] / I1[both] - 1
    assert both.mean() > 0.85 and np.all(np.isfinite(ratio))
    # 50 um panel errors: a few percent at most away from the gap images
    assert np.median(np.abs(ratio)) < 0.02


def test_shadowed_rays_carry_no_power():
    # a small plate 2 m above a larger one hides the lower plate's centre from the wave
    lower = flat_plate(8.0, 20.0, 0.25)
    upper_xy, upper_faces = panel_footprint(PanelLayout((0.0, 3.1), (1,), 0.0), 0, 0.25)
    vertices = np.vstack([lower.vertices, np.column_stack([upper_xy, np.full(len(upper_xy), 2.0)])])
    faces = np.vstack([lower.faces, upper_faces + len(lower.vertices)])
    panel = np.concatenate([np.zeros(len(lower.faces), int), np.ones(len(upper_faces), int)])
    both = Reflector(vertices, faces, panel, np.tile([0.0, 0.0, 1.0], (len(vertices), 1)), 20.0, 16.0)
    result = go.trace(both, SphereGrid(R, 60, 72))
    # the upper plate (a 3.1 m polygon of chords) hides the lower vertices under it
    r = np.hypot(lower.vertices[:, 0], lower.vertices[:, 1])
    hidden = r < 3.1 * np.cos(np.pi / len(upper_xy[np.isclose(np.hypot(*upper_xy.T), 3.1)]))
    assert result.n_shadowed == hidden.sum()
    # lit power from the geometry alone: the upper plate catches what it hides, so the wave
    # delivers the lower plate's disk, less the faces straddling the shadow's edge (their
    # corners are hidden, so they are dark): at most one ring of faces of size h = 0.25 m
    disk = np.pi * 8.0**2
    assert disk - 2 * np.pi * 3.1 * 0.25 < result.power_lit < disk * (1 - 1e-4)
    assert abs(result.power_balance) < 1e-9


def test_threads_do_not_change_the_result_by_a_bit(monkeypatch):
    # the tubes' power is summed per slice and the slices in order, whatever the threads: a
    # dataset resumed with other --threads must be bit-identical (it differed by 1e-14 when the
    # slices followed the threads)
    grid = SphereGrid(R, 45, 90)
    mesh = paraboloid(D, F, 0.6)
    results = []
    for threads in ("1", "2", "3"):
        monkeypatch.setenv("RAYSIM_THREADS", threads)
        results.append(go.trace(mesh, grid).intensity)
    assert all(np.array_equal(results[0], other) for other in results[1:])


def test_cuda_without_a_gpu_is_one_clear_error():
    from raysim.optics.runtime import init

    if init().is_cuda_available():
        pytest.skip("a GPU is present: the CUDA path is checked by the device runs instead")
    with pytest.raises(DeviceError, match="no CUDA GPU"):
        go.trace(paraboloid(D, F, 2.0), SphereGrid(R, 9, 36), device="cuda")


def test_a_tube_with_the_pole_on_its_edge_keeps_its_power():
    """Coma moves the vertex's image a few micrometres off the pole along x, onto the image of
    a radial panel edge (six panels in the first ring: an edge at phi = 180 deg): a tube whose
    image has the pole on an edge to rounding took the wrong half turn of azimuths and lost its
    power (power balance -2.3e-5 here, one bad cluster of cells at the pole)."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate

    scene = parse_scene("""
name = "pole_on_an_edge"
[dish]
diameter_m = 110.0
focal_length_m = 33.0
resolution_m = 1.0
[panels]
ring_edges_m = [0.0, 13.75, 27.5, 41.25, 55.0]
panels_per_ring = [6, 12, 18, 24]
gap_m = 0.0
[[deformation]]
type = "zernike"
terms = [[2, 2, 60.0], [3, 1, 20.0]]
[source]
frequency_hz = 0.3e9
[sphere]
radius_m = 10.0
n_theta = 20
n_phi = 40
""")
    field = simulate(scene, "go")
    assert field.attrs["power_balance"] == pytest.approx(0.0, abs=1e-12)


def _small_dish_field(n_theta: int, n_phi: int, phi_deg: tuple[float, float]):
    """GO intensity (cell means) of a small ideal dish, seen on cells of the given phi range."""
    from raysim.scene.scene import parse_scene
    from raysim.simulate import simulate

    return simulate(parse_scene(f"""
[dish]
diameter_m = 10.0
focal_length_m = 4.0
resolution_m = 1.25
[source]
frequency_hz = 1e9
[sphere]
radius_m = 2.0
n_theta = {n_theta}
n_phi = {n_phi}
phi_min_deg = {phi_deg[0]}
phi_max_deg = {phi_deg[1]}
"""), "go")


@pytest.mark.parametrize("phi_deg", [(90.0, 270.0), (-150.0, 0.0), (300.0, 420.0)])
def test_a_partial_grid_holds_the_whole_grids_cells(phi_deg):
    """A grid over part of the turn is the whole turn's cells over that part, whichever way the
    range is written. Tubes were not taken round the turn: on 90..270 deg those with an atan2
    azimuth below -90 deg were dropped (29 % of the power on the grid for 50 %), and a tube
    crossing 180 deg or next to the pole could be placed a turn away from a grid inside
    (-180, 180]."""
    whole = _small_dish_field(12, 24, (0.0, 360.0))
    part = _small_dish_field(12, round((phi_deg[1] - phi_deg[0]) / 15.0), phi_deg)
    first = round((phi_deg[0] % 360.0) / 15.0)
    columns = [(first + j) % 24 for j in range(part.sizes["phi"])]
    expected = whole.intensity_ideal.values[:, columns]
    np.testing.assert_allclose(part.intensity_ideal.values, expected, rtol=1e-10, atol=1e-12 * expected.max())


def test_one_cell_in_phi_holds_the_whole_rings_power():
    """n_phi = 1: over the whole turn a tube crossing phi_min was deposited twice (power balance
    +5.9e-2), and over part of the turn no tube was clipped to the cell (a 90 deg cell got 38 %
    of the power for 25 %)."""
    whole = _small_dish_field(12, 24, (0.0, 360.0))
    ring = _small_dish_field(12, 1, (0.0, 360.0))
    assert ring.attrs["power_balance_ideal"] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(ring.intensity_ideal.values[:, 0], whole.intensity_ideal.values.mean(axis=1),
                               rtol=1e-10)
    quarter = _small_dish_field(12, 1, (0.0, 90.0))
    np.testing.assert_allclose(quarter.intensity_ideal.values[:, 0],
                               whole.intensity_ideal.values[:, :6].mean(axis=1), rtol=1e-10)


def test_a_whole_turn_from_a_phi_min_with_decimals_is_the_whole_turn():
    """phi_max_deg = phi_min_deg + 360 computed elsewhere can exceed the span by an ulp; it was
    refused as "must lie in (0, 360]". It is the whole turn: every tube lands on the grid."""
    p0 = -131.551
    turned = _small_dish_field(6, 24, (p0, p0 + 360.0 * (1.0 + 1e-13)))
    assert turned.attrs["power_balance_ideal"] == pytest.approx(0.0, abs=1e-12)
