"""The fast (multilevel) radiator against the direct sum (issue 31).

A scaled dish (D 10 m, F 3.3 m) at 1 GHz (about 33 wavelengths across) radiating to a sphere of
1 m about the focus: the quadtree has five levels. The cost estimate picks the leaves as the
stop level there, so :func:`test_every_step_of_the_tree` sets the leaf and stop levels by hand
(and a small chunk size) to run aggregation, the tree walked a few clusters at a time and both last
steps. The reference is the direct sum
(:class:`raysim.optics.radiator.Radiator`), an independent implementation of the same sum.
"""

from __future__ import annotations

import numpy as np
import pytest

from raysim.errors import RaysimError
from raysim.maps.sphere import SphereGrid
from raysim.optics.fast.chart import Domain, domain_of, grid_points, half_rows, mirror, resample
from raysim.optics.fast.radiator import FastRadiator, make_radiator
from raysim.optics.radiator import Radiator, _kinds

D, F, R = 10.0, 3.3, 1.0
K = 2 * np.pi * 1e9 / 299792458.0
CENTRE = (0.0, 0.0, F)


def _dish_positions(spacing: float) -> np.ndarray:
    x = np.arange(-D / 2, D / 2, spacing)
    X, Y = np.meshgrid(x, x)
    inside = X**2 + Y**2 < (D / 2) ** 2
    X, Y = X[inside], Y[inside]
    return np.column_stack([X, Y, (X**2 + Y**2) / (4 * F)])


def _elements(kind: str, seed: int = 1) -> np.ndarray:
    """Elements of ``kind`` on the dish: a focused (phase from the focus) smooth moment for the
    dipole rows, random smooth values in every other row."""
    rows = _kinds()[kind].rows
    pos = _dish_positions(np.pi / K)  # half a wavelength apart
    if kind in ("fringe", "diffraction"):  # edge elements: on the rim
        a = np.linspace(0, 2 * np.pi, 400, endpoint=False)
        pos = np.column_stack([D / 2 * np.cos(a), D / 2 * np.sin(a), np.full_like(a, D**2 / (16 * F))])
    rng = np.random.default_rng(seed)
    phase = np.exp(-1j * K * np.linalg.norm(pos - np.array(CENTRE), axis=1))
    src = rng.normal(size=(rows, len(pos))) * 0.1
    src[:3] = pos.T
    src[3:6] = np.outer([1.0, 0.3, 0.1], phase.real) * (1 + 0.1 * src[3:6])
    src[6:9] = np.outer([1.0, 0.3, 0.1], phase.imag) * (1 + 0.1 * src[6:9])
    return np.ascontiguousarray(src)


def _grid_points(n_theta: int = 24, n_phi: int = 48) -> np.ndarray:
    return SphereGrid(R, n_theta, n_phi).points(F).reshape(-1, 3)


def _scan_points(n: int = 500, seed: int = 2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    theta, phi = np.arccos(rng.uniform(0.0, 1.0, n)), rng.uniform(0, 2 * np.pi, n)
    dirs = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)])
    return np.array(CENTRE) + R * dirs


def _direct(points: np.ndarray, src: np.ndarray, kind: str) -> np.ndarray:
    r = Radiator(points, K)
    r.add_packed(src, kind)
    return r.sums_of(kind)


def _fast(points: np.ndarray, src: np.ndarray, kind: str, tol: float, **kw) -> tuple[np.ndarray, str]:
    r = FastRadiator(points, K, tol=tol, centre=CENTRE, force=True, **kw)
    r.add_packed(src, kind)
    return r.sums_of(kind), r.method[kind]


def _rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.sum((a - b) ** 2) / np.sum(b**2)))


@pytest.mark.parametrize("kind", ["electric", "magnetic", "fringe", "shift"])
def test_every_kind_within_tolerance(kind: str) -> None:
    pts = _grid_points()
    src = _elements(kind)
    ref = _direct(pts, src, kind)
    assert np.all(np.isfinite(ref))
    out, method = _fast(pts, src, kind, 1e-6)
    assert method.startswith("fast")
    assert _rel_rms(out, ref) < 1e-6


@pytest.mark.parametrize("tol", [1e-3, 1e-6])
def test_a_sphere_near_the_dish_within_tolerance(tol: float) -> None:
    """The sphere's radius 0.6 F: the vertex's sources lie 1.7 R from its centre, so their
    amplitude (1/r and the near-field terms) has harmonics falling only as 0.6^l on it. Grids
    sized by the phase and a floor of d harmonics missed 1e-6 by 24 times here (and by 40 times
    through simulate, three samples per wavelength, in a QA run)."""
    pts = SphereGrid(0.6 * F, 24, 48).points(F).reshape(-1, 3)
    src = _elements("electric")
    r = Radiator(pts, K)
    r.add_packed(src, "electric")
    ref = r.sums_of("electric")
    fast = FastRadiator(pts, K, tol=tol, centre=CENTRE, force=True)
    fast.add_packed(src, "electric")
    out = fast.sums_of("electric")
    assert fast.method["electric"].startswith("fast")
    assert _rel_rms(out, ref) < tol


def test_error_shrinks_with_tolerance_on_scan_points() -> None:
    pts = _scan_points()
    src = _elements("electric")
    ref = _direct(pts, src, "electric")
    errors = [_rel_rms(_fast(pts, src, "electric", tol)[0], ref) for tol in (1e-2, 1e-4, 1e-7)]
    assert errors[0] < 1e-2 and errors[1] < 1e-4 and errors[2] < 1e-7
    assert errors[2] < errors[1] < errors[0]


def test_elements_added_in_pieces_give_the_same_bits() -> None:
    """Elements added in three pieces sum to the bits of the same elements added at once, and
    the radiator then holds them as one array (in leaf order) instead of the pieces."""
    pts = _grid_points()
    src = _elements("electric")
    whole, _ = _fast(pts, src, "electric", 1e-6)
    r = FastRadiator(pts, K, tol=1e-6, centre=CENTRE, force=True)
    for part in np.array_split(src, 3, axis=1):
        r.add_packed(part, "electric")
    assert np.array_equal(r.sums_of("electric"), whole)
    assert len(r.sources["electric"]) == 1 and r.sources["electric"][0].shape == src.shape


@pytest.mark.parametrize("lift_m, shared", [(3e-3, True), (0.6, False)])
def test_a_moved_copy_reuses_the_tree_while_its_grids_hold_it(lift_m: float, shared: bool) -> None:
    """The deformed reflector of one triangulation sums on the ideal one's tree: a smooth bump
    of 3 mm (a hundredth of a wavelength) keeps it, a lift of 0.6 m at the rim (two
    wavelengths; the rim's clusters grow past their grids) plans its own. Either way the field
    agrees with the direct sum to the tolerance."""
    pts = _grid_points()
    src = _elements("electric")
    plans: dict = {}
    first = FastRadiator(pts, K, tol=1e-6, centre=CENTRE, force=True, plans=plans)
    first.add_packed(src, "electric")
    first.sums_of("electric")
    (tree,) = plans.values()
    moved = src.copy()
    r2 = (moved[0] ** 2 + moved[1] ** 2) / (D / 2) ** 2
    moved[2] += lift_m * r2 ** 2 * (1 + 0.5 * np.cos(3 * np.arctan2(moved[1], moved[0])))
    second = FastRadiator(pts, K, tol=1e-6, centre=CENTRE, force=True, plans=plans)
    second.add_packed(moved, "electric")
    out = second.sums_of("electric")
    assert (second.leaf_order["electric"] is tree) == shared
    assert _rel_rms(out, _direct(pts, moved, "electric")) < 1e-6


def test_prepared_copies_sum_at_once_on_the_first_ones_tree_with_the_same_bits() -> None:
    """simulate's two reflectors: each radiator is prepared (its tree planned and shared) in a
    fixed order, then both sum on two threads at once. The second sums on the first one's
    tree, and every bit of both sums is what summing them one after the other gives."""
    from concurrent.futures import ThreadPoolExecutor

    pts = _grid_points()
    src = _elements("electric")
    moved = src.copy()
    moved[2] += 3e-3 * np.cos(moved[0])

    def prepared(plans: dict) -> list[FastRadiator]:
        out = []
        for elements in (src, moved):
            r = FastRadiator(pts, K, tol=1e-6, centre=CENTRE, force=True, plans=plans)
            r.add_packed(elements, "electric")
            r.prepare()
            out.append(r)
        return out

    plans: dict = {}
    first, second = prepared(plans)
    (tree,) = plans.values()
    assert first.planned["electric"] is tree and second.planned["electric"] is tree
    with ThreadPoolExecutor(max_workers=2) as pool:
        together = list(pool.map(lambda r: r.sums_of("electric"), (first, second)))
    apart = [r.sums_of("electric") for r in prepared({})]
    assert all(np.array_equal(a, b) for a, b in zip(together, apart, strict=True))
    assert _rel_rms(together[1], _direct(pts, moved, "electric")) < 1e-6


def test_batches_hold_a_batch_of_elements_and_sum_within_tolerance() -> None:
    """Elements added in four strips of the dish, with room kept for two strips: the radiator
    sums the first two as a batch on their own tree as soon as they are in and lets them go,
    then the last two; the batches' sums added agree with the direct sum to the tolerance, on
    the grid and on a block of it (the same bits as the whole grid's), and a moved copy sums
    each batch on the first copy's tree of that batch."""
    pts = _grid_points()
    src = _elements("electric")
    parts = np.array_split(src, 4, axis=1)
    room = parts[2].nbytes + parts[3].nbytes  # the last two strips are the smaller
    domain = domain_of(pts, CENTRE)
    plans: dict = {}

    def batched(points: np.ndarray, pieces: list[np.ndarray]) -> FastRadiator:
        r = FastRadiator(points, K, tol=1e-6, centre=CENTRE, force=True, domain=domain, plans=plans,
                         batch_bytes=room)
        for i, part in enumerate(pieces):
            r.add_packed(part, "electric")
            assert len(r.sources["electric"]) == (0 if i in (1, 3) else 1)  # a batch let go
        return r

    whole = batched(pts, parts)
    out = whole.sums_of("electric")
    assert whole.batches["electric"] == 2 and whole.method["electric"].endswith(", 2 batches")
    assert _rel_rms(out, _direct(pts, src, "electric")) < 1e-6
    assert len(plans) == 2  # a tree per batch
    block = batched(pts[100:333], parts).sums_of("electric")
    assert np.array_equal(block, out[100:333])
    moved = [part.copy() for part in parts]
    for part in moved:
        part[2] += 1e-3 * np.cos(part[0])  # a millimetre ripple: every batch's tree still holds
    trees = dict(plans)
    second = batched(pts, moved)
    assert _rel_rms(second.sums_of("electric"), _direct(pts, np.concatenate(moved, axis=1), "electric")) < 1e-6
    assert plans.keys() == trees.keys() and all(plans[key] is trees[key] for key in trees)


@pytest.mark.parametrize("stop_chunks", [1, 3])
def test_a_block_of_points_gives_the_same_bits(stop_chunks: int, monkeypatch) -> None:
    """A block of the grid's points gets the whole grid's bits, with the stop level's grids in
    one chunk (kept between blocks) or in several (summed again per block)."""
    from raysim.optics.fast import multilevel

    pts = _grid_points()
    src = _elements("electric")
    domain = domain_of(pts, CENTRE)
    if stop_chunks > 1:
        plan = multilevel.plan([src], domain, K, 1e-6 / 8, ((0, 0),))
        clusters = len(plan.levels[plan.stop].keys)
        monkeypatch.setattr(multilevel, "GRID_BYTES", 48 * plan.sizes[plan.stop] ** 2 * -(-clusters // 3))
        assert len(plan.stop_chunks()) == 3
    whole, _ = _fast(pts, src, "electric", 1e-6, domain=domain)
    block, _ = _fast(pts[100:333], src, "electric", 1e-6, domain=domain)
    assert np.array_equal(block, whole[100:333])


def _leaves_at_4(plan, domain):
    """``plan`` with its leaves at level 4, each on a grid of its own size, whichever level the
    cost estimate prefers."""
    from dataclasses import replace

    from raysim.optics.fast import multilevel

    leaves = plan.levels[4]
    return replace(plan, leaf=4, leaf_sizes=multilevel._sizes(leaves.centres, leaves.radii, domain, K,
                                                              plan.digits))


def _planned(pts: np.ndarray, src: np.ndarray, kind: str, stop: int, last=(0, 0)) -> np.ndarray:
    """The multilevel sum with the plan's stop level set by hand (whatever the cost estimate
    prefers), so that every step runs: leaves, aggregation, and the last step (``last``: (0, 0)
    the series on the tensor grid, else (oversampling, p) for the refined-grid Lagrange step)."""
    from dataclasses import replace

    from raysim.optics.fast import multilevel
    from raysim.optics.fast.chart import to_angles
    from raysim.optics.fast.radiator import _segments

    domain = domain_of(pts, CENTRE)
    plan = _leaves_at_4(multilevel.plan([src], domain, K, 1e-6 / 8, (last,)), domain)
    plan = replace(plan, stop=stop, oversampling=last[0], p=last[1])

    def grids():
        return multilevel.stop_grids(_segments(kind), multilevel.leaf_ordered([src], plan), plan, domain, K, "cpu")

    return multilevel.to_targets(grids, plan, to_angles(pts, CENTRE), pts, K, "cpu", domain)


@pytest.mark.parametrize("stop, last", [(2, (0, 0)), (3, (6, 10))])
def test_every_step_of_the_tree(stop: int, last: tuple[int, int], monkeypatch) -> None:
    """Aggregation from the leaves (level 4) up to level ``stop``, on the tensor grid or by
    the general last step, within the tolerance of the direct sum; and the same sum walked a
    few clusters at a time at every level (a chunk size of a few grids: several chunks of the
    stop level, as at 6 GHz on the paper's dish) agrees with it to rounding."""
    from dataclasses import replace

    from raysim.optics.fast import multilevel

    pts = _grid_points()
    src = _elements("magnetic")
    plan = _leaves_at_4(multilevel.plan([src], domain_of(pts, CENTRE), K, 1e-6 / 8, (last,)), domain_of(pts, CENTRE))
    assert len(np.unique(plan.leaf_sizes)) > 1  # each leaf aggregated from a grid of its own size
    whole = _planned(pts, src, "magnetic", stop, last)
    assert _rel_rms(whole, _direct(pts, src, "magnetic")) < 1e-6
    monkeypatch.setattr(multilevel, "CHUNK_BYTES", 2e5)
    monkeypatch.setattr(multilevel, "GRID_BYTES", 3 * 48 * plan.sizes[stop] ** 2)  # three stop grids
    assert len(replace(plan, stop=stop).stop_chunks()) > 1
    chunked = _planned(pts, src, "magnetic", stop, last)
    assert np.max(np.abs(chunked - whole)) <= 1e-12 * np.max(np.abs(whole))


def test_targets_anywhere_on_the_sphere() -> None:
    """The spectral grids cover the whole sphere: a grid reaching theta = 180 deg (far side of
    the focus) and scattered points over the whole sphere both take the multilevel sum."""
    src = _elements("electric")
    whole = SphereGrid(R, 18, 36, theta_max=np.pi).points(F).reshape(-1, 3)
    rng = np.random.default_rng(5)
    theta, phi = np.arccos(rng.uniform(-1.0, 1.0, 400)), rng.uniform(0, 2 * np.pi, 400)
    scattered = np.array(CENTRE) + R * np.column_stack(
        [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)])
    for pts in (whole, scattered):
        out, method = _fast(pts, src, "electric", 1e-6)
        assert method.startswith("fast")
        assert _rel_rms(out, _direct(pts, src, "electric")) < 1e-6


def test_spectral_grid_refines_a_plane_wave_to_rounding() -> None:
    """A plane wave exp(j k0 . P) on the sphere is band-limited in effect (its spherical-harmonic
    coefficients fall off super-exponentially beyond degree |k0| R = 5.4): computing the rows
    theta <= pi and mirroring the rest reproduces the analytic grid, and the zero-padded
    spectrum gives the analytic wave on a finer grid with an error that falls fast with n, to
    rounding at n = 48."""
    domain = Domain(CENTRE, R, 1)
    k0 = np.array([3.0, -2.0, 4.0])
    m = 96

    def wave(points: np.ndarray) -> np.ndarray:
        return np.exp(1j * (points - np.array(CENTRE)) @ k0)

    errors = []
    for n in (32, 40, 48):
        half = wave(grid_points(n, domain, half_rows(n))).reshape(1, half_rows(n), n, 1)
        full = mirror(half, n)
        assert np.allclose(full.reshape(-1), wave(grid_points(n, domain)), rtol=0, atol=1e-14)
        errors.append(np.max(np.abs(resample(full, m).reshape(-1) - wave(grid_points(m, domain)))))
    assert errors[0] > 100 * errors[1] > 1e4 * errors[2]
    assert errors[2] < 1e-12


@pytest.mark.parametrize("turn", [
    (0.3, 40),  # a Turn of period 40 read at angles from 0.3: the stop grids' n exceed and fold onto it
    (0.1, 720),  # a long period, few of its angles: the series by inverse FFT over the whole period
    None,  # angles that are no Turn: the product with the basis
])
def test_a_grids_series_at_any_angles_gives_the_analytic_wave(turn) -> None:
    """The last step's series (:func:`~raysim.optics.fast.chart.series_at`, along theta and then
    phi, an FFT of the grid first) of a plane wave sampled on the n x n chart gives the analytic
    wave at the targets' angles, whether it runs as inverse FFTs (forced here by a cost of 0 an
    FFT point; folded where the period is shorter than n) or as products with the basis."""
    from raysim.optics.fast import chart

    domain = Domain(CENTRE, R, 1)
    k0 = np.array([3.0, -2.0, 4.0])
    n = 48
    grid = mirror(np.exp(1j * (grid_points(n, domain, half_rows(n)) - np.array(CENTRE)) @ k0)
                  .reshape(1, half_rows(n), n, 1), n)
    S = np.fft.fft2(grid, axes=(1, 2)) / n**2
    if turn is None:
        thetas, phis = np.sort(np.random.default_rng(3).uniform(0, np.pi, 7)), np.array([0.2, 1.0, 4.0])
    else:
        x0, period = turn
        thetas = x0 + 2 * np.pi * np.arange(9) / period
        phis = 2 * x0 + 2 * np.pi * np.arange(period // 2) / period
        assert chart.turn_of(thetas) == chart.Turn(thetas[0], period, 9)
    out = {}
    for cost in (0.0, 1e9):
        chart.FFT_POINT_COST, saved = cost, chart.FFT_POINT_COST
        try:
            out[cost] = chart.series_at(chart.series_at(S, 1, thetas), 2, phis)[0, :, :, 0]
        finally:
            chart.FFT_POINT_COST = saved
    th, ph = np.meshgrid(thetas, phis, indexing="ij")
    dirs = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th)], axis=-1)
    analytic = np.exp(1j * R * dirs @ k0)
    for values in out.values():
        assert np.max(np.abs(values - analytic)) < 1e-12


@pytest.mark.parametrize("fft_point_cost", [0.0, 1e9])
@pytest.mark.parametrize("grid", [
    {"n_theta": 24, "n_phi": 48},
    {"n_theta": 6, "n_phi": 10},  # periods 24 and 10, shorter than the stop grids: folded
    {"n_theta": 20, "n_phi": 30, "theta_max": np.radians(85.0), "phi_min": 0.5, "phi_max": 2.0},  # no Turn
])
def test_the_last_step_on_any_sphere_grid(grid: dict, fft_point_cost: float, monkeypatch) -> None:
    """The series of the stop clusters on a sphere grid, summed by inverse FFTs where its angles
    divide the turn (every Turn taken that way, cost 0) or by products with the basis (never,
    cost 1e9), is within tolerance of the direct sum on grids whose periods are longer or
    shorter than the stop grids and on angles that are no Turn."""
    from raysim.optics.fast import chart

    monkeypatch.setattr(chart, "FFT_POINT_COST", fft_point_cost)
    pts = SphereGrid(R, **grid).points(F).reshape(-1, 3)
    src = _elements("electric")
    out, method = _fast(pts, src, "electric", 1e-6)
    assert method.startswith("fast") and "series on the grid" in method
    assert _rel_rms(out, _direct(pts, src, "electric")) < 1e-6


@pytest.mark.parametrize("n", [8, 36, 56])
def test_the_leaf_steps_distinct_nodes_are_every_point_of_the_computed_rows_once(n: int) -> None:
    """The leaf step computes each distinct point of the grid's rows theta <= pi once: the
    poles' rows (theta = 0 and pi) collapse to one point each, every other node is a point of
    its own, and every computed node lies on one of the distinct ones."""
    from raysim.optics.fast.multilevel import distinct_nodes

    domain = Domain(CENTRE, R, 1)
    computed = grid_points(n, domain, half_rows(n))
    distinct = computed[distinct_nodes(n)]
    gaps = np.linalg.norm(computed[:, None, :] - distinct[None, :, :], axis=2)
    assert np.all(gaps.min(axis=1) < 1e-12 * R)  # every node is one of them
    between = gaps[distinct_nodes(n)]  # (distinct, distinct)
    np.fill_diagonal(between, np.inf)
    assert between.min() > 1e-3 * R  # and they are distinct points
    assert len(distinct) == half_rows(n) * n - 2 * (n - 1)


def test_diffraction_elements_take_the_direct_sum() -> None:
    """go+edge's elements integrate along edge segments: not point sources, so direct."""
    pts = _grid_points(6, 12)
    src = _elements("diffraction")
    out, method = _fast(pts, src, "diffraction", 1e-6)
    assert method == "direct"
    assert np.array_equal(out, _direct(pts, src, "diffraction"))


def test_points_off_the_sphere_take_the_direct_sum() -> None:
    pts = _grid_points(6, 12) * np.linspace(0.9, 1.1, 72)[:, None]
    src = _elements("electric")
    out, method = _fast(pts, src, "electric", 1e-6)
    assert method == "direct"
    assert np.array_equal(out, _direct(pts, src, "electric"))


def test_make_radiator_refuses_an_unknown_method() -> None:
    with pytest.raises(RaysimError, match="unknown radiator"):
        make_radiator(_grid_points(2, 4), K, radiator="fmm", centre=CENTRE)
    # zero, beyond float64's reach (it used to plan grids for 20 digits), not a number
    for tol in (0.0, 1e-20, float("nan"), 1.0):
        with pytest.raises(RaysimError, match=r"tolerance must lie in \[1e-12, 1\)"):
            FastRadiator(_grid_points(2, 4), K, tol=tol, centre=CENTRE)


def test_jacobian_jvp_through_the_fast_radiator_is_the_transpose_of_the_direct_vjp() -> None:
    """The PO Jacobian's JVP (shift elements) by the fast sum: equal to the direct JVP to the
    tolerance, and <J v, w> = <v, J^T w> with the direct VJP to the tolerance."""
    from raysim.optics import po_jacobian
    from raysim.optics.illumination import Illumination
    from raysim.surface.mesh import paraboloid

    dish = paraboloid(D, F, 1.0)
    wave = Illumination.plane_wave(1e9, (0, 0, -1), (1, 0, 0))
    elements = po_jacobian.surface_elements(dish, wave, 1.5, "cpu")
    rng = np.random.default_rng(4)
    n = len(elements.r)
    dz, hx, hy = (rng.standard_normal(n) * 1e-3 for _ in range(3))
    pts = _grid_points(12, 24)
    direct = po_jacobian.jvp(elements, pts, dz, hx, hy)
    fast = po_jacobian.jvp(elements, pts, dz, hx, hy, radiator="fast", tol=1e-6, centre=CENTRE, force=True)
    assert np.sqrt(np.sum(np.abs(fast - direct) ** 2) / np.sum(np.abs(direct) ** 2)) < 1e-6
    w = rng.standard_normal((len(pts), 3)) + 1j * rng.standard_normal((len(pts), 3))
    gz, gx, gy = po_jacobian.vjp(elements, pts, w)
    lhs = float(np.real(np.sum(np.conj(w) * fast)))
    rhs = float(gz @ dz + gx @ hx + gy @ hy)
    assert abs(lhs - rhs) <= 1e-6 * abs(rhs)


def test_a_cost_estimate_from_a_subset_of_the_elements_is_the_whole_sets(monkeypatch) -> None:
    """The plan's cost from every fourth element, counted as all of them (how `check` and
    Gauss-Newton's budget estimate the large runs), is about the cost of the plan on all of
    them, where the leaves are on grids of their own sizes too (the plan aggregates; the
    subset's clusters are a little narrower, so its grids a little smaller)."""
    from raysim.optics.fast import multilevel
    from raysim.optics.fast.radiator import plan_for

    monkeypatch.setattr(multilevel, "COST_BLAS", 1.0)  # the last step dear: the plan aggregates
    pos = _dish_positions(np.pi / K / 2)  # a quarter wavelength apart
    domain = domain_of(_grid_points(), CENTRE)
    whole = plan_for([pos.T], domain, K, 1e-6)
    subset = plan_for([pos[::4].T], domain, K, 1e-6, count=len(pos))
    assert whole is not None and subset is not None
    assert whole.stop < whole.leaf and len(np.unique(whole.leaf_sizes)) > 1
    assert abs(subset.cost / whole.cost - 1) < 0.15, (subset.cost, whole.cost)
